"""``grip-force bench``: the 1 kHz loop against the middleware floor, model and diagnosis speed.

Prints figures (ratios measured side by side in one run); asserts nothing. See
BENCHMARKS.md for the figures of a 60 s run and what was tried.
"""
from __future__ import annotations

import json
import math
import sys

HELP = 'benchmark: loop latency vs the rclpy floor, model and diagnosis speed (ratios)'


def add_arguments(parser) -> None:
    parser.add_argument('--json', action='store_true', help='print the figures as JSON')
    parser.add_argument('--seconds', type=float, default=20.0,
                        help='measurement window of the floor and of the product loop (s, default 20)')
    parser.add_argument('--parts', default='loop,model,diagnosis',
                        help='comma-separated subset of loop,model,diagnosis (default all)')
    parser.add_argument('--config', default=None,
                        help='instrument YAML (path or shipped name) of the product and the model '
                             "(default: the paper's needle driver)")
    parser.add_argument('--log-minutes', type=float, default=60.0,
                        help='length of the diagnosis log at 1 kHz (min, default 60; built once, cached)')
    parser.add_argument('--model-size', type=int, default=100_000,
                        help='samples per array of the vectorised model figures')
    parser.add_argument('--domain-ids', default=None,
                        help="candidate ROS domains, e.g. '70-99' (default: ROS_DOMAIN_ID if set, "
                             'else 200-232); the first one no other bench run holds is used')
    parser.add_argument('--variants', action='store_true',
                        help='also measure the floor with each executor/QoS/gc/allocation variant')
    parser.add_argument('--variant-seconds', type=float, default=None,
                        help='window of each variant run (s, default --seconds)')
    parser.add_argument('--rt-priority', type=int, default=0, metavar='N',
                        help='run the 1 kHz processes of the floor and the product under SCHED_FIFO N '
                             '(1..99, like chrt -f N; needs CAP_SYS_NICE; default 0 = normal)')
    parser.add_argument('--arms', type=int, default=1, choices=(1, 2),
                        help='products measured at once in the loop part, each with its own sim, '
                             'controller and master in the ROS namespaces /PSM1, /PSM2, ... of one '
                             'domain, in one window, each against the one floor (default 1: one '
                             'product in the root namespace)')
    parser.add_argument('--load-cell', action='store_true',
                        help="close the product controller's force loop on the load cell "
                             '(force_sensor_enabled) and judge it against the contract floor (load '
                             'cell + combined state); default: sensorless as shipped, against the floor')
    from grip_force_ros.lab.cli.load import add_pressure_option
    add_pressure_option(parser, 'the loop part (floor and product alike)')


def _f(value, fmt='.3g') -> str:
    if isinstance(value, (int, float)) and not (isinstance(value, float) and math.isnan(value)):
        return format(value, fmt)
    return 'n/a'


def _goal(value, goal) -> str:
    if not isinstance(value, (int, float)) or value != value:
        return 'n/a'
    return 'meets goal' if value <= goal else 'MISSES goal'


def _met(ok: bool) -> str:
    return 'met' if ok else 'UNMET'


def _render_product(lines: list[str], loop: dict, pad: str) -> None:
    """Append the lines of one product (one arm) against the floor: round trip, full path, goals."""
    pr = loop['product']
    lines.append(f"{pad}product sim->ctrl->sim  p50 {_f(pr['p50_ms'])} ms  p99 {_f(pr['p99_ms'])} ms  "
                 f"max {_f(pr['max_ms'])} ms  missed {_f(loop['missed_fraction'] * 100)} %")
    full, goals, met = loop['full_path'], loop['goals'], loop['goals_met']
    lines.append(f"{pad}full path (sim sample of every input -> command"
                 + ("; the load cell before the state" if loop.get('load_cell') else '') + ")  "
                 f"p50 {_f(full['p50_ms'])} ms  p99 {_f(full['p99_ms'])} ms  max {_f(full['max_ms'])} ms")
    for name, f in full['inputs'].items():
        to, age = f['to_command'], f['age_at_step']
        lines.append(f"{pad}  {name:<9} to command p50 {_f(to['p50_ms'])} / p99 {_f(to['p99_ms'])} / max "
                     f"{_f(to['max_ms'])} ms; age at the step p50 {_f(age['p50_ms'])} / p99 "
                     f"{_f(age['p99_ms'])} ms; same sample as the state "
                     f"{_f(f['same_sample_fraction'] * 100)} %")
    ref = 'contract floor' if loop.get('load_cell') else 'floor'
    lines.append(f"{pad}goals (against the {ref}): p99 ratio {_f(loop['p99_ratio'])} <= "
                 f"{goals['p99_ratio']:g}: "
                 f"{_met(met['p99_ratio'])}; full-path p99 ratio {_f(loop['full_path_p99_ratio'])} <= "
                 f"{goals['full_path_p99_ratio']:g}: {_met(met['full_path_p99_ratio'])}; missed "
                 f"{_f(loop['missed_fraction'] * 100)} % <= {ref}'s + 0.05 % = "
                 f"{_f(goals['missed_fraction'] * 100)} %: {_met(met['missed_fraction'])}"
                 + (f"; controller cpu {_f(loop['controller_cpu_ratio'])} x the echo's <= "
                    f"{goals['controller_cpu_ratio']:g}: {_met(met['controller_cpu_ratio'])}"
                    if 'controller_cpu_ratio' in met else ''))
    if 'contract_floor' in loop and loop.get('load_cell'):
        whole = loop['contract_floor_p99_ratio'] * loop['full_path_over_contract_p99_ratio']
        lines.append(f"{pad}full-path p99 = floor x {_f(whole)}: the topic contract's "
                     f"two messages x {_f(loop['contract_floor_p99_ratio'])} (bare rclpy), this "
                     f"package's code x {_f(loop['full_path_over_contract_p99_ratio'])} "
                     f"(p50: x {_f(loop['contract_floor_p50_ratio'])}, "
                     f"x {_f(loop['full_path_over_contract_p50_ratio'])})")
    lines.append(f"{pad}of which the state publisher's own timer skipped: floor "
                 f"{_f(loop['floor_timer_missed_fraction'] * 100)} %, product "
                 f"{_f(loop['timer_missed_fraction'] * 100)} %; controller timer-fallback commands "
                 f"{loop.get('product_fallback_commands', 'n/a')}")


def render(result: dict) -> str:
    """Human-readable summary of :func:`grip_force_ros.lab.bench.run.run_bench`'s result."""
    lines = []
    m = result['machine']
    lines.append(f"machine: {m['nproc']} cpu ({m['cpu_model']}), python {m['python']}, rclpy {m['rclpy']}, "
                 f"load {m['load_average_1min']:.1f} -> {m.get('load_average_1min_end', float('nan')):.1f}")
    loop = result.get('loop')
    if loop:
        fl = loop['floor']
        rt = f", SCHED_FIFO {loop['rt_priority']}" if loop.get('rt_priority') else ''
        arms = loop.get('arms')
        what = f", {len(arms)} arms at once ({', '.join('/' + a for a in arms)})" if arms else ''
        first = next(iter(arms.values())) if arms else loop
        how = ('controller on the load cell, judged against the contract floor'
               if first.get('load_cell') else 'controller sensorless, judged against the floor')
        lines.append(f"loop ({loop['seconds']:g} s each, ROS_DOMAIN_ID {loop['domain_id']}{rt}{what}; "
                     f"{how}):")
        lines.append(f"  floor   ping-pong       p50 {_f(fl['p50_ms'])} ms  p99 {_f(fl['p99_ms'])} ms  "
                     f"max {_f(fl['max_ms'])} ms  missed {_f(loop['floor_missed_fraction'] * 100)} %")
        if 'contract_floor' in loop:
            cf = loop['contract_floor']
            lines.append(f"  contract floor (2 msgs: load cell, combined state) p50 {_f(cf['p50_ms'])} ms  "
                         f"p99 {_f(cf['p99_ms'])} ms  max {_f(cf['max_ms'])} ms  missed "
                         f"{_f(loop['contract_floor_missed_fraction'] * 100)} %")
        if arms:
            for arm, section in arms.items():
                lines.append(f"  arm /{arm} (against the floor above; its window opened "
                             f"{_f(section.get('window_skew_s', 0.0))} s after the first arm's):")
                _render_product(lines, section, '    ')
            lines.append(f"  every arm met every goal: {'yes' if loop['arms_goals_met'] else 'NO'}")
        else:
            _render_product(lines, loop, '  ')
        pressure = loop.get('pressure') or {}
        for part in ([pressure] if pressure.get('kind') != 'both' else [pressure['cpu'], pressure['disk']]):
            if part.get('kind') == 'disk':
                lines.append(f"  under disk pressure: {part['bytes_written'] / 2**20:.0f} MB written, "
                             f"{part['fsyncs']} fsyncs, {part['files_evicted']} files evicted, "
                             f"{part['memory_touched_bytes'] / 2**20:.0f} MB of memory touched in "
                             f"{part['wall_s']:.0f} s")
            elif part.get('kind') == 'cpu':
                lines.append(f"  under cpu load: {part['workers']} busy process(es) at duty "
                             f"{part['duty']:g}, {part['worker_cpu_s']:.0f} s of CPU in "
                             f"{part['wall_s']:.0f} s")
        cpu = loop['cpu_percent']
        products = cpu['arms'] if arms else {'': cpu['product']}
        lines.append('  cpu % of one core: floor '
                     + ', '.join(f'{k} {v:.0f}' for k, v in cpu['floor'].items())
                     + ''.join(f"; product{' /' + arm if arm else ''} "
                               + ', '.join(f'{k} {v:.0f}' for k, v in c.items())
                               for arm, c in products.items()))
    model = result.get('model')
    if model:
        lines.append(f"model ({model['config']}):")
        lines.append(f"  forward {_f(model['forward_ratio'])} x numpy.exp (goal <= 10: "
                     f"{_goal(model['forward_ratio'], 10)}), inverse {_f(model['inverse_ratio'])} x "
                     f"({_f(model['forward_ns_per_sample'])} / {_f(model['inverse_ns_per_sample'])} ns per "
                     f"sample, exp {_f(model['exp_ns_per_sample'])} ns)")
        lines.append(f"  control step {_f(model['step_us'])} us = {_f(model['step_share'] * 100)} % of "
                     f"{_f(model['period_ms'])} ms (goal <= 5 %: {_goal(model['step_share'], 0.05)}); "
                     f"with the input setters {_f(model['step_and_inputs_share'] * 100)} %")
        for path, r in model.get('other_configs', {}).items():
            lines.append(f"  {path}: forward {_f(r['forward_ratio'])} x, inverse {_f(r['inverse_ratio'])} x"
                         + ('' if r['affine'] else
                            ' (nonlinear: fitted tables, checked against the exact model)'
                            if r.get('fitted') else ' (nonlinear: exact solve per sample)'))
    diag = result.get('diagnosis')
    if diag:
        lines.append(f"diagnosis ({diag['minutes']:g} min at 1 kHz, {diag['rows']} rows, "
                     f"{diag['file_mb']:.0f} MB CSV):")
        lines.append(f"  load {diag['load_s']:.2f} s, diagnose {diag['diagnose_s']:.2f} s: ratio "
                     f"{_f(diag['load_ratio'])} (goal <= 5: {_goal(diag['load_ratio'], 5)}); peak RSS "
                     f"load {diag['load_peak_mb']:.0f} MB, diagnose {diag['diagnose_peak_mb']:.0f} MB "
                     f"(+{diag['diagnose_added_mb']:.0f} MB over its start-up)")
    for row in result.get('variants', []):
        lines.append(f"  floor variant [{row['label']}]: p50 {_f(row['p50_ms'])} p99 {_f(row['p99_ms'])} "
                     f"max {_f(row['max_ms'])} ms, missed {_f(row['missed_fraction'] * 100)} %, cpu "
                     + ', '.join(f'{k} {v:.0f}' for k, v in row['cpu_percent'].items()))
    return '\n'.join(lines)


def run(args) -> int:
    from grip_force_ros.lab.bench.procs import BenchError
    from grip_force_ros.lab.bench.run import PARTS, parse_domains, run_bench
    from grip_force_ros.params.files import instrument_path

    parts = tuple(p.strip() for p in args.parts.split(',') if p.strip())
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        print(f'grip-force bench: unknown part(s) {unknown}; choose from {list(PARTS)}', file=sys.stderr)
        return 2
    if args.seconds <= 0 or args.log_minutes <= 0:
        print('grip-force bench: --seconds and --log-minutes must be > 0', file=sys.stderr)
        return 2
    if not 0 <= args.rt_priority <= 99:
        print('grip-force bench: --rt-priority must be in 0..99', file=sys.stderr)
        return 2
    if args.rt_priority:
        from grip_force_ros.lab.processes import can_use_realtime
        if not can_use_realtime(args.rt_priority):
            print('grip-force bench: SCHED_FIFO not permitted here (needs CAP_SYS_NICE or an rtprio '
                  'limit); run without --rt-priority', file=sys.stderr)
            return 2
    try:
        config = str(instrument_path(args.config))
    except FileNotFoundError as exc:
        print(f'grip-force bench: {exc}', file=sys.stderr)
        return 2
    pressure_options = {}
    if args.pressure in ('disk', 'both'):
        from grip_force_ros.lab.bench.load import LoadError
        from grip_force_ros.lab.bench.pressure import make_pressure
        from grip_force_ros.lab.cli.load import pressure_options as disk_options
        pressure_options = disk_options(args)
        try:        # its bounds checked before any measurement
            make_pressure('disk', seconds=args.seconds, **pressure_options)
        except (LoadError, OSError) as exc:
            print(f'grip-force bench: {exc}', file=sys.stderr)
            return 2
    say = (lambda msg: print(f'[bench] {msg}', file=sys.stderr, flush=True))
    try:
        result = run_bench(args.seconds, parts, domains=parse_domains(args.domain_ids), config=config,
                           log_minutes=args.log_minutes, model_size=args.model_size,
                           variants=args.variants, variant_seconds=args.variant_seconds,
                           rt_priority=args.rt_priority,
                           pressure=args.pressure, pressure_options=pressure_options,
                           arms=args.arms, load_cell=args.load_cell, say=say)
    except BenchError as exc:
        print(f'grip-force bench: {exc}', file=sys.stderr)
        return 1
    print(json.dumps(result, indent=2) if args.json else render(result))
    return 0
