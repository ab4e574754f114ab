"""`grip-force predict`: run the forward model over a log and add the model's columns."""
from __future__ import annotations

import sys

from grip_force_ros.objects import OBJECTS

HELP = ('run the forward model over a log (CSV contract or rosbag2) and write a CSV with '
        'grip_force_model, pull_out_force_model, jaw_angle_model')

#: Columns added to the log.
ADDED_COLUMNS = ('grip_force_model', 'pull_out_force_model', 'jaw_angle_model')


def add_arguments(parser) -> None:
    parser.add_argument('--config', required=True, metavar='YAML', help='instrument YAML')
    parser.add_argument('--input', required=True, metavar='LOG',
                        help='log: CSV in the docs/design.md contract, or a rosbag2 bag')
    parser.add_argument('--output', required=True, metavar='CSV', help='CSV to write')
    parser.add_argument('--object', default='needle', choices=OBJECTS,
                        help="object for rows without an 'object' column (default: needle)")
    parser.add_argument('--ideal', action='store_true', help='model without losses')


def predict_log(log: dict, params, default_object: str = 'needle', losses: bool = True) -> dict:
    """Return a copy of ``log`` with the model columns added (numpy arrays).

    Parameters
    ----------
    log : dict of str to ndarray
        Columns ``current`` (A), ``motor_angle``, ``wrist_angle``, ``jaw_angle`` (rad),
        optional ``object`` (str), ``motor_velocity`` and ``jaw_velocity`` (rad/s).
    params : ParamSet
        Instrument parameters.
    default_object : str
        Object where the log has no ``object`` column.
    losses : bool
        False: the ideal model (no friction, no creep).

    Returns
    -------
    dict
        ``log`` plus ``grip_force_model`` (N), ``pull_out_force_model`` (N; NaN where
        not modelled: rigid, tissue) and ``jaw_angle_model`` (rad).
    """
    import numpy as np

    from grip_force_ros.model import GripForceModel
    model = GripForceModel(params, losses=losses)
    n = len(log['t'])
    objects = np.asarray(log['object'], dtype=str) if 'object' in log else np.full(n, default_object)
    zeros = np.zeros(n)
    motor_velocity = np.asarray(log.get('motor_velocity', zeros), float)
    jaw_velocity = np.asarray(log.get('jaw_velocity', zeros), float)
    grip, pull, torque = np.zeros(n), np.zeros(n), np.zeros(n)
    for obj in np.unique(objects):
        rows = objects == obj
        result = model.forward(log['current'][rows], log['wrist_angle'][rows], log['jaw_angle'][rows],
                               str(obj), motor_velocity[rows], jaw_velocity[rows])
        grip[rows], pull[rows], torque[rows] = result.grip_force, result.pull_out_force, result.jaw_torque
    out = dict(log)
    out['grip_force_model'] = grip
    out['pull_out_force_model'] = pull
    if 'jaw_torque' in log:                 # a rig that measures torque at the jaw: compare like with like
        out['jaw_torque_model'] = torque
    out['jaw_angle_model'] = np.asarray(model.jaw_angle(log['motor_angle'], log['wrist_angle'],
                                                        log['current']), float)
    return out


def run(args) -> int:
    from grip_force_ros.logs import LogError, read_log, write_csv
    from grip_force_ros.model import ModelError
    from grip_force_ros.params import ParameterError, load_params_file
    try:
        params = load_params_file(args.config)
        log = read_log(args.input)
        out = predict_log(log, params, args.object, losses=not args.ideal)
        write_csv(args.output, out)
    except (ParameterError, ModelError, LogError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    print(f'{args.output}: {len(out["t"])} rows, added {", ".join(ADDED_COLUMNS)}', file=sys.stderr)
    return 0
