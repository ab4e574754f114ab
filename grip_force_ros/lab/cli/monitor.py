"""`grip-force monitor`: a live text view of the force and state topics."""
from __future__ import annotations

HELP = 'live view of target/estimated/measured force, current, mode and diagnostics'


def add_arguments(parser) -> None:
    parser.add_argument('--duration', type=float, help='stop after S seconds (default: Ctrl-C)')
    parser.add_argument('--period', type=float, default=0.2, help='refresh period in s')
    parser.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID to watch (default: env)')
    parser.add_argument('--plain', action='store_true',
                        help='one plain line per refresh even on a terminal')


def run(args) -> int:
    from grip_force_ros.lab.demo.monitor import monitor
    if args.period <= 0:
        print('error: --period must be > 0 s')
        return 2
    monitor(duration=args.duration, period=args.period, domain_id=args.domain_id,
            tty=False if args.plain else None)
    return 0
