"""The controller node's own loop timing (rclpy; prints figures, asserts nothing).

Starts sim_instrument, controller and a repeating master as separate processes
(as the demo does), lets the loop run, then reads the controller's own timing
from its /diagnostics: mean and max period, periods longer than 1.5x nominal,
and the time spent in one tick::

    .venv/bin/python -m grip_force_ros.lab.bench.node_timing --seconds 20

Set ROS_DOMAIN_ID first (DDS stays on loopback unless you chose a range). The
round trip against the middleware floor is :mod:`.loop` (``grip-force bench``).
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray

from grip_force_ros import topics
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.lab.processes import NodeProcess, ensure_local_discovery, ros_environment
from grip_force_ros.params import instrument_path

CONFIG = instrument_path()


def run(seconds: float, config: Path = CONFIG) -> dict:
    """Run the loop for ``seconds`` and return the controller's timing figures."""
    env = ros_environment()
    latest: dict[str, str] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('controller'):
                latest.clear()
                latest.update({kv.key: kv.value for kv in status.values})

    logdir = Path(tempfile.mkdtemp(prefix='gf_bench_'))
    with RosRunner(executor_kind='single') as ros:
        probe = ros.plain_node('bench_probe')
        probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, 10)
        ros.start()
        procs = [NodeProcess('sim_instrument', params_file=str(config), env=env,
                             log_path=str(logdir / 'sim.log')),
                 NodeProcess('controller', params_file=str(config), env=env,
                             log_path=str(logdir / 'controller.log')),
                 NodeProcess('master', params_file=str(config), params={'repeat': True},
                             env=env, log_path=str(logdir / 'master.log'))]
        try:
            time.sleep(seconds)
        finally:
            for proc in procs:
                proc.stop()
    return {
        'seconds': seconds,
        'periods': int(latest.get('periods', 0)),
        'period_mean_ms': float(latest.get('period_mean_ms', 'nan')),
        'period_max_ms': float(latest.get('period_max_ms', 'nan')),
        'late_periods': int(latest.get('late_periods', -1)),
        'tick_mean_us': float(latest.get('tick_mean_us', 'nan')),
        'tick_max_us': float(latest.get('tick_max_us', 'nan')),
        'load_average_1min': os.getloadavg()[0],
    }


def main(argv: list[str] | None = None) -> int:
    """Run :func:`run` with the command-line options and print its figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=20.0)
    args = parser.parse_args(argv)
    ensure_local_discovery()
    print(json.dumps(run(args.seconds)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
