"""`grip-force load`: a bounded load, as another job would make: CPU, disk and memory, or both."""
from __future__ import annotations

HELP = ('a bounded load for T seconds: busy processes (cpu), fsync writers, page-cache '
        'eviction and memory (disk), or both (Ctrl-C stops them at once)')


def add_pressure_option(parser, what: str) -> None:
    """Add ``--pressure none|cpu|disk|both`` and the disk pressure's ``--disk-*`` options.

    ``what`` says what runs under the load (``'the demo'``, ``'the loop part'``).
    """
    parser.add_argument('--pressure', choices=('none', 'cpu', 'disk', 'both'), default='none',
                        help=f'run {what} under a bounded load, stopped when it ends: cpu (one '
                             'busy process per core), disk (fsync writers, page-cache eviction of '
                             "the package's files; the --disk-* options), both (default none)")
    add_pressure_arguments(parser, prefix='disk-')


def add_pressure_arguments(parser, prefix: str = '') -> None:
    """Add the options of the disk pressure (:class:`~grip_force_ros.lab.bench.pressure.DiskPressure`).

    ``prefix`` goes before each option's name (``--disk-writers`` with ``prefix='disk-'``),
    for the commands whose own options would clash.
    """
    parser.add_argument(f'--{prefix}writers', dest='disk_writers', type=int, default=2,
                        help='disk pressure: fsync writer processes (default 2; 0 = none)')
    parser.add_argument(f'--{prefix}file-mb', dest='disk_file_mb', type=float, default=256.0,
                        help="disk pressure: each writer's file, rewritten in a loop (MB, default 256)")
    parser.add_argument(f'--{prefix}rate-mb-s', dest='disk_rate_mb_s', type=float, default=64.0,
                        help='disk pressure: most MB/s each writer writes (default 64; 0: as fast '
                             'as the disk takes them, on a VM with a cached virtual disk a CPU load)')
    parser.add_argument(f'--{prefix}evict-rate', dest='disk_evict_rate', type=float, default=500.0,
                        help="disk pressure: the package's files dropped from the page cache a "
                             'second (1/s, default 500; 0 = none)')
    parser.add_argument(f'--{prefix}memory-mb', dest='disk_memory_mb', type=float, default=0.0,
                        help='disk pressure: memory allocated, touched and released in a loop '
                             '(MB, default 0 = none)')
    parser.add_argument(f'--{prefix}drop-caches', dest='disk_drop_caches', action='store_true',
                        help='disk pressure: also write 1 to /proc/sys/vm/drop_caches every 5 s '
                             "where it is writable (the whole machine's page cache)")
    parser.add_argument(f'--{prefix}dir', dest='disk_dir', default=None,
                        help="disk pressure: where its temporary directory goes (default $TMPDIR)")


def pressure_options(args) -> dict:
    """Return the keywords of :class:`~grip_force_ros.lab.bench.pressure.DiskPressure` in ``args``."""
    return {'writers': args.disk_writers, 'file_mb': args.disk_file_mb,
            'rate_mb_s': args.disk_rate_mb_s or None, 'evict_rate': args.disk_evict_rate,
            'memory_mb': args.disk_memory_mb, 'drop_caches': args.disk_drop_caches,
            'directory': args.disk_dir}


def add_arguments(parser) -> None:
    parser.add_argument('--kind', choices=('cpu', 'disk', 'both'), default='cpu',
                        help='cpu: busy processes (default); disk: fsync writers, page-cache '
                             'eviction of the package and optional memory; both')
    parser.add_argument('--seconds', type=float, default=600.0,
                        help='how long the load lasts (s, default 600; hard stop of every worker)')
    parser.add_argument('--workers', type=int, default=None,
                        help='busy processes (default: one per core)')
    parser.add_argument('--duty', type=float, default=1.0,
                        help='busy share of each worker, 0 < duty <= 1 (default 1: a full core each)')
    add_pressure_arguments(parser)
    parser.add_argument('--json', action='store_true', help='print the summary as JSON')


def say_summary(summary: dict) -> None:
    """Print one line per generator of a load's summary (``kind`` cpu, disk or both)."""
    if summary.get('kind') == 'both':
        for part in ('cpu', 'disk'):
            say_summary(summary[part])
    elif summary.get('kind') == 'disk':
        print(f"load: disk, {summary['wall_s']:.1f} s: {summary['bytes_written'] / 2**20:.0f} MB "
              f"written, {summary['fsyncs']} fsyncs, {summary['files_evicted']} files evicted "
              f"(of {summary['evict_targets']}), {summary['memory_touched_bytes'] / 2**20:.0f} MB "
              f"of memory touched, files removed: {summary['cleaned']}")
    else:
        print(f"load: {summary['workers']} worker(s), {summary['wall_s']:.1f} s, load average "
              f"{summary['load_average_before']:.2f} -> {summary['load_average_now']:.2f}")


def run(args) -> int:
    import json
    import sys
    import time

    from grip_force_ros.lab.bench.load import LoadError
    from grip_force_ros.lab.bench.pressure import describe, make_pressure

    try:
        load = make_pressure(args.kind, seconds=args.seconds, workers=args.workers, duty=args.duty,
                             **({} if args.kind == 'cpu' else pressure_options(args)))
    except (LoadError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    print(f'load: {describe(load)} for {args.seconds:g} s (Ctrl-C stops it)', file=sys.stderr,
          flush=True)
    interrupted = False
    try:
        load.start()
        while load.running():
            time.sleep(0.5)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        summary = load.stop()
    if args.json:
        print(json.dumps(summary))
    else:
        say_summary(summary)
    return 130 if interrupted else 0
