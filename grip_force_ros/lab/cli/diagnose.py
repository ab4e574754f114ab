"""`grip-force diagnose`: where the model disagrees with logs, which effect, how far it shrinks."""
from __future__ import annotations

import json
import sys
import time

from grip_force_ros.objects import OBJECTS

HELP = 'diagnose the sim-to-real gap of logs (CSV or rosbag2): where, which effect, how far'


def add_arguments(parser) -> None:
    parser.add_argument('logs', nargs='*', metavar='LOG',
                        help='logs (CSV, rosbag2 directory, .mcap or .db3); split into time blocks '
                             'when no --test is given')
    parser.add_argument('--config', required=True, metavar='YAML', help='instrument parameter YAML')
    parser.add_argument('--train', nargs='+', default=[], metavar='LOG', help='logs to fit on')
    parser.add_argument('--test', nargs='+', default=[], metavar='LOG',
                        help='held-out logs (never fitted); needs LOG or --train')
    parser.add_argument('--json', action='store_true', help='print the result as one JSON object')
    parser.add_argument('--report', metavar='DIR', help='write report.md and PNG figures into DIR')
    parser.add_argument('--object', default='needle', choices=OBJECTS,
                        help='object assumed when a log has no object column (default: needle)')
    parser.add_argument('--rate', type=float, default=200.0,
                        help='analysis rate (Hz): logs are block-averaged to it (default 200)')
    parser.add_argument('--quiet', action='store_true', help='no progress on stderr')
    parser.add_argument('--adopt', metavar='OUT.yaml',
                        help='write the --config file with the verdict\'s effects as instrument terms '
                             '(and the re-identified parameters), diagnose the same logs against it, '
                             'and add adopted: {file, gap_before, gap_after, ...} to the result')


def _parameters(calibration: dict) -> str:
    """One line: each re-identified parameter, YAML -> fitted (+- std), and those named off."""
    parts = []
    for name, p in calibration.get('parameters', {}).items():
        fitted = (f"{p['fitted']:.4g} +- {p['std']:.2g}" if p.get('std') is not None else 'held')
        parts.append(f"{name} {p['yaml']:.4g} -> {fitted}{' (off)' if p.get('off') else ''}")
    return '; '.join(parts) or 'none fitted'


def _summary(result: dict) -> str:
    v = result['verdict']
    lines = [f"verdict: {v['effect']}  (runner-up {v['runner_up']})",
             f"held-out gap ({result['measured']}): {v['gap_before']:.4g} -> {v['gap_after']:.4g} "
             f"{v['unit']} rms (shrink {100 * v['shrink']:.0f} %)",
             f"jaw angle gap: {v['angle_gap_before']:.4g} -> {v['angle_gap_after']:.4g} rad rms",
             f"split: {result['split'].get('description', result['split']['method'])}",
             'parameters (YAML -> re-identified): ' + _parameters(result['calibration']),
             f"calibration: force gain {result['calibration']['force_gain']['value']:.4g}, "
             f"jaw zero {result['calibration']['jaw_angle_offset']['value']:.4g} rad",
             'where (share of the held-out gap):']
    for r in result['regions'][:5]:
        lines.append(f"  {r['share_of_gap']:5.2f}  {r['where']}  (samples {r['share_of_samples']:.2f})")
    lines.append('which (held-out score, lower is better):')
    for r in result['ranking'][:5]:
        lines.append(f"  {r['score']:7.3f}  {r['effect']:28s} rmse {r['holdout_rmse']:.4g}")
    return '\n'.join(lines)


def _adopt(result: dict, args, loaded: list, n_train: int, say) -> dict:
    """Write the adopted file, diagnose the same logs against it: the result's ``adopted``."""
    from grip_force_ros.lab.diagnosis import run_diagnosis
    from grip_force_ros.lab.diagnosis.adopt import write
    from grip_force_ros.params import load_params_file, read_params_yaml
    values, skipped = write(result, args.config, args.adopt, read_params_yaml(args.config))
    say(f'adopted {", ".join(values) or "nothing"} into {args.adopt}; diagnosing against it')
    again = run_diagnosis(loaded[:n_train], loaded[n_train:] or None, load_params_file(args.adopt),
                          analysis_rate=args.rate, default_object=args.object, progress=say).result
    before, after = result['verdict'], again['verdict']
    return {'file': str(args.adopt), 'gap_before': before['gap_before'], 'gap_after': after['gap_before'],
            'shrink': 1.0 - after['gap_before'] / before['gap_before'] if before['gap_before'] else 0.0,
            'unit': before['unit'], 'terms': {k: v[0] for k, v in values.items()},
            'not_adopted': skipped, 'verdict_after': after['effects'],
            'gap_after_with_its_effects': after['gap_after']}


def run(args) -> int:
    from grip_force_ros.lab.diagnosis import DiagnosisError, run_diagnosis
    from grip_force_ros.logs import LogError
    from grip_force_ros.params import ParameterError, load_params_file

    def say(msg):
        if not args.quiet:
            print(f'[diagnose] {msg}', file=sys.stderr, flush=True)

    train = list(args.logs) + list(args.train)
    if not train:
        print('error: give at least one LOG (or --train LOG...)', file=sys.stderr)
        return 2
    try:
        params = load_params_file(args.config)
        start = time.perf_counter()
        loaded = []
        for path in train + list(args.test):
            def rows(n, path=path):
                say(f'{path}: {n} rows read')
            from grip_force_ros.lab.diagnosis.frame import load_decimated
            loaded.append(load_decimated(path, args.rate, progress=rows))
        say(f'logs read in {time.perf_counter() - start:.1f} s')
        d = run_diagnosis(loaded[:len(train)], loaded[len(train):] or None, params,
                          analysis_rate=args.rate, default_object=args.object, progress=say)
    except (ParameterError, LogError, DiagnosisError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    d.result['logs'] = {'train': train, 'test': list(args.test)}
    if args.adopt:
        try:
            d.result['adopted'] = _adopt(d.result, args, loaded, len(train), say)
        except (ParameterError, DiagnosisError) as exc:
            print(f'error: --adopt: {exc}', file=sys.stderr)
            return 1
    if args.report:
        from grip_force_ros.lab.diagnosis import write_report
        path = write_report(d, args.report, sources=train + list(args.test))
        d.result['report'] = str(path)
        say(f'report: {path}')
    say(f'done in {time.perf_counter() - start:.1f} s')
    if args.json:
        print(json.dumps(d.result, indent=1, default=float))
    else:
        print(_summary(d.result))
        if 'adopted' in d.result:
            a = d.result['adopted']
            print(f"adopted into {a['file']}: {', '.join(a['terms']) or 'nothing'}; held-out gap "
                  f"{a['gap_before']:.4g} -> {a['gap_after']:.4g} {a['unit']} rms (shrink "
                  f"{100 * a['shrink']:.0f} %), verdict against it: {' + '.join(a['verdict_after'])}")
            for s in a['not_adopted']:
                print(f"  not adopted: {s['effect']}: {s['reason']}")
    return 0
