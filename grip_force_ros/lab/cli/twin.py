"""`grip-force twin`: an instrument file identified from rig runs (grip_force_ros.lab.rig.twin)."""
from __future__ import annotations

import json
import sys

HELP = ('instrument twin: fit the transmission terms (friction, spring, efficiency, gain) on rig '
        'runs and write an instrument file the sim and the controller load')


def add_arguments(parser) -> None:
    parser.add_argument('--rig', nargs='+', required=True, metavar='DIR',
                        help='rig folders with XY.TXT runs (paths, or names under '
                             '../shared/data/mis-tool-characterization)')
    parser.add_argument('--base', required=True, metavar='X.yaml',
                        help='instrument file giving what the rig cannot (routing, motor, moment '
                             'arms, limits, gains)')
    parser.add_argument('--out', required=True, metavar='Y.yaml', help='instrument file to write')
    parser.add_argument('--json', action='store_true',
                        help='print {parameters: {name: {value, std, unit}}, heldout_rmse (N*m), ...}')


def run(args) -> int:
    from grip_force_ros.lab.rig import RigDataError
    from grip_force_ros.lab.rig.estimator import EstimatorError
    from grip_force_ros.lab.rig.twin import identify, write
    from grip_force_ros.params import ParameterError, load_params_file, read_params_yaml
    try:
        load_params_file(args.base)
        twin = identify(args.rig, read_params_yaml(args.base),
                        progress=lambda msg: print(f'[twin] {msg}', file=sys.stderr))
        write(twin, args.base, args.out)
    except (RigDataError, EstimatorError, ParameterError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(dict(twin.to_json(), file=str(args.out)), indent=1))
        return 0
    for name, p in twin.parameters.items():
        spread = '' if p['std'] is None else f" +- {p['std']:.2g}"
        print(f"{name:30s} {p['value']:.4g}{spread} {p['unit']}")
    print(f'held-out jaw torque RMSE {twin.heldout_rmse * 1e3:.2f} mN*m '
          f'({twin.heldout_rmse_after_startup * 1e3:.2f} after the first second); wrote {args.out}')
    for note in twin.notes:
        print(f'note: {note}')
    return 0
