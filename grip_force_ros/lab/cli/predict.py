"""`grip-force predict`: run the nominal model over a log and add the model's columns."""
from __future__ import annotations

import sys

from grip_force_ros.objects import OBJECTS

HELP = ('run the nominal model over a log (CSV contract or rosbag2; inputs only suffice) and write a CSV '
        'with grip_force_model, pull_out_force_model, jaw_angle_model: the prediction diagnose compares '
        'against')

#: Columns added to the log.
ADDED_COLUMNS = ('grip_force_model', 'pull_out_force_model', 'jaw_angle_model')


def add_arguments(parser) -> None:
    parser.add_argument('--config', required=True, metavar='YAML', help='instrument YAML')
    parser.add_argument('--input', required=True, metavar='LOG',
                        help='log: CSV in the docs/design.md contract, or a rosbag2 bag; the measured '
                             'column (grip_force or jaw_torque) is optional')
    parser.add_argument('--output', required=True, metavar='CSV', help='CSV to write')
    parser.add_argument('--object', default='needle', choices=OBJECTS,
                        help="object for rows without an 'object' column (default: needle)")
    parser.add_argument('--loading-branch', action='store_true',
                        help="the paper's quasi-static form: pulley friction always in the loading "
                             'direction, no stick, jaw angle without the cable stretch')
    parser.add_argument('--rate', type=float, default=200.0,
                        help='analysis rate (Hz) of the direction-aware nominal, as diagnose --rate: the '
                             'log is block-averaged to it and the prediction interpolated back (default 200)')
    parser.add_argument('--ideal', action='store_true', help='model without losses')


def predict_log(log: dict, params, default_object: str = 'needle', losses: bool = True,
                loading_branch: bool = False, analysis_rate: float = 200.0) -> dict:
    """Return a copy of ``log`` with the model columns added (numpy arrays).

    By default the nominal prediction the diagnosis compares against
    (:func:`grip_force_ros.lab.diagnosis.frame.nominal`): the model's pulley friction in the
    direction the cable slips, stick in between (the capstan band, with the wrist moving a
    stuck cable), and the jaw angle with the cable's stretch under those tensions; computed,
    as the diagnosis does, on the log block-averaged to ``analysis_rate`` (the stick state is
    a play operator of the current: at a sensor's full rate its noise would ratchet it) and
    interpolated back to the log's rows. With ``loading_branch`` the paper's quasi-static
    form (:meth:`GripForceModel.forward` with the log's velocity columns,
    :meth:`GripForceModel.jaw_angle`), row by row.

    Parameters
    ----------
    log : dict of str to ndarray
        Columns ``t`` (s), ``current`` (A), ``motor_angle``, ``wrist_angle``, ``jaw_angle``
        (rad), optional ``object`` (str), ``motor_velocity`` and ``jaw_velocity`` (rad/s; the
        loading branch's inertial term), ``grip_force`` / ``jaw_torque`` (not needed).
    params : ParamSet
        Instrument parameters.
    default_object : str
        Object where the log has no ``object`` column.
    losses : bool
        False: the ideal model (no friction, no creep).
    loading_branch : bool
        The paper's quasi-static form instead of the direction-aware nominal.
    analysis_rate : float
        Rate (Hz) of the direction-aware nominal (the diagnosis' ``analysis_rate``).

    Returns
    -------
    dict
        ``log`` plus ``grip_force_model`` (N), ``pull_out_force_model`` (N; NaN where
        not modelled: rigid, tissue), ``jaw_angle_model`` (rad) and, for a log with
        ``jaw_torque``, ``jaw_torque_model`` (N*m, the drive torque M).

    Raises
    ------
    DiagnosisError
        A log too short for the direction-aware nominal (fewer than 20 finite samples).
    """
    import numpy as np

    from grip_force_ros.model import GripForceModel
    from grip_force_ros.model.contact import needle_pull_out
    model = GripForceModel(params, losses=losses)
    n = len(log['t'])
    objects = np.asarray(log['object'], dtype=str) if 'object' in log else np.full(n, default_object)
    out = dict(log)
    if loading_branch:
        zeros = np.zeros(n)
        motor_velocity = np.asarray(log.get('motor_velocity', zeros), float)
        jaw_velocity = np.asarray(log.get('jaw_velocity', zeros), float)
        grip, pull, torque = np.zeros(n), np.zeros(n), np.zeros(n)
        for obj in np.unique(objects):
            rows = objects == obj
            result = model.forward(log['current'][rows], log['wrist_angle'][rows], log['jaw_angle'][rows],
                                   str(obj), motor_velocity[rows], jaw_velocity[rows])
            grip[rows], pull[rows], torque[rows] = result.grip_force, result.pull_out_force, result.jaw_torque
        jaw = np.asarray(model.jaw_angle(log['motor_angle'], log['wrist_angle'], log['current']), float)
    else:
        from grip_force_ros.lab.diagnosis.frame import frame_inputs, load_decimated, nominal
        decimated = load_decimated({k: v for k, v in {**log, 'object': objects}.items()
                                    if k not in ('grip_force', 'jaw_torque')}, analysis_rate, measured=False)
        inputs = frame_inputs(decimated, measured='jaw_torque' if 'jaw_torque' in log else 'grip_force',
                              default_object=default_object, require_measured=False)
        nom = nominal(inputs, model)
        t = np.asarray(log['t'], float)

        def back(x):         # the analysis rate's prediction at the log's rows
            return np.interp(t, inputs['t'], np.where(inputs['finite'], x, np.nan))

        torque = back(nom['torque'])
        grip = back(np.maximum(nom['torque'], 0.0) * nom['gain'])
        # the model's pull-out force of that grip: needle only (NaN for rigid and tissue, 0 free)
        pull = np.where(objects == 'needle', needle_pull_out(grip, params.needle_friction_coefficient),
                        np.where(objects == 'free', 0.0, np.nan))
        jaw = back(nom['jaw_model'] + nom['stretch'])
    out['grip_force_model'] = grip
    out['pull_out_force_model'] = pull
    if 'jaw_torque' in log:                 # a rig that measures torque at the jaw: compare like with like
        out['jaw_torque_model'] = torque
    out['jaw_angle_model'] = jaw
    return out


def run(args) -> int:
    from grip_force_ros.lab.diagnosis import DiagnosisError
    from grip_force_ros.logs import LogError, read_log, write_csv
    from grip_force_ros.model import ModelError
    from grip_force_ros.params import ParameterError, load_params_file
    try:
        params = load_params_file(args.config)
        log = read_log(args.input, measured=False)
        out = predict_log(log, params, args.object, losses=not args.ideal, loading_branch=args.loading_branch,
                          analysis_rate=args.rate)
        write_csv(args.output, out, measured=False)
    except (ParameterError, ModelError, LogError, DiagnosisError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    form = 'loading branch' if args.loading_branch else 'direction-aware nominal (as diagnose)'
    print(f'{args.output}: {len(out["t"])} rows, added {", ".join(ADDED_COLUMNS)} ({form})', file=sys.stderr)
    return 0
