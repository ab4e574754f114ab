"""`grip-force load`: keep every core busy for a while (bounded), as another job would."""
from __future__ import annotations

HELP = 'a bounded CPU load: N busy processes for T seconds (Ctrl-C stops them at once)'


def add_arguments(parser) -> None:
    parser.add_argument('--seconds', type=float, default=600.0,
                        help='how long the load lasts (s, default 600; hard stop of every worker)')
    parser.add_argument('--workers', type=int, default=None,
                        help='busy processes (default: one per core)')
    parser.add_argument('--duty', type=float, default=1.0,
                        help='busy share of each worker, 0 < duty <= 1 (default 1: a full core each)')
    parser.add_argument('--json', action='store_true', help='print the summary as JSON')


def run(args) -> int:
    import json
    import sys
    import time

    from grip_force_ros.bench.load import LoadError, LoadGenerator

    try:
        load = LoadGenerator(args.workers, seconds=args.seconds, duty=args.duty)
    except LoadError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    print(f'load: {load.workers} busy process(es) at duty {load.duty:g} for {load.seconds:g} s '
          '(Ctrl-C stops them)', file=sys.stderr, flush=True)
    interrupted = False
    load.start()
    try:
        while load.running():
            time.sleep(0.5)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        summary = load.stop()
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"load: {summary['workers']} worker(s), {summary['wall_s']:.1f} s, load average "
              f"{summary['load_average_before']:.2f} -> {summary['load_average_now']:.2f}")
    return 130 if interrupted else 0
