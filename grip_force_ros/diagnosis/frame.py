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
from grip_force_ros.objects import OBJECTS

#: Time (s) after the predicted load starts or stops that is left out as a transient.
SETTLE_TIME = 0.2
#: Jaw-side free length of the cable (m) for the stick phase of the pulley friction: an
#: assumption (about 2 cm from the last guide pulley to the jaw of an 8 mm instrument).
JAW_SIDE_CABLE_LENGTH = 0.02
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
                   progress=None) -> dict[str, np.ndarray]:
    """Read a log (path or dict) and block-average it to about ``analysis_rate`` (Hz).

    A path is streamed in chunks (CSV) so the full-rate log is never held whole.
    ``progress(rows)`` is called per chunk.
    """
    if isinstance(source, Mapping):
        log = normalise_log(source)
        return decimate(log, _factor_for(log['t'], analysis_rate))
    parts: dict[str, list[np.ndarray]] = {}
    factor = None
    carry: dict[str, np.ndarray] | None = None
    rows = 0
    for chunk in iter_log(source, chunk_rows=chunk_rows):
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
    """Hold ``values`` where not ``sliding``: the last value seen while sliding.

    Where ``sliding``, ``values`` itself; before any sliding, the first value.
    """
    idx = np.maximum.accumulate(np.where(sliding, np.arange(values.size), 0))
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


def build_frame(log: Mapping[str, np.ndarray], model, *, measured: str | None = None,
                default_object: str = 'needle', direction_aware: bool = True,
                jaw_side_cable_length: float = JAW_SIDE_CABLE_LENGTH) -> dict[str, np.ndarray]:
    """Analysis frame of one (decimated) log: signals, nominal prediction and features.

    Parameters
    ----------
    log : mapping
        Contract columns (see :mod:`grip_force_ros.logs`), usually block-averaged.
    model : GripForceModel
        The nominal model of the instrument.
    measured : {'grip_force', 'jaw_torque'}, optional
        Which column to explain; found from the log when omitted.
    default_object : str
        Object assumed when the log has no ``object`` column.
    direction_aware : bool
        Apply the model's pulley friction in the direction of cable slip
        (:func:`capstan_tension`) instead of the loading direction only.
    jaw_side_cable_length : float
        Free cable length (m) between the pulleys and the jaw: sets how fast the wrist
        moves a stuck cable across the friction band (stiffness E A / length).

    Returns
    -------
    dict of str to ndarray
        ``t`` (s from the log start), ``dt`` (s, scalar array), ``y`` (measured),
        ``nominal`` (model prediction of ``y``), ``torque`` (N*m, drive torque M),
        ``gain`` (1/m, grip force per drive torque; 1 for jaw torque logs),
        ``drum_tension`` / ``jaw_tension`` (N, cable tension at the drum / jaw side),
        ``contact`` (0/1), ``current`` (A),
        ``current_rate`` (A/s), ``jaw``/``wrist``/``motor`` angles (rad),
        ``jaw_velocity``/``motor_velocity`` (rad/s), ``jaw_model`` (rad, model jaw
        angle from the drum angle), ``load_time`` (s under load), ``object`` (code).
    """
    measured = measured or measured_column(log)
    if measured not in log:
        raise DiagnosisError(f'log has no {measured!r} column')
    t = np.asarray(log['t'], float)
    if t.size < 20:
        raise DiagnosisError(f'log too short for a diagnosis ({t.size} samples after averaging)')
    dt = float(np.median(np.diff(t)))
    raw = {k: np.asarray(log[k], float)
           for k in ('current', 'wrist_angle', 'jaw_angle', 'motor_angle', measured)}
    # samples with a missing (non-finite) value are carried as 0 and left out of every fit
    finite = np.logical_and.reduce([np.isfinite(v) for v in raw.values()])
    if finite.sum() < 20:
        raise DiagnosisError(f'log has only {int(finite.sum())} samples with every value finite')
    raw = {k: np.where(finite, v, 0.0) for k, v in raw.items()}
    current, wrist, jaw, motor = (raw['current'], raw['wrist_angle'], raw['jaw_angle'], raw['motor_angle'])
    jaw_vel = np.gradient(lowpass(jaw, dt, 0.02), t)
    motor_vel = np.gradient(lowpass(motor, dt, 0.02), t)
    objects = np.asarray(log.get(OBJECT_COLUMN, np.full(t.size, default_object)), dtype=str)
    codes = np.zeros(t.size)
    torque = np.zeros(t.size)            # model drive torque M (N*m), loading branch
    drum_tension = np.zeros(t.size)      # F0 (N)
    efficiency = np.ones(t.size)         # lambda_n (-)
    gain = np.zeros(t.size)              # contact gain G (1/m): grip force per drive torque
    for name in np.unique(objects):
        sel = objects == name
        codes[sel] = OBJECTS.index(str(name))
        r = model.forward(current[sel], wrist[sel], jaw[sel], obj=str(name),
                          motor_velocity=motor_vel[sel], jaw_velocity=jaw_vel[sel])
        torque[sel] = r.jaw_torque
        drum_tension[sel] = r.drum_tension
        efficiency[sel] = r.efficiency
        gain[sel] = contact_gain(str(name), jaw[sel], model.params.jaw_moment_arm_tip,
                                 model.params.jaw_moment_arm_inner)
    if direction_aware:
        rn = model.params.drive_pulley_radius
        f = model.params.drive_resistance_fraction
        # loading branch: M = r_n F0 (lambda - f) = r_n (1 - f/lambda) Tn with Tn = lambda F0, so
        # M = forward torque + r_n (1 - f/lambda) (Tn - lambda F0) with the slip-direction Tn
        with np.errstate(divide='ignore', invalid='ignore'):
            arm = rn * np.maximum(1.0 - f / efficiency, 0.0)                # m
        # cable pulled in at the jaw a = r_n (c wrist - jaw): a stuck cable's jaw side tension
        # falls by k da (k: jaw-side cable stiffness E A / L, L = JAW_SIDE_CABLE_LENGTH assumed)
        p = model.params
        k = p.cable_modulus * np.pi * p.cable_radius ** 2 / jaw_side_cable_length      # N/m
        pulled = rn * (p.wrist_finger_coupling * lowpass(wrist, dt, 0.02) - lowpass(jaw, dt, 0.02))
        change = -k * np.diff(pulled, prepend=pulled[0])
        tn, uncertain = capstan_tension(drum_tension, efficiency, change)
        torque = torque + arm * (tn - efficiency * drum_tension)
    else:
        tn, uncertain = efficiency * drum_tension, np.zeros(t.size, dtype=bool)
    nominal = torque if measured == 'jaw_torque' else np.maximum(torque, 0.0) * gain
    if measured == 'jaw_torque':
        # a jaw torque rig holds the jaw against its load through the whole stroke: loaded
        # wherever the log names an object (the current's sign says which way the drive
        # slides, not whether the jaw is loaded: with friction larger than the load it flips
        # at every stroke under a constant load)
        contact = (codes > 0).astype(float)
    else:
        contact = ((nominal > 0) & (codes > 0)).astype(float)
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
    jaw_model = model.jaw_angle(motor, wrist, current)
    current_smooth = lowpass(current, dt, 0.02)
    current_rate = np.gradient(current_smooth, t)
    stepping = np.abs(current_rate) > STEP_RATE
    if stepping.any():
        hold = max(1, int(round(STEP_HOLD / dt)))
        stepping = np.convolve(stepping.astype(float), np.ones(hold + 1), mode='full')[:t.size] > 0
    return {'t': t - t[0], 'dt': np.array(dt), 'y': raw[measured],
            'max_current': np.array(float(model.params.max_current)),
            'steady': (~near & ~uncertain & ~stepping & finite).astype(float),
            'torque': torque, 'gain': np.ones(t.size) if measured == 'jaw_torque' else gain,
            'drum_tension': drum_tension, 'jaw_tension': tn,
            'nominal': np.asarray(nominal, float), 'contact': contact, 'current': current,
            'current_rate': current_rate, 'jaw': jaw, 'wrist': wrist,
            'motor': motor, 'jaw_velocity': jaw_vel, 'motor_velocity': motor_vel,
            'jaw_model': np.asarray(jaw_model, float), 'load_time': load_time, 'object': codes}


def measured_of(logs: Iterable[Mapping[str, np.ndarray]]) -> str:
    """Return the one measured column shared by all ``logs``."""
    names = {measured_column(log) for log in logs}
    if len(names) != 1:
        raise DiagnosisError(f'logs mix measured columns {sorted(names)}; diagnose them separately')
    return names.pop()
