"""Measure how often a crashed and restarted ROS process is never heard from again.

This process stands for the controller: it reads ``state`` from a child process and
publishes ``command`` to it at 1 kHz. The child stands for the instrument: it publishes
``state`` at 1 kHz (each message carries how many commands it has received) and reads
``command``. Each cycle starts a child, waits for its first state, lets the loop run,
kills the child with SIGKILL (a crash), waits ``--gap`` s and starts a new one, which then
has ``--deaf-after`` s to be heard. A cycle whose new child is never heard is "deaf"; the
tool then records what each side sees (the child's log says how many subscribers match its
writer and how many commands it has received; ``/dev/shm`` lists the Fast DDS ports)::

    .venv/bin/python tools/shm_crash_restart.py --cycles 200

This is the fault check's ``sim_restart@sim_instrument`` case (a SIGKILL'ed
``sim_instrument`` process and a new one) without the rest of the package: with Fast DDS's
shared-memory transport a new participant that reuses the killed one's port removes the
killed port's segment, which the survivors may go on writing to (eProsima/Fast-DDS#5053,
#4728). Every process runs with loopback discovery in a ROS domain of its own.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

#: The child: publish ``state`` at 1 kHz with the commands received so far; log once a second.
CHILD = r'''
import sys, time
import rclpy
from rclpy.executors import ExternalShutdownException
from std_msgs.msg import UInt64
rclpy.init()
node = rclpy.create_node('crash_child')
received = [0]
state = node.create_publisher(UInt64, 'state', 10)
node.create_subscription(UInt64, 'command', lambda m: received.__setitem__(0, received[0] + 1), 10)
node.create_timer(0.001, lambda: state.publish(UInt64(data=received[0])))
def report():
    print(f'{time.time():.3f} subscribers={state.get_subscription_count()} '
          f'commands={received[0]}', flush=True)
node.create_timer(1.0, report)
if len(sys.argv) > 1 and sys.argv[1] == 'flood':    # publish as fast as it can, from a thread
    import threading
    def flood():
        msg = UInt64(data=0)
        while True:
            state.publish(msg)
    threading.Thread(target=flood, daemon=True).start()
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
'''


class Survivor:
    """The long-lived side: count states, publish commands at 1 kHz."""

    def __init__(self):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import UInt64
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('survivor', context=self.context)
        self.lock = threading.Lock()
        self.states = 0
        self.last_state = (0.0, 0)          # (monotonic receive time, commands the child had)
        self.node.create_subscription(UInt64, 'state', self._on_state, 10)
        self.command = self.node.create_publisher(UInt64, 'command', 10)
        self.node.create_timer(0.001, lambda: self.command.publish(UInt64(data=1)))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        from rclpy.executors import ExternalShutdownException
        try:
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.05)
        except ExternalShutdownException:
            pass                            # close() shut the context down

    def _on_state(self, msg):
        with self.lock:
            self.states += 1
            self.last_state = (time.monotonic(), msg.data)

    def heard_since(self, t: float) -> bool:
        with self.lock:
            return self.last_state[0] > t

    def close(self):
        self.context.shutdown()
        self.thread.join(timeout=2.0)
        self.node.destroy_node()


def start_child(log: Path, env: dict, flood: bool = False) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, '-c', CHILD] + (['flood'] if flood else []), env=env,
                            stdout=open(log, 'w'), stderr=subprocess.STDOUT)


def wait_for(predicate, timeout: float) -> float | None:
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if predicate():
            return time.monotonic() - start
        time.sleep(0.005)
    return None


def shm_ports() -> list[str]:
    return sorted(p.name for p in Path('/dev/shm').glob('fastrtps_port*') if not p.name.endswith('_el'))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cycles', type=int, default=100)
    parser.add_argument('--run', type=float, default=1.0, help='s the loop runs before the kill')
    parser.add_argument('--gap', type=float, default=0.15, help='s between the kill and the new child')
    parser.add_argument('--deaf-after', type=float, default=20.0)
    parser.add_argument('--flood', action='store_true',
                        help='the children publish as fast as they can (killed mid-push more often)')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', '57')))
    parser.add_argument('--out', type=Path, default=Path(tempfile.mkdtemp(prefix='shm_crash_')))
    args = parser.parse_args(argv)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = str(args.domain)
    env = dict(os.environ)
    args.out.mkdir(parents=True, exist_ok=True)
    survivor = Survivor()
    heard, deaf = [], []
    child = start_child(args.out / 'child_0.log', env, args.flood)
    first = wait_for(lambda: survivor.heard_since(0.0), args.deaf_after)
    if first is None:
        print('the first child was never heard', file=sys.stderr)
        return 2
    try:
        for cycle in range(1, args.cycles + 1):
            time.sleep(args.run)
            child.send_signal(signal.SIGKILL)
            child.wait()
            time.sleep(args.gap)
            t_start = time.monotonic()
            log = args.out / f'child_{cycle}.log'
            child = start_child(log, env, args.flood)
            latency = wait_for(lambda: survivor.heard_since(t_start), args.deaf_after)
            if latency is None:
                record = {'cycle': cycle, 'child_pid': child.pid, 'child_alive': child.poll() is None,
                          'child_log_tail': log.read_text().splitlines()[-3:],
                          'shm_ports': shm_ports()}
                deaf.append(record)
                print('deaf:', json.dumps(record), file=sys.stderr, flush=True)
            else:
                heard.append(latency)
            print(f'cycle {cycle}: heard {len(heard)}, deaf {len(deaf)}', file=sys.stderr, flush=True)
    finally:
        child.kill()
        child.wait()
        survivor.close()
    heard.sort()
    print(json.dumps({'cycles': args.cycles, 'heard': len(heard), 'deaf': len(deaf),
                      'first_state_s': {'median': heard[len(heard) // 2] if heard else None,
                                        'max': heard[-1] if heard else None},
                      'deaf_cycles': deaf, 'logs': str(args.out)}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
