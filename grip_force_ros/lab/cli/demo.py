"""`grip-force demo`: the closed loop on ROS 2, one needle grasp, recorded and plotted.

Starts ``master``, ``sim_instrument`` and ``controller`` as separate processes
(DDS on loopback, a free ROS domain), runs the needle grasp (approach, close,
hold, pull test, release) with live progress, records a rosbag2 (MCAP) of
every topic, writes a summary plot and prints target vs measured grip force,
pull-out force and the hold-phase errors. ``--compare-instruments`` runs the
same master trajectory on three instruments (see docs/demo.md).
"""
from __future__ import annotations

import json
import math
import signal
import sys
import time
from pathlib import Path

#: Length of the demo's needle grasp (s): the scripted task at half speed.
DEMO_DURATION = 10.0
#: Hard stop of the --pressure generator (s): a demo that runs longer goes on without it.
PRESSURE_SECONDS = 3600.0

HELP = 'run the closed-loop needle-grasp demo over ROS 2 (or --compare-instruments)'


def add_arguments(parser) -> None:
    parser.add_argument('--config', default=None,
                        help="instrument YAML (path, or name in config/); default: the paper's "
                             'needle driver')
    parser.add_argument('--duration', type=float, default=None,
                        help='length of the needle-grasp task in s (default 10; 6 per run of '
                             '--compare-instruments)')
    parser.add_argument('--out', help='output directory (default out/demo/<UTC timestamp>)')
    parser.add_argument('--json', action='store_true', help='print the results as JSON on stdout')
    parser.add_argument('--domain-id', type=int, help='ROS_DOMAIN_ID (default: a free one)')
    parser.add_argument('--compare-instruments', action='store_true',
                        help='the same master trajectory on the shipped instruments: calibrated '
                             'sensorless, uncalibrated, load cell and naive; prints the spreads')
    parser.add_argument('--configs', nargs='+', metavar='YAML',
                        help='instruments of --compare-instruments (default: config/*.yaml '
                             'except maryland; with --plants: the controller file of each plant, '
                             'default the plant\'s own)')
    parser.add_argument('--plants', nargs='+', metavar='YAML',
                        help='--compare-instruments: the simulated plants\' instrument files, in '
                             'place of the shipped instruments off by --plant-error (e.g. twins of '
                             'rig folders, grip-force twin)')
    parser.add_argument('--plant-error', type=float, default=0.2,
                        help='--compare-instruments: relative error of the simulated plant\'s '
                             'friction and cable stiffness vs the YAML (default %(default)s)')
    parser.add_argument('--parallel', action='store_true',
                        help='--compare-instruments: run the instruments of each stage at the '
                             'same time, one ROS domain each (needs a core per instrument: on a '
                             'loaded machine the controllers miss their 30 ms watchdog)')
    parser.add_argument('--interface', choices=('crtk', 'dvrk'), default='crtk',
                        help='topic profile of the nodes: crtk (default) or dvrk (the sim plays a '
                             'dVRK arm, 100 Hz, jaw effort in N*m; docs/dvrk.md)')
    parser.add_argument('--arm', default='PSM1', help='--interface dvrk: the arm (default PSM1)')
    parser.add_argument('--master', default='MTML',
                        help='--interface dvrk: the master (default MTML)')
    parser.add_argument('--arms', type=int, default=1, choices=(1, 2),
                        help='needle grasps at once, each arm with its own sim, controller and master '
                             'in the ROS namespaces /PSM1, /PSM2, ... of one domain, recorded and '
                             'analysed apart (<out>/PSM1/, ...; crtk only; default 1)')
    parser.add_argument('--quiet', action='store_true', help='no live progress')
    parser.add_argument('--rt-priority', type=int, default=None, metavar='N',
                        help='SCHED_FIFO priority of the 1 kHz nodes (sim, controller), like chrt -f N '
                             '(default 50 where the machine permits it, as ros2_control runs its '
                             'loop; else normal scheduling, said in the JSON "scheduling"; '
                             '0 = normal scheduling)')
    from grip_force_ros.lab.cli.load import add_pressure_option
    add_pressure_option(parser, 'the demo (its summary: "pressure" in the JSON)')


def _write_report(report: dict, out: Path, args, load, show) -> None:
    """Add the pressure summary, write ``out/results.json``, print it (--json) or ``show`` it."""
    if args.pressure != 'none':
        report['pressure'] = load.last_summary
    (out / 'results.json').write_text(json.dumps(report, indent=1))
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        show(report)


def _print_with_pressure(report: dict) -> None:
    """Print the single-arm report, then the pressure summary when there was a load."""
    print_report(report)
    if 'pressure' in report:
        from grip_force_ros.lab.cli.load import say_summary
        say_summary(report['pressure'])


def _default_out(kind: str) -> Path:
    return Path('out') / kind / time.strftime('%Y%m%d-%H%M%S', time.gmtime())


def _sigterm_as_interrupt() -> None:
    def handler(_signum, _frame):
        raise KeyboardInterrupt
    try:
        signal.signal(signal.SIGTERM, handler)
    except ValueError:  # pragma: no cover - not the main thread
        pass


def _interrupted_exit() -> int:
    print('interrupted: every node was stopped', file=sys.stderr)
    return 130


def _fmt(value, spec='.3f', unit=' N') -> str:
    return f'{value:{spec}}{unit}' if isinstance(value, (int, float)) and math.isfinite(value) \
        else 'n/a'


def print_report(result: dict, stream=sys.stdout) -> None:
    """Print the human-readable end of a demo run."""
    m = result['metrics'] or {}
    w = stream.write
    w(f"instrument        {result['instrument']} ({result['config']})\n")
    if result.get('interface') == 'dvrk':
        w(f"interface         dvrk: arm {result['arm']}, master {result['master']} (jaw effort in "
          'N*m, 100 Hz states)\n')
    w(f"task              needle grasp, {result['duration']:.2f} s, "
      f"ROS domain {result['domain_id']}\n")
    w(f"steady hold       target {_fmt(m.get('target_force'))}, measured (load cell) "
      f"{_fmt(m.get('measured_force'))}, estimated (model) {_fmt(m.get('estimated_force'))}\n")
    w(f"hold-phase error  mean {_fmt(m.get('hold_error_mean'), '+.3f')}, rms "
      f"{_fmt(m.get('hold_error_rms'))}, max {_fmt(m.get('hold_error_max'))} "
      f"({_fmt(100 * m.get('hold_error_rel', float('nan')), '+.1f', ' %')} of target)\n")
    w(f"settling          {_fmt(m.get('settling_time'), '.3f', ' s')} to within 5 % of target\n")
    w(f"pull test         pull-out force {_fmt(m.get('pull_out_force'))} (estimated), grip "
      f"{_fmt(m.get('pull_grip_force'))} (load cell)\n")
    w(f"estimate vs cell  rms {_fmt(m.get('estimate_error_rms'))} over the steady hold\n")
    w(f"peak current      {_fmt(m.get('peak_current'), '.3f', ' A')}\n")
    late = result.get('late_inputs') or {}
    by_source = ', '.join(f"{k} {v['count']} (oldest {v['max_ms']:.1f} ms)"
                          for k, v in late.items() if k != 'total')
    w(f"late inputs       {late.get('total', 0)} during the task"
      + (f': {by_source}; control went on with the last values' if by_source else '') + '\n')
    events = result.get('safe_state_entries') or []
    w(f"safe state        {len(events)} entr{'y' if len(events) == 1 else 'ies'} during the task"
      + (f" (first at {events[0]['t']:.2f} s: {events[0]['reason']})" if events else '')
      + (' (an input lost: older than its watchdog timeout)' if events else '') + '\n')
    for problem in result.get('problems') or []:
        w(f"WARNING           {problem} (a starved node: the machine is overloaded)\n")
    sched = result.get('scheduling') or {}
    if sched:
        w('scheduling        ' + ', '.join(f'{k} {v}' for k, v in sched.items()) + '\n')
    w(f"bag               {result['bag']} ({sum(result['messages'].values())} messages)\n")
    w(f"plot              {result['plot']}\n")


def print_arms_report(report: dict, stream=sys.stdout) -> None:
    """Print the human-readable end of a several-arm demo run: one block per arm."""
    w = stream.write
    arms = report['arms']
    w(f"{len(arms)} arms at once in ROS domain {report['domain_id']}: "
      + ', '.join(f"/{name} {'held' if r['grasp_held'] else 'NOT held'}" for name, r in arms.items())
      + f" (every grasp held: {'yes' if report['arms_held'] else 'NO'})\n")
    for name, r in arms.items():
        w(f"\n--- arm /{name} ---\n")
        print_report(r, stream)
    w(f"\nresults           {report['results']}\n")


def _run_arms(args, config, params, out: Path, load) -> int:
    """``--arms N`` (N > 1): the grasps of N arms at once, their reports and results.json."""
    from grip_force_ros.lab.bench.loop import ARM_NAMESPACES
    from grip_force_ros.lab.demo.run import Progress, RunSpec, grasp_held, run_arms
    from grip_force_ros.lab.processes import reserve_domains

    names = ARM_NAMESPACES[:args.arms]
    held = reserve_domains(1) if args.domain_id is None else None
    domain = args.domain_id if held is None else held.domain_id
    specs = [RunSpec(config=config, duration=args.duration or DEMO_DURATION,
                     label=params.instrument_name, namespace=name,
                     **({} if args.rt_priority is None else {'rt_priority': args.rt_priority}))
             for name in names]
    shown: list = []

    def progress(name):
        if args.quiet:
            return None
        p = Progress(_PlainStream(sys.stderr), label=f'/{name}')
        shown.append(p)
        return p

    if not args.quiet:
        sys.stderr.write(f"grip-force demo: {params.instrument_name}, {args.arms} arms "
                         f"({', '.join('/' + n for n in names)}), ROS domain {domain}, output {out}\n")
    try:
        with load:
            results = run_arms(specs, out, domain, progress=progress)
    finally:
        for p in shown:
            p.close()
        if held is not None:
            held.release()
    arms = {}
    for name, result in results.items():
        r = result.as_dict()
        r['instrument'] = params.instrument_name
        r['grasp_held'] = grasp_held(result.metrics, result.problems)
        (result.out_dir / 'results.json').write_text(json.dumps(r, indent=1))
        arms[name] = r
    report = {'instrument': params.instrument_name, 'config': str(config), 'domain_id': domain,
              'arms': arms, 'arms_held': all(r['grasp_held'] for r in arms.values()),
              'out_dir': str(out), 'results': str(out / 'results.json')}
    _write_report(report, out, args, load, print_arms_report)
    return 0


class _PlainStream:
    """A stream that is never a TTY: several arms' progress as plain lines, not redrawn in place."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> None:
        self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()


def _pressure(args):
    """Build the --pressure generator of ``args`` (not started); LoadError beyond its bounds."""
    from grip_force_ros.lab.bench.pressure import make_pressure
    from grip_force_ros.lab.cli.load import pressure_options
    options = pressure_options(args) if args.pressure in ('disk', 'both') else {}
    return make_pressure(args.pressure, seconds=PRESSURE_SECONDS, **options)


def run(args) -> int:
    from grip_force_ros.lab.bench.load import LoadError
    from grip_force_ros.lab.bench.pressure import describe
    from grip_force_ros.lab.demo.recorder import interrupt_behind
    from grip_force_ros.lab.processes import ProcessError, reserve_domains
    from grip_force_ros.params import ParameterError, load_params_file
    from grip_force_ros.params.files import instrument_path

    _sigterm_as_interrupt()
    if args.duration is not None and args.duration <= 0:
        print('error: --duration must be > 0 s', file=sys.stderr)
        return 2
    if args.rt_priority is not None and not 0 <= args.rt_priority <= 99:
        print('error: --rt-priority must be 0 (normal scheduling) or 1..99', file=sys.stderr)
        return 2
    if args.out and Path(args.out).exists() and any(Path(args.out).iterdir()):
        # a run writes bags, which are never overwritten: refuse before starting any node
        print(f'error: --out {args.out} is not empty; choose a new directory', file=sys.stderr)
        return 2
    try:
        load = _pressure(args)
    except (LoadError, OSError) as exc:
        print(f'error: --pressure: {exc}', file=sys.stderr)
        return 2
    if args.pressure != 'none' and not args.quiet:
        sys.stderr.write(f'grip-force demo: under pressure, {describe(load)}\n')
    try:
        if args.compare_instruments and args.arms > 1:
            print('error: --compare-instruments runs one arm at a time (no --arms)', file=sys.stderr)
            return 2
        if args.compare_instruments and args.interface != 'crtk':
            print('error: --compare-instruments runs the crtk profile only', file=sys.stderr)
            return 2
        if args.compare_instruments:
            from grip_force_ros.lab.demo.compare import TASK_DURATION, compare_instruments
            out = Path(args.out) if args.out else _default_out('compare')
            configs = [instrument_path(c) for c in args.configs] if args.configs else None
            plants = [instrument_path(c) for c in args.plants] if args.plants else None
            with load:
                report = compare_instruments(
                    out, configs=configs, plants=plants, plant_error=args.plant_error,
                    parallel=args.parallel, domain_id=args.domain_id,
                    task_duration=args.duration or TASK_DURATION,
                    log=None if args.quiet else sys.stderr, rt_priority=args.rt_priority)
            if args.pressure != 'none':
                report['pressure'] = load.last_summary
            if args.json:
                print(json.dumps(report, indent=1))
            else:
                from grip_force_ros.lab.demo.compare import format_report
                print(format_report(report))
            return 0

        from grip_force_ros.lab.demo.run import Progress, RunSpec, run_task
        config = instrument_path(args.config)
        params = load_params_file(config)
        out = Path(args.out) if args.out else _default_out('demo')
        if args.arms > 1:
            if args.interface != 'crtk':
                print('error: --arms runs the crtk profile only', file=sys.stderr)
                return 2
            return _run_arms(args, config, params, out, load)
        # a free domain, held until this run ends (no other run on the machine takes it)
        held = reserve_domains(1) if args.domain_id is None else None
        domain = args.domain_id if held is None else held.domain_id
        spec = RunSpec(config=config, duration=args.duration or DEMO_DURATION,
                       label=params.instrument_name, interface=args.interface, arm=args.arm,
                       master=args.master,
                       **({} if args.rt_priority is None else {'rt_priority': args.rt_priority}))
        progress = None if args.quiet else Progress(sys.stderr)
        if progress is not None:
            sys.stderr.write(f'grip-force demo: {params.instrument_name}, {args.interface} '
                             f'interface, ROS domain {domain}, output {out}\n')
        try:
            with load:
                result = run_task(spec, out, domain, progress=progress)
        finally:
            if progress is not None:
                progress.close()
        report = result.as_dict()
        report['instrument'] = params.instrument_name
        _write_report(report, out, args, load, _print_with_pressure)
        return 0
    except KeyboardInterrupt:
        return _interrupted_exit()
    except Exception as exc:
        if interrupt_behind(exc):
            return _interrupted_exit()
        if isinstance(exc, (ProcessError, ParameterError, FileNotFoundError, ValueError)):
            print(f'error: {exc}', file=sys.stderr)
            return 1
        raise
