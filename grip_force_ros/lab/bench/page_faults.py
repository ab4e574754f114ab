"""Page faults, CPU and resident memory of the three shipped 1 kHz nodes, with or without the lock.

Starts ``sim_instrument``, ``controller`` and ``master`` (the shipped executables, the given
instrument file, ``lock_memory`` true or false), waits ``--warmup`` s (start-up, the lock and
the pre-faulting), then reads /proc/<pid>/stat of each process at the start and the end of
a ``--seconds`` window: minor and major page faults and CPU time in the window, the faults
of the start-up, resident and locked memory (MiB). One JSON line on stdout.
docs/ros_interface.md ("Real-time settings") gives the figures it measured::

    ROS_DOMAIN_ID=59 .venv/bin/python -m grip_force_ros.lab.bench.page_faults --lock on --seconds 20
    ROS_DOMAIN_ID=59 .venv/bin/python -m grip_force_ros.lab.bench.page_faults --lock off --seconds 20
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

from grip_force_ros.lab.processes import node_command, ros_environment
from grip_force_ros.params.files import instrument_path

NODES = ('sim_instrument', 'controller', 'master')


def proc_stat(pid: int) -> tuple[int, int, float]:
    """Return (minor faults, major faults, CPU time in s) of ``pid`` from /proc/<pid>/stat."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    # after the command: field 3 is fields[0]; minflt 10, majflt 12, utime 14, stime 15
    ticks = os.sysconf('SC_CLK_TCK')
    return int(fields[7]), int(fields[9]), (int(fields[11]) + int(fields[12])) / ticks


def status_mib(pid: int, key: str) -> int:
    """Return a kB field of /proc/<pid>/status (e.g. 'VmRSS') in MiB."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith(key + ':'):
            return int(line.split()[1]) // 1024
    return 0


def main(argv=None) -> int:
    """Run the three nodes for one window and print the JSON line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--lock', choices=('on', 'off'), default='on',
                        help="the nodes' lock_memory parameter")
    parser.add_argument('--seconds', type=float, default=20.0, help='window (s)')
    parser.add_argument('--warmup', type=float, default=15.0, help='time before it (s)')
    parser.add_argument('--config', default=None, help='instrument YAML (default: the shipped one)')
    args = parser.parse_args(argv)
    config = str(instrument_path(args.config).resolve())
    env = ros_environment(int(os.environ.get('ROS_DOMAIN_ID', '59')))
    extra = {} if args.lock == 'on' else {'lock_memory': False}
    procs = {}
    try:
        for name in NODES:
            params = {**extra, **({'repeat': True} if name == 'master' else {})}
            procs[name] = subprocess.Popen(node_command(name, config, params, log_level='warn'),
                                           env=env, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL)
        time.sleep(args.warmup)
        start = {n: proc_stat(p.pid) for n, p in procs.items()}
        time.sleep(args.seconds)
        end = {n: proc_stat(p.pid) for n, p in procs.items()}
        nodes = {n: {'startup_minflt': start[n][0], 'startup_majflt': start[n][1],
                     'window_minflt': end[n][0] - start[n][0],
                     'window_majflt': end[n][1] - start[n][1],
                     'window_cpu_percent': round(100 * (end[n][2] - start[n][2]) / args.seconds, 1),
                     'rss_mib': status_mib(p.pid, 'VmRSS'), 'locked_mib': status_mib(p.pid, 'VmLck')}
                 for n, p in procs.items()}
    finally:
        for p in procs.values():
            p.send_signal(2)
        for p in procs.values():
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
    print(json.dumps({'lock_memory': args.lock == 'on', 'warmup_s': args.warmup,
                      'window_s': args.seconds, 'nodes': nodes}))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
