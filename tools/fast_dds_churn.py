"""Reproduce Fast DDS's deadlock of a participant's own threads (eProsima/Fast-DDS#6502).

A long-lived participant (its own process: a node that echoes ``ping`` on ``echo`` and has a
writer and a reader that the others match) lives beside participants that come and go (a
churn process: each worker creates a context and a node with a matching writer and reader,
spins 0.3 s, and destroys them), whose profile announces a short lease so that the
long-lived participant checks their liveliness often. This process pings the long-lived one
every 10 ms; when no echo has come for 10 s it takes the long-lived process's native stacks
with gdb and says whether they show the deadlock::

    .venv/bin/python tools/fast_dds_churn.py --workers 4 --lease 0.2 --seconds 1200

The deadlock: a receive thread, removing a remote writer under the PDP mutex
(``PDP::removeWriterProxyData`` -> ``WriterProxy::stop``), waits in
``ResourceEvent::unregister_timer`` for the event thread, which waits for that mutex in
``PDP::check_remote_participant_liveliness``. The participant receives nothing from then on,
and whatever destroys it waits for good (docs/reliability.md, seventeenth round). Every
process runs with loopback discovery in a ROS domain of its own.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

#: A Fast DDS profile whose participants announce ``{lease}`` s of lease, every quarter of it.
PROFILE = '''<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="churn" is_default_profile="true">
    <rtps><builtin><discovery_config>
      <leaseDuration><sec>{sec}</sec><nanosec>{nanosec}</nanosec></leaseDuration>
      <leaseAnnouncement><sec>{asec}</sec><nanosec>{ananosec}</nanosec></leaseAnnouncement>
    </discovery_config></builtin></rtps>
  </participant>
</profiles>
'''
#: Frames of the two threads of the deadlock, as gdb names them.
DEADLOCK_FRAMES = ('check_remote_participant_liveliness', 'unregister_timer')
#: No echo for this long (s) counts as a deaf participant.
DEAF_AFTER = 10.0


def long_lived() -> None:
    """Echo ``ping`` on ``echo``; publish on ``churn_back`` and read ``churn``."""
    import rclpy
    from std_msgs.msg import String, UInt64

    rclpy.init()
    node = rclpy.create_node('long_lived')
    echo = node.create_publisher(UInt64, 'echo', 10)
    node.create_subscription(UInt64, 'ping', echo.publish, 10)
    node.create_subscription(String, 'churn', lambda _msg: None, 10)
    back = node.create_publisher(String, 'churn_back', 10)
    node.create_timer(0.01, lambda: back.publish(String(data='x')))
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass


def churn(workers: int, seconds: float) -> None:
    """Create and destroy participants, ``workers`` at a time, for ``seconds``; print the count."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    count, lock = [0], threading.Lock()

    def worker(index: int) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            context = Context()
            rclpy.init(context=context)
            node = rclpy.create_node(f'churn_{index}', context=context)
            writer = node.create_publisher(String, 'churn', 10)
            node.create_subscription(String, 'churn_back', lambda _msg: None, 10)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            until = time.monotonic() + 0.3
            while time.monotonic() < until:
                writer.publish(String(data='c'))
                executor.spin_once(timeout_sec=0.01)
            executor.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=context)
            with lock:
                count[0] += 1
                if count[0] % 100 == 0:
                    print(f'participants created and removed: {count[0]}', flush=True)

    threads = [threading.Thread(target=worker, args=(i,), daemon=True) for i in range(workers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    print(f'participants created and removed: {count[0]}', flush=True)


def churned(out: Path) -> str:
    """Return the churn process's last count, from its log (Fast DDS writes its lines there too)."""
    counts = [line for line in (out / 'churn.log').read_text(errors='replace').splitlines()
              if line.startswith('participants created and removed')]
    return counts[-1] if counts else 'no participant count yet'


def watch(args) -> int:
    """Start both processes, ping the long-lived one, and report; 1 when it went deaf."""
    import rclpy
    from std_msgs.msg import UInt64

    from grip_force_ros.nodes.processes import ensure_local_discovery

    env = ensure_local_discovery(dict(os.environ))
    env.setdefault('ROS_DOMAIN_ID', str(args.domain_id))
    os.environ.update(env)
    out = Path(args.out or tempfile.mkdtemp(prefix='fast_dds_churn_'))
    out.mkdir(parents=True, exist_ok=True)
    profile = out / 'churn_profile.xml'
    sec, nanosec = divmod(round(args.lease * 1e9), 1_000_000_000)
    asec, ananosec = divmod(round(args.lease * 1e9 / 4), 1_000_000_000)
    profile.write_text(PROFILE.format(sec=sec, nanosec=nanosec, asec=asec, ananosec=ananosec))
    rclpy.init()
    node = rclpy.create_node('pinger')
    me = [sys.executable, __file__]
    with open(out / 'long.log', 'w') as long_log, open(out / 'churn.log', 'w') as churn_log:
        lived = subprocess.Popen(me + ['--role', 'long'], env=env, stdout=long_log,
                                 stderr=subprocess.STDOUT)
        churning = subprocess.Popen(me + ['--role', 'churn', '--workers', str(args.workers),
                                          '--seconds', str(args.seconds)],
                                    env=dict(env, FASTRTPS_DEFAULT_PROFILES_FILE=str(profile)),
                                    stdout=churn_log, stderr=subprocess.STDOUT)
    echoes = {'last': time.monotonic(), 'count': 0}

    def echoed(_msg) -> None:
        echoes['last'], echoes['count'] = time.monotonic(), echoes['count'] + 1

    node.create_subscription(UInt64, 'echo', echoed, 10)
    ping = node.create_publisher(UInt64, 'ping', 10)
    started, sent, deaf = time.monotonic(), 0, False
    try:
        while churning.poll() is None:
            sent += 1
            ping.publish(UInt64(data=sent))
            rclpy.spin_once(node, timeout_sec=0.01)
            time.sleep(0.01)
            if echoes['count'] and time.monotonic() - echoes['last'] > DEAF_AFTER:
                deaf = True
                break
        elapsed = time.monotonic() - started
        if deaf:
            stacks = subprocess.run(['gdb', '-p', str(lived.pid), '-batch', '-nx', '-ex',
                                     'thread apply all bt'], capture_output=True, text=True,
                                    timeout=120).stdout
            (out / 'long_gdb.txt').write_text(stacks)
            named = all(frame in stacks for frame in DEADLOCK_FRAMES)
            print(f'deaf after {elapsed:.0f} s ({echoes["count"]} echoes, {churned(out)}): '
                  f'{"the deadlock of eProsima/Fast-DDS#6502" if named else "another cause"}; '
                  f'stacks in {out / "long_gdb.txt"}', flush=True)
        else:
            print(f'no deaf participant in {elapsed:.0f} s ({echoes["count"]} echoes, {churned(out)})',
                  flush=True)
    finally:
        churning.kill()
        lived.kill()
        node.destroy_node()
        rclpy.try_shutdown()
    return 1 if deaf else 0


def main(argv: list[str] | None = None) -> int:
    """Run one role (``long``, ``churn``) or the whole reproduction (default)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--role', choices=('watch', 'long', 'churn'), default='watch')
    parser.add_argument('--workers', type=int, default=4, help='participants at a time')
    parser.add_argument('--lease', type=float, default=0.2,
                        help='lease (s) the churning participants announce (Fast DDS default: 20)')
    parser.add_argument('--seconds', type=float, default=1200.0, help='how long to churn (s)')
    parser.add_argument('--domain-id', type=int, default=221, help='ROS domain (unless ROS_DOMAIN_ID is set)')
    parser.add_argument('--out', help='folder for the logs and the stacks (default: a new temporary one)')
    args = parser.parse_args(argv)
    if not 0 <= args.domain_id <= 232:                # Fast DDS's ports for larger ones overflow
        parser.error(f'--domain-id {args.domain_id}: 0 to 232')
    if args.role == 'long':
        long_lived()
        return 0
    if args.role == 'churn':
        churn(args.workers, args.seconds)
        return 0
    return watch(args)


if __name__ == '__main__':
    sys.exit(main())
