"""`grip-force realdata`: held-out jaw torque from motor current on the MRDLab rig runs."""
from __future__ import annotations

import json
import sys
from pathlib import Path

HELP = ('real instrument data: held-out jaw torque RMSE from motor-side signals, effects, '
        'regions, report')


def add_arguments(parser) -> None:
    parser.add_argument('directory', nargs='?', default=None,
                        help='rig folder with XY.TXT files (default: '
                             '../shared/data/mis-tool-characterization/Tool_4_Maryland_L_2)')
    parser.add_argument('--out', metavar='DIR', default=None,
                        help='write report.md and PNG figures here')
    parser.add_argument('--json', action='store_true', help='print the result as JSON')
    parser.add_argument('--quick', action='store_true',
                        help='fewer splits: estimators on holdout + leave-one-level-out, '
                             'effects on holdout only')


def _summary(result) -> str:
    lines = [f"split: {result['split']['holdout']['description']}"]
    for e in result['estimators']:
        cv = ', '.join(f'{k} {v:.2f}' for k, v in e['cv_rmse_mNm'].items())
        lines.append(f"{e['name']:26s} holdout {e['holdout_rmse_mNm']:6.2f} mN m "
                     f"(after 1 s {e['holdout_rmse_after_startup_mNm']:.2f}); CV {cv}")
    lines.append(f"published (O'Neill et al. 2018)   {result['published_rmse_mNm']:.2f} mN m; "
                 f"beaten on the holdout split: {result['beats_published']}")
    phys = result['estimators'][1]['parameters']['physical']
    lines.append('parameters: ' + ', '.join(f"{k} {v['value']:.4g} +- {v['std']:.2g}"
                                            for k, v in phys.items()))
    top = [r for r in result['regions'] if r['family'] == 'motion'][:2]
    lines.append('largest share of the gap: ' + '; '.join(
        f"{r['where']} {100 * r['share_of_gap']:.0f} %" for r in top))
    if 'report' in result:
        lines.append(f"report: {result['report']}")
    return '\n'.join(lines)


def run(args) -> int:
    from grip_force_ros.rig import RigDataError, default_data_dir, read_runs
    from grip_force_ros.rig.analysis import analyse
    directory = Path(args.directory) if args.directory else default_data_dir()
    try:
        runs = read_runs(directory)
    except RigDataError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    progress = (lambda msg: print(f'[realdata] {msg}', file=sys.stderr))
    result = analyse(runs, quick=args.quick, progress=progress)
    result.pop('_predictions', None)
    result['data']['directory'] = str(directory)
    if args.out:
        from grip_force_ros.rig.report import write_report
        progress('writing report and figures')
        write_report(result, runs, args.out)
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        print(_summary(result))
    return 0
