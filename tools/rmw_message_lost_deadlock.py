"""Provoke rmw_fastrtps's message-lost deadlock: the event way of counting losses, and the new one.

Loaded run 44/1 hung for 30 min in ``test_lifecycle.py``: the test's recording node had a
subscription with a ``message_lost`` event callback. Its executor thread was in
``rcl_take_event`` -> rmw_fastrtps ``RMWSubscriptionEvent::take_event`` (holding the event's
mutex) waiting for the DataReader's mutex, while a Fast DDS receive thread held that reader
mutex in ``on_sample_lost`` -> ``RMWSubscriptionEvent::update_sample_lost``, waiting for the
event's mutex: an AB-BA inversion (ros2/rmw_fastrtps#890, fixed upstream in 2026; the Jazzy
wheels' rmw_fastrtps 8.4.3 has it). rclpy does not release the GIL around ``take_event``, so
the whole process stopped, its timeouts too.

This tool floods a depth-1 topic (reliable unless asked) from one process and reads it, slowly,
in another, so that the reader loses samples all the time, and watches its heartbeat (a line
from a timer; a deadlocked executor writes none). Two ways of counting the losses:

* ``event``: a ``message_lost`` event callback (what the test and the fault probe had);
* ``sequence``: gaps in the writer's ``publication_sequence_number`` of each sample's
  MessageInfo (a two-argument callback; this tool spins a SingleThreadedExecutor: the
  EventsExecutor of these wheels raises "SystemError: null argument to internal routine" for
  such a callback, which is why the probe and the test now infer lost commands from the
  control steps received between two commands: ``faults.probe.LimitMonitor``).

::

    .venv/bin/python tools/rmw_message_lost_deadlock.py --runs 6 --seconds 60

Per run it says whether the reader stalled (no heartbeat for ``--stall`` s: its native stacks
are then written beside the report when gdb is there) and how many losses it counted. The
race is narrow: the event way ran 16 runs of 20-40 s here without a stall (stop 44), so a
clean run shows little; the hang's own stacks are in docs/reliability.md. The two ways also
count different things: the event only samples DDS gave up on, the sequence gaps every sample
the callback never saw (also those a newer one replaced in the reader's depth-1 history).
Every process runs with loopback discovery in a ROS domain this tool holds.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from grip_force_ros.nodes.processes import reserve_domains, ros_environment

MODES = ('event', 'sequence')
TOPIC = 'message_lost_flood'


def flood_qos(reliability: str):
    """Depth 1, ``reliable`` or ``best_effort``: the reader loses samples as soon as it lags."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE if reliability == 'reliable'
                      else ReliabilityPolicy.BEST_EFFORT)


def writer(seconds: float, reliability: str) -> None:
    """Publish JointStates as fast as possible for ``seconds`` (depth 1)."""
    import rclpy
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node('flood_writer')
    pub = node.create_publisher(JointState, TOPIC, flood_qos(reliability))
    msg = JointState(name=['jaw'], position=[0.0], velocity=[0.0], effort=[0.0])
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            pub.publish(msg)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def reader(mode: str, seconds: float, work: float, reliability: str) -> None:
    """Read the flood, ``work`` s per sample, count losses ``mode``'s way; a heartbeat each 0.2 s."""
    import rclpy
    from rclpy.event_handler import SubscriptionEventCallbacks
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node('flood_reader')
    counts = {'samples': 0, 'lost': 0, 'reports': 0}
    last_number = [0]                    # the writer's last sequence number received
    qos = flood_qos(reliability)

    def on_lost(info) -> None:
        counts['lost'] += info.total_count_change
        counts['reports'] += 1

    if mode == 'event':
        def on_sample(msg) -> None:
            counts['samples'] += 1
            time.sleep(work)
        node.create_subscription(JointState, TOPIC, on_sample, qos,
                                 event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
    else:
        def on_sample(msg, info) -> None:            # noqa: F811 (one of the two is made)
            counts['samples'] += 1
            number = info['publication_sequence_number']
            missed = number - last_number[0] - 1 if last_number[0] else 0
            last_number[0] = number
            if missed > 0:
                counts['lost'] += missed
                counts['reports'] += 1
            time.sleep(work)
        node.create_subscription(JointState, TOPIC, on_sample, qos)
    node.create_timer(0.2, lambda: print(json.dumps(counts), flush=True))
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def native_stacks(pid: int) -> str:
    """Return the backtrace of every thread of ``pid`` (gdb), or why there is none."""
    if not shutil.which('gdb'):
        return 'no gdb'
    out = subprocess.run(['gdb', '-p', str(pid), '-batch', '-ex', 'thread apply all bt 20'],
                         capture_output=True, text=True, timeout=120)
    return out.stdout + out.stderr


def one_run(mode: str, env: dict, seconds: float, work: float, stall: float, out: Path,
            index: int, reliability: str) -> dict:
    """One writer and one reader for ``seconds``; the reader's last counts and whether it stalled."""
    me = [sys.executable, __file__]
    qos = ['--reliability', reliability]
    wr = subprocess.Popen(me + ['--role', 'writer', '--seconds', str(seconds + 5), *qos], env=env,
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rd = subprocess.Popen(me + ['--role', 'reader', '--mode', mode, '--seconds', str(seconds),
                                '--work', str(work), *qos], env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.DEVNULL, text=True)
    os.set_blocking(rd.stdout.fileno(), False)
    last, last_beat, stalled, started = {}, time.monotonic(), False, time.monotonic()
    while rd.poll() is None:
        for line in rd.stdout:
            if line.strip():
                last, last_beat = json.loads(line), time.monotonic()
        if time.monotonic() - last_beat > stall:
            stalled = True
            (out / f'{mode}_{index}_stacks.txt').write_text(native_stacks(rd.pid))
            break
        time.sleep(0.1)
    for proc in (rd, wr):
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        proc.wait()
    return {'mode': mode, 'run': index, 'reliability': reliability, 'stalled': stalled,
            'stalled_after_s': round(last_beat - started, 1) if stalled else None, **last}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--runs', type=int, default=4, help='runs per way of counting (alternating)')
    ap.add_argument('--seconds', type=float, default=60.0, help='length of a run (s)')
    ap.add_argument('--work', type=float, default=0.0005, help="the reader's time per sample (s)")
    ap.add_argument('--stall', type=float, default=5.0, help='no heartbeat this long (s): stalled')
    ap.add_argument('--modes', nargs='+', default=list(MODES), choices=MODES)
    ap.add_argument('--reliability', choices=('reliable', 'best_effort'), default='reliable',
                    help="the flood's QoS (default reliable, as the probe's RECORD_QOS)")
    ap.add_argument('--out', type=Path, default=None, help='folder of the report and stacks')
    ap.add_argument('--role', choices=('writer', 'reader'), help=argparse.SUPPRESS)
    ap.add_argument('--mode', choices=MODES, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.role == 'writer':
        writer(args.seconds, args.reliability)
        return 0
    if args.role == 'reader':
        reader(args.mode, args.seconds, args.work, args.reliability)
        return 0
    out = args.out or Path(tempfile.mkdtemp(prefix='message_lost_'))
    out.mkdir(parents=True, exist_ok=True)
    with reserve_domains(1) as domain:
        env = ros_environment(domain.domain_id)
        runs = [one_run(mode, env, args.seconds, args.work, args.stall, out, k, args.reliability)
                for k in range(args.runs) for mode in args.modes]
    for mode in args.modes:
        mine = [r for r in runs if r['mode'] == mode]
        print(f"{mode}: {sum(r['stalled'] for r in mine)} of {len(mine)} runs stalled; "
              f"losses counted per run {[r.get('lost') for r in mine]}")
    (out / 'report.json').write_text(json.dumps(runs, indent=1))
    print(f'report and stacks: {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
