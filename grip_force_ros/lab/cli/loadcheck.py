"""`grip-force loadcheck`: the ROS test files K times under a load, failures tabulated."""
from __future__ import annotations

HELP = 'run the ROS tests K times under a bounded CPU (or disk) load and tabulate the failures'


def add_arguments(parser) -> None:
    from grip_force_ros.lab.cli.load import add_pressure_arguments
    parser.add_argument('--runs', type=int, default=3, help='pytest runs (default 3; the bar is 20)')
    parser.add_argument('--workers', type=int, default=None,
                        help='busy processes during each run (default: one per core; 0 = no load)')
    parser.add_argument('--duty', type=float, default=1.0, help='busy share of each worker (default 1)')
    parser.add_argument('--kind', choices=('cpu', 'disk', 'both'), default='cpu',
                        help='the load of each run: cpu (busy processes, default), disk (fsync '
                             "writers, page-cache eviction of the package's files, optional "
                             'memory), both')
    add_pressure_arguments(parser, prefix='disk-')
    parser.add_argument('--select', default='ros',
                        help="pytest -m expression of the tests (default 'ros': every test with real nodes)")
    parser.add_argument('--files', nargs='*', metavar='FILE',
                        help='test files or node ids (default: the whole test folder)')
    parser.add_argument('--out', default=None,
                        help='folder of the junit files and logs (default out/loadcheck/<time>)')
    parser.add_argument('--timeout', type=float, default=1800.0, help='longest run (s, default 1800)')
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.add_argument('--tally', nargs='+', metavar='FOLDER',
                        help='run nothing: count the loaded runs of these loadcheck folders per '
                             'code (commit), clean of complete; FOLDER=CODE names the code of a '
                             "folder whose runs have no record of it (an older loadcheck's)")


def run(args) -> int:
    import json
    import signal
    import sys
    import time
    from pathlib import Path

    from grip_force_ros.lab.bench.load import LoadError
    from grip_force_ros.lab.bench.loadcheck import loadcheck, render, render_tally, tally
    from grip_force_ros.lab.bench.pressure import make_pressure
    from grip_force_ros.lab.cli.load import pressure_options

    if args.tally:
        folders = [Path(f.partition('=')[0]) for f in args.tally]
        given = {Path(f.partition('=')[0]): f.partition('=')[2] for f in args.tally if '=' in f}
        missing = [str(f) for f in folders if not f.is_dir()]
        if missing:
            print(f'error: no such folder: {", ".join(missing)}', file=sys.stderr)
            return 2
        table = tally(folders, given)
        print(json.dumps(table, indent=1) if args.json else render_tally(table))
        return 0
    if args.runs < 1:
        print('error: --runs must be >= 1', file=sys.stderr)
        return 2
    disk_options = pressure_options(args) if args.kind != 'cpu' else None
    if args.kind != 'cpu':
        try:        # its bounds checked before the first run, not after it
            make_pressure('disk', seconds=args.timeout + 60.0, **disk_options)
        except (LoadError, OSError) as exc:
            print(f'error: {exc}', file=sys.stderr)
            return 2
    out = Path(args.out or f"out/loadcheck/{time.strftime('%Y%m%d-%H%M%S')}")

    def progress(r):
        failed = ', '.join(f['test'] for f in r['failed']) or 'none'
        print(f"run {r['run']}: {r['tests']} tests, {r['seconds']:.0f} s, load average "
              f"{r['load_average_mean']}, failed: {failed}", file=sys.stderr, flush=True)

    def stopped(signum, frame):     # SIGTERM as Ctrl-C: the run in progress and the load stop
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stopped)
    report = loadcheck(args.runs, out, progress=progress, workers=args.workers, duty=args.duty,
                       select=args.select, files=args.files, timeout=args.timeout,
                       kind=args.kind, disk_options=disk_options)
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(render(report))
    return 0 if report['failed_runs'] == 0 else 1
