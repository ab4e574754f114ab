"""Logs -> analysis frames: block-averaged signals, the model's nominal prediction, features.

A frame is a dict of equal-length float arrays at the analysis rate (default
200 Hz). Logs are streamed and block-averaged chunk by chunk, so a 1 h log at
1 kHz never sits in memory at full rate: memory grows with duration x analysis
rate (about 60 MB per hour at 200 Hz).
"""
from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np
from scipy.signal import lfilter

from grip_force_ros.logs import LogError, iter_log, measured_column, normalise_log
from grip_force_ros.logs.columns import OBJECT_COLUMN
from grip_force_ros.model.contact import contact_gain
from grip_force_ros.model.jaw_friction import dahl_direction
from grip_force_ros.objects import OBJECTS

#: Time (s) after the predicted load starts or stops that is left out as a transient.
SETTLE_TIME = 0.2
#: Current steps (A/s of the 20 ms smoothed current) whose mechanical response (cable and
#: contact dynamics, ~10 ms) the quasi-static model does not describe; left out for STEP_HOLD s.
STEP_RATE = 4.0
STEP_HOLD = 0.05


class DiagnosisError(ValueError):
    """The diagnosis cannot run on these logs (too short, no contact, mixed measured columns)."""


def _block_mean(values: np.ndarray, factor: int) -> np.ndarray:
    n = (values.size // factor) * factor
    return values[:n].reshape(-1, factor).mean(axis=1)


def decimate(log: Mapping[str, np.ndarray], factor: int) -> dict[str, np.ndarray]:
    """Block-average every numeric column by ``factor`` (object: first of each block)."""
    if factor <= 1:
        return dict(log)
    out = {}
    for k, v in log.items():
        if k == OBJECT_COLUMN:
            n = (v.size // factor) * factor
            out[k] = v[:n:factor]
        else:
            out[k] = _block_mean(v, factor)
    return out


def _factor_for(t: np.ndarray, analysis_rate: float) -> int:
    if t.size < 2:
        return 1
    dt = float(np.median(np.diff(t)))
    return max(1, int(round(1.0 / (dt * analysis_rate))))


def load_decimated(source, analysis_rate: float = 200.0, *, chunk_rows: int = 200_000,
                   progress=None, measured: bool = True) -> dict[str, np.ndarray]:
    """Read a log (path or dict) and block-average it to about ``analysis_rate`` (Hz).

    A path is streamed in chunks (CSV) so the full-rate log is never held whole.
    ``progress(rows)`` is called per chunk. ``measured=False`` accepts a log of inputs only.
    """
    if isinstance(source, Mapping):
        log = normalise_log(source, measured=measured)
        return decimate(log, _factor_for(log['t'], analysis_rate))
    parts: dict[str, list[np.ndarray]] = {}
    factor = None
    carry: dict[str, np.ndarray] | None = None
    rows = 0
    for chunk in iter_log(source, chunk_rows=chunk_rows, measured=measured):
        if carry:
            chunk = {k: np.concatenate([carry[k], v]) for k, v in chunk.items()}
        if factor is None:
            factor = _factor_for(chunk['t'], analysis_rate)
        n = (chunk['t'].size // factor) * factor
        carry = {k: v[n:] for k, v in chunk.items()}
        for k, v in decimate({k: v[:n] for k, v in chunk.items()}, factor).items():
            parts.setdefault(k, []).append(v)
        rows += n
        if progress is not None:
            progress(rows)
    if not parts:
        raise LogError(f'{source}: no data rows')
    return {k: np.concatenate(v) for k, v in parts.items()}


def lowpass(x: np.ndarray, dt: float, time_constant: float, initial: float | None = None) -> np.ndarray:
    """First-order low-pass (unit DC gain), time constant in s, sample time dt in s."""
    a = np.exp(-dt / time_constant)
    zi = [a * (x[0] if initial is None else initial)]
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=zi)
    return y


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Direction with memory in [-1, 1]: a backlash (play) operator of full width ``width``.

    The state follows ``x`` with a lag of at most width/2; the output is
    (x - state)/(width/2): +1 after ``x`` has risen by at least ``width``, -1
    after it has fallen by as much, in between after a reversal (stiction).
    """
    half = 0.5 * width
    out = np.empty_like(x)
    z = float(x[0])
    xs = x.tolist()
    for i, xi in enumerate(xs):
        if xi - half > z:
            z = xi - half
        elif xi + half < z:
            z = xi + half
        out[i] = z
    return (x - out) / half


def play_sliding(x: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the :func:`play` output and where its state moves (the input slides beyond the band).

    Returns
    -------
    direction : ndarray
        As :func:`play`, in [-1, 1].
    sliding : ndarray of bool
        True where the play's state moved at this sample: ``x`` has travelled the full
        band since its last reversal and keeps going; False while it sits inside the band
        (stuck, or reversing).
    """
    direction = play(x, width)
    state = x - direction * (0.5 * width)
    sliding = np.abs(np.diff(state, prepend=state[0])) > 1e-12 * max(1.0, width)
    return direction, sliding


def hold_where_stuck(values: np.ndarray, sliding: np.ndarray) -> np.ndarray:
    """Hold ``values`` (rows) where not ``sliding``: the last value seen while sliding.

    Where ``sliding``, ``values`` itself; before any sliding, the first value.
    """
    idx = np.maximum.accumulate(np.where(sliding, np.arange(len(values)), 0))
    return values[idx]


def capstan_tension(drum_tension: np.ndarray, efficiency: np.ndarray,
                    jaw_side_change: np.ndarray | None = None, *,
                    tolerance: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Jaw-side cable tension (N) with the pulley friction acting in the direction of slip.

    The model's chain efficiency ``lambda`` holds while the drum pulls (loading):
    ``Tn = lambda T0``. When the jaw pulls back (unloading) the friction reverses,
    ``T0 = lambda Tn``; in between the cable sticks on the pulleys and ``Tn`` stays
    put. So ``Tn`` is ``T0`` passed through a clamp with memory::

        Tn[k] = clip(Tn[k-1] + jaw_side_change[k], lambda T0[k], T0[k] / lambda)

    ``jaw_side_change`` (N per sample) is what the jaw side does to a stuck cable
    (the wrist pulling or releasing it). This is the model's own friction; on a
    loading branch it equals ``GripForceModel.forward``.

    Where the tension starts to pull (``T0`` turns positive, e.g. the jaw closing on
    an object) the stuck tension is unknown anywhere in the band: both extremes are
    carried through the clamp, and samples where they still differ by more than
    ``tolerance`` (relative) are flagged.

    Returns
    -------
    tension : ndarray
        Jaw-side tension (N), the loading-side path.
    uncertain : ndarray of bool
        True where the stuck tension is not yet determined by the history.
    """
    f0 = np.asarray(drum_tension, float)
    lam = np.broadcast_to(np.asarray(efficiency, float), f0.shape)
    with np.errstate(divide='ignore', invalid='ignore'):
        a = lam * f0
        b = np.where(lam > 0, f0 / lam, f0)
    lo = np.minimum(a, b).tolist()
    hi = np.maximum(a, b).tolist()
    n = f0.size
    step = [0.0] * n if jaw_side_change is None else np.asarray(jaw_side_change, float).tolist()
    pulling = (f0 > 0).tolist()
    out = np.empty(n)
    spread = np.zeros(n)
    low = high = (lo[0] if n and f0[0] >= 0 else (hi[0] if n else 0.0))
    was_pulling = False
    for i in range(n):
        if pulling[i] and not was_pulling:
            low, high = lo[i], hi[i]
        was_pulling = pulling[i]
        low += step[i]
        high += step[i]
        if low < lo[i]:
            low = lo[i]
        elif low > hi[i]:
            low = hi[i]
        if high < lo[i]:
            high = lo[i]
        elif high > hi[i]:
            high = hi[i]
        out[i] = low
        spread[i] = high - low
    uncertain = spread > tolerance * np.maximum(np.abs(out), 1e-9)
    return out, uncertain


def frame_inputs(log: Mapping[str, np.ndarray], *, measured: str | None = None,
                 default_object: str = 'needle', require_measured: bool = True) -> dict:
    """Return the parameter-free part of a frame: signals, smoothed velocities, objects, current steps.

    Parameters
    ----------
    log : mapping
        Contract columns (see :mod:`grip_force_ros.logs`), usually block-averaged.
    measured : {'grip_force', 'jaw_torque'}, optional
        Which column to explain; found from the log when omitted.
    default_object : str
        Object assumed when the log has no ``object`` column.
    require_measured : bool
        False: a log with inputs only (``y`` is then NaN).

    Returns
    -------
    dict
        ``t`` (s), ``dt`` (s), ``measured`` (name), ``y`` (measured column), ``finite``
        (bool), ``current`` (A), ``wrist``, ``jaw``, ``motor`` (rad), ``jaw_velocity``,
        ``motor_velocity`` (rad/s, 20 ms smoothed), ``objects`` (str), ``codes`` (object
        codes), ``current_rate`` (A/s), ``stepping`` (bool: within STEP_HOLD of a current step).
    """
    if measured is None:
        try:
            measured = measured_column(log)
        except LogError:
            if require_measured:
                raise
            measured = 'grip_force'
    if measured not in log and require_measured:
        raise DiagnosisError(f'log has no {measured!r} column')
    t = np.asarray(log['t'], float)
    if t.size < 20:
        raise DiagnosisError(f'log too short for a diagnosis ({t.size} samples after averaging)')
    dt = float(np.median(np.diff(t)))
    raw = {k: np.asarray(log[k], float) for k in ('current', 'wrist_angle', 'jaw_angle', 'motor_angle')}
    y = np.asarray(log[measured], float) if measured in log else np.full(t.size, np.nan)
    # samples with a missing (non-finite) value are carried as 0 and left out of every fit
    finite = np.logical_and.reduce([np.isfinite(v) for v in raw.values()]
                                   + ([np.isfinite(y)] if measured in log else []))
    if finite.sum() < 20:
        raise DiagnosisError(f'log has only {int(finite.sum())} samples with every value finite')
    raw = {k: np.where(finite, v, 0.0) for k, v in raw.items()}
    current, wrist, jaw, motor = (raw['current'], raw['wrist_angle'], raw['jaw_angle'], raw['motor_angle'])
    objects = np.asarray(log.get(OBJECT_COLUMN, np.full(t.size, default_object)), dtype=str)
    codes = np.zeros(t.size)
    for name in np.unique(objects):
        codes[objects == name] = OBJECTS.index(str(name))
    current_rate = np.gradient(lowpass(current, dt, 0.02), t)
    stepping = np.abs(current_rate) > STEP_RATE
    if stepping.any():
        hold = max(1, int(round(STEP_HOLD / dt)))
        stepping = np.convolve(stepping.astype(float), np.ones(hold + 1), mode='full')[:t.size] > 0
    return {'t': t, 'dt': dt, 'measured': measured, 'y': np.where(finite, y, 0.0) if measured in log else y,
            'finite': finite, 'current': current, 'wrist': wrist, 'jaw': jaw, 'motor': motor,
            'jaw_velocity': np.gradient(lowpass(jaw, dt, 0.02), t),
            'motor_velocity': np.gradient(lowpass(motor, dt, 0.02), t),
            'objects': objects, 'codes': codes, 'current_rate': current_rate, 'stepping': stepping}


def cable_lengths(params, jaw_side_cable_length: float | None = None) -> tuple[float, float]:
    """Free cable length (m) on the drum side and on the jaw side of the guide pulleys.

    From the schema's ``cable_length`` and ``cable_jaw_side_fraction`` (the cable of the
    simulated plant, our stated assumption for any instrument); ``jaw_side_cable_length``
    (m) replaces the jaw side when given.
    """
    total = float(params.cable_length)
    share = float(params.cable_jaw_side_fraction)
    jaw_side = share * total if jaw_side_cable_length is None else float(jaw_side_cable_length)
    return (1.0 - share) * total, jaw_side


def nominal(inputs: Mapping, model, *, direction_aware: bool = True,
            jaw_side_cable_length: float | None = None) -> dict[str, np.ndarray]:
    """Return the model's part of a frame: the nominal prediction, tensions, model jaw angle, stretch.

    Parameters
    ----------
    inputs : mapping
        :func:`frame_inputs` of a log.
    model : GripForceModel
        The nominal model of the instrument (its parameters: ``model.params``).
    direction_aware : bool
        Apply the model's pulley friction in the direction of cable slip
        (:func:`capstan_tension`); False: the loading branch (``GripForceModel.forward``).
        Either way an instrument with jaw friction terms gets them, in the friction state
        of its drum angle (:mod:`grip_force_ros.model.jaw_friction`).
    jaw_side_cable_length : float, optional
        Free cable length (m) between the pulleys and the jaw (:func:`cable_lengths`):
        sets how fast the wrist moves a stuck cable across the friction band (stiffness
        E A / length) and the jaw side's share of the stretch.

    Returns
    -------
    dict of str to ndarray
        ``nominal`` (prediction of the measured column: grip force N, or drive torque
        N*m for ``jaw_torque``), ``torque`` (N*m, drive torque M), ``drum_tension`` /
        ``jaw_tension`` (N), ``efficiency`` (-), ``gain`` (1/m, grip force per drive
        torque), ``uncertain`` (bool: the stuck tension is not yet determined),
        ``jaw_model`` (rad, model jaw angle from the drum angle) and ``stretch`` (rad: the
        jaw angle the cable's elastic stretch adds, ``(L_d T0 + L_j Tn) / (E A r_n)``; its two
        parts ``stretch_drum`` and ``stretch_jaw``).
    """
    current, wrist, jaw = inputs['current'], inputs['wrist'], inputs['jaw']
    objects = inputs['objects']
    n = current.size
    p = model.params
    torque = np.zeros(n)            # model drive torque M (N*m), loading branch
    drum_tension = np.zeros(n)      # F0 (N)
    efficiency = np.ones(n)         # lambda_n (-)
    gain = np.zeros(n)              # contact gain G (1/m): grip force per drive torque
    for name in np.unique(objects):
        sel = objects == name
        r = model.forward(current[sel], wrist[sel], jaw[sel], obj=str(name),
                          motor_velocity=inputs['motor_velocity'][sel],
                          jaw_velocity=inputs['jaw_velocity'][sel])
        torque[sel] = r.jaw_torque
        drum_tension[sel] = r.drum_tension
        efficiency[sel] = r.efficiency
        gain[sel] = contact_gain(str(name), jaw[sel], p.jaw_moment_arm_tip, p.jaw_moment_arm_inner)
    rn = p.drive_pulley_radius
    section = p.cable_modulus * np.pi * p.cable_radius ** 2                               # E A (N)
    drum_side, jaw_side = cable_lengths(p, jaw_side_cable_length)
    if direction_aware:
        f = p.drive_resistance_fraction
        dt = inputs['dt']
        # loading branch: M = r_n F0 (lambda - f) = r_n (1 - f/lambda) Tn with Tn = lambda F0, so
        # M = forward torque + r_n (1 - f/lambda) (Tn - lambda F0) with the slip-direction Tn
        with np.errstate(divide='ignore', invalid='ignore'):
            arm = rn * np.maximum(1.0 - f / efficiency, 0.0)                # m
        # cable pulled in at the jaw a = r_n (c wrist - jaw): a stuck cable's jaw side tension
        # falls by k da (k: jaw-side cable stiffness E A / L_j)
        k = section / jaw_side                                                            # N/m
        pulled = rn * (p.wrist_finger_coupling * lowpass(wrist, dt, 0.02) - lowpass(jaw, dt, 0.02))
        change = -k * np.diff(pulled, prepend=pulled[0])
        tn, uncertain = capstan_tension(drum_tension, efficiency, change)
        torque = torque + arm * (tn - efficiency * drum_tension)
    else:
        tn, uncertain = efficiency * drum_tension, np.zeros(n, dtype=bool)
    friction = getattr(model, 'jaw_friction', None)
    if friction is not None and friction.active:
        # the instrument's jaw friction and spring (model/jaw_friction.py), its friction state
        # following the drum angle (through a reversal the Dahl state moves the friction across)
        direction = dahl_direction(np.asarray(inputs['motor'], float), friction.width)
        torque = friction.jaw_torque_array(torque, jaw, direction, inputs['jaw_velocity'])
    predicted = torque if inputs['measured'] == 'jaw_torque' else np.maximum(torque, 0.0) * gain
    return {'nominal': np.asarray(predicted, float), 'torque': torque, 'drum_tension': drum_tension,
            'jaw_tension': tn, 'efficiency': efficiency, 'gain': gain, 'uncertain': uncertain,
            'jaw_model': np.asarray(model.jaw_angle(inputs['motor'], wrist, current), float),
            'stretch_drum': drum_side * drum_tension / (section * rn),
            'stretch_jaw': jaw_side * tn / (section * rn),
            'stretch': (drum_side * drum_tension + jaw_side * tn) / (section * rn)}


def build_frame(log: Mapping[str, np.ndarray], model, *, measured: str | None = None,
                default_object: str = 'needle', direction_aware: bool = True,
                jaw_side_cable_length: float | None = None) -> dict[str, np.ndarray]:
    """Analysis frame of one (decimated) log: signals, nominal prediction and features.

    :func:`frame_inputs` and :func:`nominal` (see them for ``measured``,
    ``default_object``, ``direction_aware`` and ``jaw_side_cable_length``), joined by
    :func:`assemble_frame`.
    """
    return assemble_frame(frame_inputs(log, measured=measured, default_object=default_object), model,
                          direction_aware=direction_aware, jaw_side_cable_length=jaw_side_cable_length)


def assemble_frame(inputs: Mapping, model, *, direction_aware: bool = True,
                   jaw_side_cable_length: float | None = None) -> dict[str, np.ndarray]:
    """Analysis frame from a log's :func:`frame_inputs` and the model ``model``.

    Returns
    -------
    dict of str to ndarray
        ``t`` (s from the log start), ``dt`` (s, scalar array), ``y`` (measured),
        ``nominal`` (model prediction of ``y``), ``torque`` (N*m, drive torque M),
        ``gain`` (1/m, grip force per drive torque; 1 for jaw torque logs),
        ``drum_tension`` / ``jaw_tension`` (N, cable tension at the drum / jaw side),
        ``stretch`` (rad, jaw angle added by the cable's stretch), ``contact`` (0/1),
        ``current`` (A), ``current_rate`` (A/s), ``jaw``/``wrist``/``motor`` angles (rad),
        ``jaw_velocity``/``motor_velocity`` (rad/s), ``jaw_model`` (rad, model jaw
        angle from the drum angle), ``load_time`` (s under load), ``object`` (code),
        ``steady`` (1 where fits and scores may use the sample).
    """
    t = inputs['t']
    nom = nominal(inputs, model, direction_aware=direction_aware, jaw_side_cable_length=jaw_side_cable_length)
    codes = inputs['codes']
    if inputs['measured'] == 'jaw_torque':
        # a jaw torque rig holds the jaw against its load through the whole stroke: loaded
        # wherever the log names an object (the current's sign says which way the drive
        # slides, not whether the jaw is loaded: with friction larger than the load it flips
        # at every stroke under a constant load)
        contact = (codes > 0).astype(float)
    else:
        contact = ((nom['nominal'] > 0) & (codes > 0)).astype(float)
    # time under load (s): resets whenever the prediction says no load
    loaded = contact > 0
    load_time = np.zeros(t.size)
    if loaded.any():
        idx = np.arange(t.size)
        start = np.maximum.accumulate(np.where(~loaded, idx, 0))
        load_time = np.where(loaded, t - t[start], 0.0)
    # transients: the jaw hitting or leaving the object (impact, fly-off) within SETTLE_TIME
    # of a change of the predicted load state; left out of every fit and score
    changes = np.flatnonzero(np.diff(loaded.astype(np.int8)) != 0) + 1
    near = np.zeros(t.size, dtype=bool)
    if changes.size:
        after = np.searchsorted(t[changes], t, side='right') - 1
        valid = after >= 0
        near[valid] = (t[valid] - t[changes[after[valid]]]) < SETTLE_TIME
    return {'t': t - t[0], 'dt': np.array(inputs['dt']), 'y': inputs['y'],
            'max_current': np.array(float(model.params.max_current)),
            'steady': (~near & ~nom['uncertain'] & ~inputs['stepping'] & inputs['finite']).astype(float),
            'torque': nom['torque'],
            'gain': np.ones(t.size) if inputs['measured'] == 'jaw_torque' else nom['gain'],
            'drum_tension': nom['drum_tension'], 'jaw_tension': nom['jaw_tension'], 'stretch': nom['stretch'],
            'stretch_drum': nom['stretch_drum'], 'stretch_jaw': nom['stretch_jaw'],
            'nominal': nom['nominal'], 'contact': contact, 'current': inputs['current'],
            'current_rate': inputs['current_rate'], 'jaw': inputs['jaw'], 'wrist': inputs['wrist'],
            'motor': inputs['motor'], 'jaw_velocity': inputs['jaw_velocity'],
            'motor_velocity': inputs['motor_velocity'], 'jaw_model': nom['jaw_model'], 'load_time': load_time,
            'object': codes}


def measured_of(logs: Iterable[Mapping[str, np.ndarray]]) -> str:
    """Return the one measured column shared by all ``logs``."""
    names = {measured_column(log) for log in logs}
    if len(names) != 1:
        raise DiagnosisError(f'logs mix measured columns {sorted(names)}; diagnose them separately')
    return names.pop()
