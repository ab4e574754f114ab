"""`grip-force realdata`: held-out jaw torque from motor current on the MRDLab rig runs.

Two forms:

* ``grip-force realdata [DIR]``: fit and judge inside one folder (holdout split,
  cross-validation, effects, regions, report);
* ``grip-force realdata --train DIR [DIR ...] --test DIR [--calibrate RUN ...]``: fit on
  the training folders, judge every run of another folder, zero-shot or after one
  calibration run whose jaw torque is read (:mod:`grip_force_ros.lab.rig.transfer`).
"""
from __future__ import annotations

import json
import sys
from dataclasses import replace
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
    parser.add_argument('--train', nargs='+', metavar='DIR', default=None,
                        help='transfer: fit on these folders (paths, or names under '
                             '../shared/data/mis-tool-characterization)')
    parser.add_argument('--test', metavar='DIR', default=None,
                        help='transfer: judge on every run of this folder')
    parser.add_argument('--calibrate', nargs='+', metavar='RUN', default=(),
                        help="transfer: runs of the test folder whose jaw torque may be read "
                             "(e.g. 21 or 21.TXT; 'auto' = the default rule: mid frequency, mid "
                             "load); never scored. Without it: zero-shot")
    parser.add_argument('--groups', nargs='+', metavar='GROUP', default=None,
                        help='transfer: calibration groups (default: every group of '
                             'grip_force_ros.lab.rig.transfer.GROUPS; listed in docs/real_data.md)')
    parser.add_argument('--sweep', action='store_true',
                        help='transfer: also every single run of the test folder as the '
                             'calibration run (mean, worst, best)')
    parser.add_argument('--ablation', action='store_true',
                        help='transfer: each calibration group alone and all but one')
    parser.add_argument('--floor', metavar='DIR', default=None,
                        help='in-folder floor of the transfer model: cross-validation inside '
                             'this folder and where the error lies (with --out: the figure)')
    parser.add_argument('--no-consistency', action='store_true',
                        help='transfer: leave out the session consistency (the motor side of '
                             'every test run moving the calibration groups); zero-shot is then '
                             'the trained model as it is')
    parser.add_argument('--offline', action='store_true',
                        help='transfer: score the offline estimate of the recorded runs (the '
                             'observer forward and backward in time; the start of a run gets '
                             'its own level) instead of the real-time one')
    parser.add_argument('--oneill', nargs='?', const='Tool_4_Maryland_L_4', metavar='DIR', default=None,
                        help="score the estimator under O'Neill et al. 2018's protocol (random "
                             '70/15/15 split of the samples, closing portions; default folder '
                             'Tool_4_Maryland_L_4), beside the published 4.42 mN m')
    parser.add_argument('--no-load-model', action='store_true',
                        help='transfer: the observer averages the jaw torque itself instead of '
                             'the load level with the load\'s learned shape along the stroke '
                             '(the model before the load model)')


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


def _transfer_summary(result) -> str:
    mode = 'zero-shot' if result['zero_shot'] else \
        'calibrated on ' + ', '.join(result['calibration']['runs'])
    train = ' + '.join(f['folder'] for f in result['train'])
    lines = [f"train {train} -> test {result['test']['folder']} ({mode})",
             f"held-out RMSE {result['heldout_rmse'] * 1e3:.2f} mN m over "
             f"{len(result['per_run'])} runs (published {result['published_rmse_mNm']:.2f}); "
             f"worst run {result['worst_run']['file']} {result['worst_run']['rmse'] * 1e3:.2f}"]
    lines.append(f"after the first second {result['heldout_rmse_after_startup'] * 1e3:.2f} mN m; the "
                 f"start-up ({100 * result['startup']['fraction_of_samples']:.1f} % of the samples) "
                 f"holds {100 * result['startup']['share_of_squared_error']:.0f} % of the squared error")
    if not result['zero_shot']:
        lines.append(f"zero-shot on the same runs {result['zero_shot_heldout_rmse'] * 1e3:.2f} mN m")
    tare = result['test']['current_tare']
    lines.append(f"test folder: spindle {result['test']['spindle']} ({result['test']['spindle_source']}), "
                 f"current sensor zero {tare['zero_A'] * 1e3:.1f} mA, flips "
                 f"{result['test']['motor_side_orientation']['flips_against_header_convention'] or 'none'}")
    if 'sweep' in result:
        sw = result['sweep']
        lines.append(f"every run as the calibration run: mean {sw['mean'] * 1e3:.2f}, worst "
                     f"{sw['worst'] * 1e3:.2f}, best {sw['best'] * 1e3:.2f} mN m")
    for row in result.get('ablation', {}).get('rows', []):
        extra = f", sweep mean {row['sweep_mean'] * 1e3:.2f}" if 'sweep_mean' in row else ''
        lines.append(f"  {row['groups']:24s} {row['heldout_rmse'] * 1e3:6.2f} mN m{extra}")
    lines.append(f"runtime {result['runtime_s']:.1f} s")
    return '\n'.join(lines)


def _run_transfer(args) -> int:
    from grip_force_ros.lab.rig import RigDataError
    from grip_force_ros.lab.rig.estimator import EstimatorError
    from grip_force_ros.lab.rig.transfer import GROUP_NAMES, TRANSFER_SETTINGS, transfer
    if not args.test:
        print('error: --train needs --test', file=sys.stderr)
        return 2
    progress = (lambda msg: print(f'[realdata] {msg}', file=sys.stderr))
    try:
        result = transfer(args.train, args.test, calibrate_runs=list(args.calibrate),
                          groups=tuple(args.groups) if args.groups else GROUP_NAMES,
                          with_sweep=args.sweep, with_ablation=args.ablation,
                          consistency=not args.no_consistency, offline=args.offline,
                          progress=progress,
                          settings=replace(TRANSFER_SETTINGS, load_model=not args.no_load_model))
    except (RigDataError, EstimatorError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        print(_transfer_summary(result))
    return 0


def _floor_summary(result) -> str:
    lines = [f"in-folder floor of {result['folder']} ({result['runs']} runs)"]
    for label, rows in result['cross_validation'].items():
        lines.append(f'{label:16s} ' + ', '.join(
            f"{k} {v['rmse_mNm']:.2f} ({v['rmse_after_startup_mNm']:.2f} after 1 s)"
            for k, v in rows.items()))
    bound = result['two_sided_bound_even_odd']
    lines.append(f"two-sided (non-causal) bound, even/odd: {bound['rmse_mNm']:.2f} "
                 f"({bound['rmse_after_startup_mNm']:.2f} after 1 s) mN m")
    start = result['startup_bound']
    lines.append(f"start-up ({100 * start['startup_fraction_of_samples']:.1f} % of samples) alone: "
                 f"whole-run RMSE >= {start['bound_one_value_mNm']:.2f} mN m with one start-up "
                 f"value, >= {start['bound_linear_in_startup_current_mNm']:.2f} linear in the "
                 f"start-up current (oracles; published {start['published_rmse_mNm']:.2f})")
    for row in result['breakdown']['transfer_model']['by_phase']:
        lines.append(f"  {row['phase']:36s} {100 * row['fraction_of_samples']:5.1f} % of samples, "
                     f"RMSE {row['rmse_mNm']:6.2f}, "
                     f"{100 * row['share_of_squared_error']:4.1f} % of the error")
    lines.append(f"runtime {result['runtime_s']:.1f} s")
    return '\n'.join(lines)


def _run_floor(args) -> int:
    from grip_force_ros.lab.rig import RigDataError
    from grip_force_ros.lab.rig.estimator import EstimatorError
    from grip_force_ros.lab.rig.floor import analyse_floor
    from grip_force_ros.lab.rig.transfer import load_folder
    progress = (lambda msg: print(f'[realdata] {msg}', file=sys.stderr))
    try:
        result = analyse_floor(load_folder(args.floor), quick=args.quick, out_dir=args.out,
                               progress=progress)
    except (RigDataError, EstimatorError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(json.dumps(result, indent=1, default=float) if args.json else _floor_summary(result))
    return 0


def _run_oneill(args) -> int:
    from grip_force_ros.lab.rig import RigDataError
    from grip_force_ros.lab.rig.oneill import score
    try:
        result = score(args.oneill, progress=lambda msg: print(f'[realdata] {msg}', file=sys.stderr))
    except RigDataError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"O'Neill protocol on {result['folder']}: test RMSE mean {result['mean_test_rmse_mNm']:.2f}, "
              f"worst {result['worst_test_rmse_mNm']:.2f} mN m over {len(result['seeds'])} seeds "
              f"(published {result['published_rmse_mNm']:.2f}; raw-current line "
              f"{result['mean_linear_test_rmse_mNm']:.2f})\n{result['protocol']}")
    return 0


def run(args) -> int:
    if args.oneill:
        return _run_oneill(args)
    if args.floor:
        return _run_floor(args)
    if args.train or args.test:
        if not args.train:
            print('error: --test needs --train', file=sys.stderr)
            return 2
        return _run_transfer(args)
    from grip_force_ros.lab.rig import RigDataError, default_data_dir, read_runs
    from grip_force_ros.lab.rig.analysis import analyse
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
        from grip_force_ros.lab.rig.report import write_report
        progress('writing report and figures')
        write_report(result, runs, args.out)
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        print(_summary(result))
    return 0
