"""Jaw torque from motor-side signals only: a friction-aware cable transmission observer.

What a robot has on its motor side, and nothing else, goes in (:data:`ALLOWED_INPUTS`):
measured current, the back-end command, the input-disk and motor encoders (and
their derivatives). The jaw torque sensor, the jaw encoder, the input-disk
torque sensor and the resisting (front-end) motor are never read
(:func:`motor_side_inputs` copies only the allowed columns; a test corrupts the
others and checks the prediction does not move).

The physics (docs/real_data.md): the current the motor needs is

    I = alpha(s) * tau + b0 + b1 * s + k(x) + c * v            (forward model)

with tau the jaw torque (N*m), s in [-1, 1] the direction of the cable friction
(+1 while the motor drives closing, -1 while the load back-drives it), x the disk
angle (rad), v the motor velocity (rad/s):

* direction-dependent efficiency: alpha(+1) = 1/(G*eta) while driving, alpha(-1) =
  eta/G while back-driven (capstan friction proportional to tension loses in the
  driving direction and helps in the back-driven one; eta is the one-way efficiency,
  G the loss-free gain in N*m/A);
* Coulomb friction b1 (A, tension-independent part), offset b0 (A);
* k(x): a position-dependent spring (cable pretension and jaw), Legendre terms;
* c: viscous friction (A*s/rad).

s follows the motor angle like a Dahl friction model (it moves towards the sign
of each displacement, exponentially over ``hysteresis_width`` rad), so it is
known only while the motor slides: at a reversal the motor sticks while its
current swings from one friction branch to the other, and the jaw torque cannot
be told from the current. The observer therefore inverts the forward model
only while sliding (|s| high, |v| above the stick speed) and holds its last
estimate otherwise, averaging with a first-order gain (noise of the current)
and weighting each sample by its information (alpha(s)/alpha_max)^2: the
back-driven branch, where a current error maps to a larger torque error,
counts less.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import numpy as np
from scipy.signal import butter, lfilter, lfilter_zi

from grip_force_ros.model import jaw_friction as _jaw_friction

#: Columns an estimator may read: the robot's motor side.
ALLOWED_INPUTS = ('t', 'current', 'current_command', 'motor_angle', 'motor_shaft_angle')
#: Columns it must never read (jaw side, the input-disk torque sensor, the resisting motor).
FORBIDDEN_INPUTS = ('jaw_torque', 'jaw_angle', 'disk_torque', 'load_command', 'grip_force')
#: The target.
TARGET = 'jaw_torque'


class EstimatorError(ValueError):
    """Bad estimator input (missing motor-side column) or an estimator used before fitting."""


def motor_side_inputs(source) -> dict[str, np.ndarray]:
    """Copy only the motor-side columns of a run or a log (the one input gate).

    Parameters
    ----------
    source : RigRun or mapping of str to array
        Needs ``t`` (s), ``current`` (A), ``motor_angle`` (rad, input disk);
        ``motor_shaft_angle`` (rad) and ``current_command`` (A) when present.

    Returns
    -------
    dict of str to ndarray
        float64 copies of :data:`ALLOWED_INPUTS` that exist in ``source``.

    Raises
    ------
    EstimatorError
        When ``t``, ``current`` or ``motor_angle`` is missing.
    """
    get = source.get if isinstance(source, Mapping) else (lambda k: getattr(source, k, None))
    out = {}
    for name in ALLOWED_INPUTS:
        value = get(name)
        if value is not None:
            out[name] = np.array(value, dtype=np.float64, copy=True)
    missing = [c for c in ('t', 'current', 'motor_angle') if c not in out]
    if missing:
        raise EstimatorError(f'motor-side input lacks {", ".join(missing)}')
    return out


def _target(source) -> np.ndarray:
    get = source.get if isinstance(source, Mapping) else (lambda k: getattr(source, k, None))
    value = get(TARGET)
    if value is None:
        raise EstimatorError(f'training data lacks the target column {TARGET!r}')
    return np.asarray(value, dtype=np.float64)


def _sample_period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if t.size > 1 else 1e-3


def causal_lowpass(x: np.ndarray, cutoff_hz: float, dt: float) -> np.ndarray:
    """Second-order Butterworth low-pass, causal, started at rest on the first sample."""
    nyquist = 0.5 / dt
    if cutoff_hz <= 0 or cutoff_hz >= nyquist:
        return x.copy()
    b, a = butter(2, cutoff_hz / nyquist)
    y, _ = lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])
    return y


def causal_velocity(angle: np.ndarray, dt: float, window_s: float, cutoff_hz: float) -> np.ndarray:
    """Backward difference over ``window_s`` then the causal low-pass (rad/s)."""
    n = max(1, int(round(window_s / dt)))
    v = np.zeros_like(angle)
    if angle.size > n:
        v[n:] = (angle[n:] - angle[:-n]) / (n * dt)
    k = np.arange(1, min(n, angle.size))
    v[k] = (angle[k] - angle[0]) / (k * dt)
    return causal_lowpass(v, cutoff_hz, dt)


def dahl_direction(angle: np.ndarray, width: float, start: float = 0.0) -> np.ndarray:
    """Friction direction state s in [-1, 1] of a record: the instrument's Dahl model.

    :func:`grip_force_ros.model.jaw_friction.dahl_direction` (the instrument physics),
    with the estimator's error for a bad width.

    Parameters
    ----------
    angle : ndarray
        Motor-side angle (rad), positive closing.
    width : float
        Angle (rad) over which the friction reverses (e-folding).
    start : float
        Initial state.
    """
    if width <= 0:
        raise EstimatorError(f'hysteresis width must be > 0 rad, got {width!r}')
    return _jaw_friction.dahl_direction(angle, width, start)


def observer_gains(weight: np.ndarray, gain: float) -> np.ndarray:
    """Per-sample gain g[k] of :func:`hold_observer` (0 where the weight is 0).

    g[k] = max(gain * w[k], w[k] / W[k]), W the weight seen up to and including k:
    a running mean of the first measurements, then an exponential average.
    """
    w = np.asarray(weight, dtype=np.float64)
    seen = np.cumsum(w)
    out = np.zeros_like(w)
    on = w > 0.0
    out[on] = np.maximum(gain * w[on], w[on] / seen[on])
    return out


def hold_observer(measurement: np.ndarray, weight: np.ndarray, gain: float,
                  initial: float, *, block: int = 256) -> np.ndarray:
    """First-order observer that holds while ``weight`` is 0.

    estimate[k] = estimate[k-1] + g[k] * (measurement[k] - estimate[k-1]) with
    g[k] = max(gain * weight[k], weight[k] / W[k]), W the weight seen so far: a
    running mean of the first measurements, then an exponential average. Before
    the first measurement with weight > 0 the estimate is ``initial`` (the
    training mean: nothing is known yet).

    The recursion est[k] = a[k] est[k-1] + b[k] (a = 1 - g, b = g z) is solved in
    blocks of ``block`` samples with cumulative products (the same numbers as the
    sample loop to ~1e-12 relative; the streaming observer runs the loop).
    """
    z = np.asarray(measurement, dtype=np.float64)
    g = observer_gains(weight, gain)
    a = 1.0 - g
    b = g * z
    out = np.empty(z.size)
    est = float(initial)
    n = z.size
    # a[k] == 0 (the first measurement: g = 1) resets the estimate to b[k]; split there
    resets = np.flatnonzero(a == 0.0)
    cuts = sorted(set(range(0, n, block)) | set(resets.tolist()) | {n})
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        seg_a, seg_b = a[lo:hi], b[lo:hi]
        if seg_a[0] == 0.0:                       # reset: the estimate restarts at b
            est = seg_b[0]
            out[lo] = est
            if hi - lo == 1:
                continue
            seg_a, seg_b, lo = seg_a[1:], seg_b[1:], lo + 1
        prod = np.cumprod(seg_a)
        # est[k] = P[k] * (est0 + sum_{j<=k} b[j] / P[j]); P >= (1-g)^block stays well above 0
        vals = prod * (est + np.cumsum(seg_b / prod))
        out[lo:hi] = vals
        est = vals[-1]
    return out


def two_sided_average(inverted: np.ndarray, weight: np.ndarray, time_constant: float,
                      dt: float) -> np.ndarray:
    """Run the observer forward and backward in time and average (N*m): the offline estimate.

    Each direction holds through stick as the observer does; where only one has seen a
    sliding sample (the start and the end of a run) that one is used; NaN where neither
    has. Same model, same samples, no causality: what the motor side allows when the
    future may be used (a recorded run; the in-folder floor's non-causal bound).
    """
    gain = 1.0 - math.exp(-dt / time_constant)
    fwd = hold_observer(inverted, weight, gain, np.nan)
    bwd = hold_observer(inverted[::-1], weight[::-1], gain, np.nan)[::-1]
    return np.where(np.isnan(fwd), bwd, np.where(np.isnan(bwd), fwd, 0.5 * (fwd + bwd)))


@dataclass(frozen=True)
class ObserverSettings:
    """Structure and fixed settings of :class:`CableFrictionObserver`.

    The effect switches name the docs/design.md vocabulary they model; turning one off
    is how the analysis measures what each effect is worth on held-out runs.

    Attributes
    ----------
    efficiency : bool
        tension_dependent_friction: direction-dependent efficiency alpha(s).
    load_dependent_efficiency : bool
        The friction split between the branches grows with the square of the load
        as well (a forward term ``alpha1_quad * s * tau**2``): efficiency falls as
        the load grows (the cable's slack side unloads; found across the 10-100 %
        loads of ``Tool_4_Maryland_L_4``). Needs ``efficiency``. Off by default (one
        folder of 10-40 % loads cannot see it); on in the transfer model
        (:data:`grip_force_ros.lab.rig.transfer.TRANSFER_SETTINGS`).
    coulomb : bool
        pivot_coulomb_friction: constant friction b1 * s.
    hysteresis : bool
        cable_hysteresis: Dahl state and stick-hold observer. Off: s = sign(v),
        the model is inverted at every sample (no hold, no averaging).
    viscous : bool
        viscous_friction: c * v.
    spring_order : int
        Legendre order of the position spring k(x) (0 = none).
    friction_map_order : int
        Legendre order of a position-dependent Coulomb friction s * m(x) over the disk
        stroke (0 = none). Order 1 is the transfer model's (:data:`.transfer.TRANSFER_SETTINGS`):
        the cable pretension, and with it the Coulomb friction, changes along the stroke,
        by a different amount in each session (docs/real_data.md, "The wide-load floor").
    backlash_angle : str
        Angle that drives the friction state: ``'motor_shaft_angle'`` (gearbox
        output; the backlash of the coupling lies between it and the disk) or
        ``'motor_angle'`` (input disk, after the backlash).
    current_delay_s : float
        sensor_delay: the current is used this much later (s); 0 = as logged.
    hysteresis_width : float
        Dahl width (rad).
    slow_hysteresis_width : float
        viscoelastic_creep: width (rad) of a second, slower friction state that
        lets the friction settle over a longer stroke after a reversal (0 = none).
    sliding_threshold : float
        |s| above which the friction direction counts as known.
    stick_speed : float
        |v| (rad/s) below which the motor counts as stuck.
    observer_time_constant : float
        Averaging time constant (s) of the observer while sliding.
    current_filter_hz : float
        Causal low-pass of the measured current and the velocity (Hz).
    velocity_window_s : float
        Backward-difference window of the velocity (s).
    load_model : bool
        Estimate the *level* of the load the jaw holds, and the jaw torque as that level
        plus a learned model of how the grasped load's torque moves with the stroke
        direction and position (:class:`LoadModel`: on the rig, the resisting motor's
        own friction and lever). Fitted on the training runs' jaw torque with the
        forward model. Off by default; on in the transfer model.
    level_time_constant : float
        Averaging time constant (s) of the level while sliding (with ``load_model``):
        the level of a held load changes slowly, its within-stroke changes are the load
        model's.
    """

    efficiency: bool = True
    load_dependent_efficiency: bool = False
    coulomb: bool = True
    hysteresis: bool = True
    viscous: bool = True
    spring_order: int = 2
    friction_map_order: int = 0
    backlash_angle: str = 'motor_shaft_angle'
    current_delay_s: float = 0.0
    hysteresis_width: float = 0.02
    slow_hysteresis_width: float = 0.0
    sliding_threshold: float = 0.9
    stick_speed: float = 0.1
    observer_time_constant: float = 0.1
    current_filter_hz: float = 10.0
    velocity_window_s: float = 0.02
    load_model: bool = False
    level_time_constant: float = 1.0

    def __post_init__(self):
        if self.backlash_angle not in ('motor_shaft_angle', 'motor_angle'):
            raise EstimatorError(f'backlash_angle must be motor_shaft_angle or motor_angle, '
                                 f'got {self.backlash_angle!r}')
        if not 0.0 <= self.sliding_threshold < 1.0:
            raise EstimatorError(f'sliding_threshold must be in [0, 1), got {self.sliding_threshold!r}')
        if self.spring_order < 0 or self.observer_time_constant < 0 or self.current_delay_s < 0:
            raise EstimatorError('spring_order, observer_time_constant and current_delay_s must be >= 0')
        if self.load_model and not (self.hysteresis and self.level_time_constant > 0):
            raise EstimatorError('load_model needs hysteresis (the hold) and level_time_constant > 0 s')


@dataclass
class _Signals:
    current: np.ndarray         # A, filtered (and delayed)
    velocity: np.ndarray        # rad/s
    direction: np.ndarray       # s in [-1, 1]
    slow_direction: np.ndarray | None   # second, slower Dahl state (or None)
    position: np.ndarray        # disk angle scaled to [-1, 1] for the Legendre terms (clipped)
    sliding: np.ndarray         # 0..1 confidence that the friction direction is known


#: Disk angle range used to scale the spring's Legendre argument (rad): the rig
#: sweeps the input disk over [-1.05, 0] rad (a 30 degree amplitude sine).
POSITION_RANGE = (-1.05, 0.0)


def scaled_position(motor_angle):
    """Disk angle (rad) mapped to the Legendre argument in [-1, 1] over :data:`POSITION_RANGE`.

    Clipped at the ends: a stroke beyond the range the spring was fitted on (another
    jaw stopping position, another spindle) uses the spring's end value, never an
    extrapolated polynomial.
    """
    lo, hi = POSITION_RANGE
    return np.clip(2.0 * (np.asarray(motor_angle, dtype=np.float64) - lo) / (hi - lo) - 1.0,
                   -1.0, 1.0)


def _signals(inputs: Mapping[str, np.ndarray], settings: ObserverSettings) -> _Signals:
    t = inputs['t']
    dt = _sample_period(t)
    current = inputs['current']
    if settings.current_delay_s > 0:
        shift = int(round(settings.current_delay_s / dt))
        current = np.concatenate([np.full(shift, current[0]), current[:-shift] if shift else current])
    current = causal_lowpass(current, settings.current_filter_hz, dt)
    angle = inputs.get(settings.backlash_angle, inputs['motor_angle'])
    velocity = causal_velocity(angle, dt, settings.velocity_window_s, settings.current_filter_hz)
    if settings.hysteresis:
        direction = dahl_direction(angle, settings.hysteresis_width)
        known = np.clip((np.abs(direction) - settings.sliding_threshold)
                        / (1.0 - settings.sliding_threshold), 0.0, 1.0)
        sliding = known * (np.abs(velocity) > settings.stick_speed)
    else:
        direction = np.sign(velocity)
        sliding = np.ones_like(velocity)
    slow = dahl_direction(angle, settings.slow_hysteresis_width) \
        if settings.slow_hysteresis_width > 0 else None
    position = scaled_position(inputs['motor_angle'])
    return _Signals(current, velocity, direction, slow, position, sliding)


def _nuisance_columns(sig: _Signals, settings: ObserverSettings) -> tuple[list[str], np.ndarray]:
    """Columns of the forward model that do not multiply the jaw torque (units of A)."""
    names, cols = ['offset'], [np.ones_like(sig.current)]
    if settings.coulomb:
        names.append('coulomb')
        cols.append(sig.direction)
    if sig.slow_direction is not None:
        names.append('coulomb_slow')
        cols.append(sig.slow_direction)
    for order in range(1, settings.spring_order + 1):
        names.append(f'spring_P{order}')
        cols.append(np.polynomial.legendre.legval(sig.position, [0.0] * order + [1.0]))
    for order in range(1, settings.friction_map_order + 1):
        names.append(f'friction_P{order}')
        cols.append(sig.direction * np.polynomial.legendre.legval(sig.position, [0.0] * order + [1.0]))
    if settings.viscous:
        names.append('viscous')
        cols.append(sig.velocity)
    return names, np.column_stack(cols)


@dataclass
class FitResult:
    """Fitted forward-model coefficients and their jackknife uncertainty.

    Attributes
    ----------
    names : list of str
        Coefficient names: ``alpha0`` (A/(N*m)), ``alpha1`` (A/(N*m), efficiency
        term), ``alpha1_quad`` (A/(N*m)^2, load-dependent efficiency), then the
        nuisance columns (A, or A*s/rad for ``viscous``).
    values, std : ndarray
        Estimates and leave-one-run-out jackknife standard errors.
    physical : dict of str to (value, std)
        Interpretable parameters: ``gain_Nm_per_A`` G, ``efficiency`` eta (at
        zero load), ``efficiency_at_100mNm`` (with the load-dependent term),
        ``coulomb_Nm`` (at the jaw), ``offset_Nm``, ``viscous_Nms_per_rad``,
        ``spring_span_Nm`` (peak-to-peak of k(x) over the disk range),
        ``coulomb_change_Nm`` (with a friction map: Coulomb friction at the closed end
        of the disk range minus at the open end, at the jaw).
    training_samples : int
        Sliding samples the fit used.
    """

    names: list
    values: np.ndarray
    std: np.ndarray
    physical: dict = field(default_factory=dict)
    training_samples: int = 0


def _physical(names: Sequence[str], values: np.ndarray) -> dict[str, float]:
    coef = dict(zip(names, values))
    a0, a1 = coef['alpha0'], coef.get('alpha1', 0.0)
    a_drive, a_back = a0 + a1, a0 - a1
    gain, eff = _jaw_friction.two_branch_gain_efficiency(a_drive, a_back)   # N*m/A, -
    out = {'gain_Nm_per_A': gain, 'efficiency': eff, 'offset_Nm': -coef['offset'] * gain}
    if 'alpha1_quad' in coef:
        # branch slopes dI/dtau at 0.1 N*m: alpha0 +- (alpha1 + 2 * alpha1_quad * tau)
        split = a1 + 2.0 * coef['alpha1_quad'] * REFERENCE_TORQUE
        c_slope, o_slope = a0 + split, a0 - split
        out['efficiency_at_100mNm'] = math.sqrt(o_slope / c_slope) \
            if c_slope > 0 and o_slope > 0 else float('nan')
    if 'coulomb' in coef:
        out['coulomb_Nm'] = coef['coulomb'] * gain
    if 'viscous' in coef:
        out['viscous_Nms_per_rad'] = coef['viscous'] * gain
    spring = [k for k in names if k.startswith('spring_P')]
    if spring:
        grid = np.linspace(-1, 1, 101)
        shape = sum(coef[k] * np.polynomial.legendre.legval(grid, [0.0] * int(k[8:]) + [1.0])
                    for k in spring)
        out['spring_span_Nm'] = float(np.ptp(shape)) * gain
    friction = [k for k in names if k.startswith('friction_P')]
    if friction:
        # P_k(+1) - P_k(-1) = 1 - (-1)^k: the odd terms change the friction along the stroke
        out['coulomb_change_Nm'] = sum(coef[k] * (1 - (-1) ** int(k[10:])) for k in friction) * gain
    return out


#: Load (N*m) at which the load-dependent efficiency is reported.
REFERENCE_TORQUE = 0.1


#: Jaw torque (N*m) solving I = a*tau + quad*tau**2 + beta, and the local slope dI/dtau:
#: the instrument's branch solve (:func:`grip_force_ros.model.jaw_friction.solve_branch`).
invert_forward = _jaw_friction.solve_branch


#: Seconds at the start of a training run left out when its load level is taken (the
#: front end switches the load on at t = 0).
LEVEL_SKIP_S = 1.0


@dataclass(frozen=True)
class LoadModel:
    """How the torque of a held load moves around its level along the stroke.

    A grasped load is rarely a pure constant torque. On the rig, the resisting motor
    holds one level per run, but the jaw torque steps with the stroke direction (the
    front end's own friction) and changes along the stroke (its lever and spring),
    by 4-9 mN*m std within a run (docs/real_data.md). The observer then estimates the
    slowly changing *level* and adds the load's known shape::

        tau = level * (1 + B(s, x) . proportional) + A(s, x) . constant
        A = [s, P1(x), P2(x), s * P1(x), 1]       B = [s, P1(x)]

    with s the friction direction (the jaw moves with the disk) and x the scaled disk
    position (Legendre P1, P2). Fitted by least squares on the training runs' jaw
    torque, each run's level its mean after :data:`LEVEL_SKIP_S`.

    Attributes
    ----------
    constant : tuple of float
        Coefficients of A (N*m).
    proportional : tuple of float
        Coefficients of B (dimensionless, per unit of level).
    residual_std : float
        Training jaw torque minus the model at the true level (N*m).
    """

    constant: tuple
    proportional: tuple
    residual_std: float = float('nan')

    #: Smallest factor level -> torque allowed (a fit that would invert the load's sign
    #: somewhere along the stroke is clipped there).
    MIN_SCALE = 0.2

    @staticmethod
    def columns(direction, position):
        """Return the columns A (n, 5) and B (n, 2) of the load model."""
        s = np.asarray(direction, dtype=np.float64)
        x = np.asarray(position, dtype=np.float64)
        p2 = 0.5 * (3.0 * x * x - 1.0)
        return np.column_stack([s, x, p2, s * x, np.ones_like(s)]), np.column_stack([s, x])

    #: Names of the columns of A and B (in :meth:`columns`' order), for :meth:`to_json`.
    CONSTANT_TERMS = ('direction', 'position_P1', 'position_P2', 'direction_x_position_P1', 'offset')
    PROPORTIONAL_TERMS = ('direction', 'position_P1')

    def to_json(self) -> dict:
        """Named coefficients with their units, and the training residual."""
        return {'constant_Nm': dict(zip(self.CONSTANT_TERMS, self.constant)),
                'proportional_per_level': dict(zip(self.PROPORTIONAL_TERMS, self.proportional)),
                'residual_std_Nm': self.residual_std,
                'form': 'tau = level * (1 + B(s, x) . proportional) + A(s, x) . constant; '
                        's friction direction (+-1), x disk position scaled to [-1, 1], '
                        'P1, P2 Legendre polynomials'}

    def terms(self, direction, position) -> tuple[np.ndarray, np.ndarray]:
        """Return the offset (N*m) and the factor on the level along (s, x)."""
        a, b = self.columns(direction, position)
        return a @ np.asarray(self.constant), np.maximum(1.0 + b @ np.asarray(self.proportional),
                                                         self.MIN_SCALE)

    @classmethod
    def fit(cls, samples: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> 'LoadModel':
        """Least squares on ``(jaw torque, direction, position)`` per run, after its start.

        Parameters
        ----------
        samples : sequence of (ndarray, ndarray, ndarray)
            Per training run: the jaw torque (N*m), s and x of the samples after
            :data:`LEVEL_SKIP_S`.
        """
        rows, target = [], []
        for tau, s, x in samples:
            if tau.size == 0:
                continue
            level = float(np.mean(tau))
            a, b = cls.columns(s, x)
            rows.append(np.column_stack([a, level * b]))
            target.append(tau - level)
        if not rows:
            raise EstimatorError('the load model needs training runs longer than '
                                 f'{LEVEL_SKIP_S} s')
        design, y = np.vstack(rows), np.concatenate(target)
        coef = np.linalg.lstsq(design, y, rcond=None)[0]
        return cls(tuple(float(c) for c in coef[:5]), tuple(float(c) for c in coef[5:]),
                   float(np.std(y - design @ coef)))


class CableFrictionObserver:
    """Interpretable jaw torque estimator (see the module docstring for the physics).

    >>> est = CableFrictionObserver().fit(train_runs)          # doctest: +SKIP
    >>> tau = est.predict(test_run)       # N*m, reads motor-side columns only  # doctest: +SKIP
    """

    name = 'cable_friction_observer'

    def __init__(self, settings: ObserverSettings | None = None, **changes):
        self.settings = replace(settings or ObserverSettings(), **changes)
        self.fit_result: FitResult | None = None
        self.load_model: LoadModel | None = None
        self._prior = 0.0

    # -- fitting ---------------------------------------------------------------------
    def _design(self, source, cache: dict | None = None):
        key = (id(source), self.settings)
        hit = _cached(cache, key, source)
        if hit is not None:
            return hit
        inputs = motor_side_inputs(source)
        sig = _signals(inputs, self.settings)
        names, nuisance = _nuisance_columns(sig, self.settings)
        dt = _sample_period(inputs['t'])
        if cache is not None:
            cache[key] = (source, (sig, names, nuisance, dt))
        return sig, names, nuisance, dt

    def _rows(self, source, cache=None):
        sig, names, nuisance, _ = self._design(source, cache)
        tau = _target(source)
        mask = sig.sliding > 0
        torque_cols = [tau[mask]]
        coef_names = ['alpha0']
        if self.settings.efficiency:
            torque_cols.append(tau[mask] * sig.direction[mask])
            coef_names.append('alpha1')
            if self.settings.load_dependent_efficiency:
                torque_cols.append(tau[mask] ** 2 * sig.direction[mask])
                coef_names.append('alpha1_quad')
            if sig.slow_direction is not None:
                torque_cols.append(tau[mask] * sig.slow_direction[mask])
                coef_names.append('alpha2')
        a = np.column_stack(torque_cols + [nuisance[mask]])
        return coef_names + names, a, sig.current[mask], tau

    def fit(self, runs: Sequence, *, cache: dict | None = None,
            masks: Sequence[np.ndarray] | None = None) -> 'CableFrictionObserver':
        """Fit the forward model on the sliding samples of ``runs`` (least squares).

        Parameter uncertainty: leave-one-run-out jackknife over ``runs``.
        ``cache``: a dict the caller keeps to reuse per-run signals across fits
        (keyed by the run object's id and the settings; keep the runs alive).
        ``masks``: one boolean array per run, the samples the fit may read (a split of
        individual samples, :mod:`.oneill`); the signals are still computed over the whole
        run (causal filters and the friction state need its history).
        """
        if not runs:
            raise EstimatorError('fit needs at least one run')
        if masks is not None:
            blocks = [self._masked_normal_equations(r, m, cache) for r, m in zip(runs, masks, strict=True)]
        else:
            blocks = [self._normal_equations(r, cache) for r in runs]
        names = blocks[0][0]
        ata = sum(b[1] for b in blocks)
        aty = sum(b[2] for b in blocks)
        values = self._solve(names, ata, aty)
        n = len(blocks)
        if n > 2:
            jack = np.array([self._solve(names, ata - b[1], aty - b[2]) for b in blocks])
            std = np.sqrt((n - 1) / n * np.sum((jack - jack.mean(0)) ** 2, axis=0))
            phys_jack = [_physical(names, j) for j in jack]
        else:
            std, phys_jack = np.full(values.size, np.nan), []
        phys = _physical(names, values)
        physical = {}
        for key, value in phys.items():
            spread = [p[key] for p in phys_jack]
            sd = math.sqrt((n - 1) / n * np.sum((np.array(spread) - np.mean(spread)) ** 2)) \
                if spread else float('nan')
            physical[key] = (value, sd)
        self.fit_result = FitResult(names, values, std, physical, sum(b[3] for b in blocks))
        self._prior = sum(b[4] for b in blocks) / sum(b[5] for b in blocks)   # mean torque
        self.load_model = self._fit_load_model(runs, cache) if self.settings.load_model else None
        return self

    def _fit_load_model(self, runs: Sequence, cache: dict | None) -> LoadModel:
        samples = []
        for run in runs:
            sig = self._design(run, cache)[0]
            t = motor_side_inputs(run)['t']
            late = t - t[0] >= LEVEL_SKIP_S
            samples.append((_target(run)[late], sig.direction[late], sig.position[late]))
        return LoadModel.fit(samples)

    @staticmethod
    def _solve(names, ata, aty):
        """Solve the least squares from the normal equations.

        The load-dependent efficiency term is kept only with the physical sign (>= 0:
        friction grows at least in proportion to the load, efficiency never rises with
        it), else fitted as 0.
        """
        values = np.linalg.solve(ata, aty)
        if 'alpha1_quad' in names:
            q = names.index('alpha1_quad')
            if values[q] < 0:
                keep = [i for i in range(len(names)) if i != q]
                values = np.zeros(len(names))
                values[keep] = np.linalg.solve(ata[np.ix_(keep, keep)], aty[keep])
        return values

    def _masked_normal_equations(self, source, mask: np.ndarray, cache=None):
        """:meth:`_normal_equations` over the sliding samples of ``source`` where ``mask`` holds."""
        sig = self._design(source, cache)[0]
        names, a, y, tau = self._rows(source, cache)
        keep = np.asarray(mask, bool)[sig.sliding > 0]
        a, y = a[keep], y[keep]
        picked = tau[np.asarray(mask, bool)]
        return names, a.T @ a, a.T @ y, a.shape[0], float(np.sum(picked)), picked.size

    def _normal_equations(self, source, cache=None):
        """(names, A'A, A'y, sliding samples, sum of torque, samples) of one run."""
        key = (id(source), self.settings, 'normal')
        hit = _cached(cache, key, source)
        if hit is not None:
            return hit
        names, a, y, tau = self._rows(source, cache)
        out = (names, a.T @ a, a.T @ y, a.shape[0], float(np.sum(tau)), tau.size)
        if cache is not None:
            cache[key] = (source, out)
        return out

    # -- coefficients ----------------------------------------------------------------
    @property
    def coefficients(self) -> dict[str, float]:
        """Forward-model coefficients by name (see :class:`FitResult`)."""
        if self.fit_result is None:
            raise EstimatorError('no coefficients before fit')
        return {k: float(v) for k, v in zip(self.fit_result.names, self.fit_result.values)}

    @property
    def prior_torque(self) -> float:
        """Estimate (N*m) before the first sliding sample of a run (the training mean)."""
        return self._prior

    def with_coefficients(self, changes: Mapping[str, float], *,
                          prior_torque: float | None = None) -> 'CableFrictionObserver':
        """Return a copy with some forward coefficients replaced (a calibrated instrument).

        Parameters
        ----------
        changes : mapping of str to float
            New values by coefficient name (units of :class:`FitResult`).
        prior_torque : float, optional
            New estimate before the first sliding sample (N*m).
        """
        if self.fit_result is None:
            raise EstimatorError('with_coefficients before fit')
        unknown = set(changes) - set(self.fit_result.names)
        if unknown:
            raise EstimatorError(f'unknown coefficients {sorted(unknown)}')
        pairs = zip(self.fit_result.names, self.fit_result.values)
        values = np.array([changes.get(k, v) for k, v in pairs])
        out = CableFrictionObserver(self.settings)
        out.fit_result = FitResult(list(self.fit_result.names), values, self.fit_result.std.copy(),
                                   {k: (v, float('nan')) for k, v in
                                    _physical(self.fit_result.names, values).items()},
                                   self.fit_result.training_samples)
        out._prior = self._prior if prior_torque is None else float(prior_torque)
        out.load_model = self.load_model
        return out

    # -- prediction ------------------------------------------------------------------
    def inversion(self, source, *, cache: dict | None = None):
        """Per-sample inverted torque (N*m), observer weight (0..1) and sample period (s).

        The forward model solved for the jaw torque at every sample, and the weight
        the observer gives it (0 while stuck or reversing).
        """
        if self.fit_result is None:
            raise EstimatorError('predict before fit')
        sig, names, nuisance, dt = self._design(source, cache)
        coef = self.coefficients
        a = coef['alpha0'] + coef.get('alpha1', 0.0) * sig.direction
        if sig.slow_direction is not None:
            a = a + coef.get('alpha2', 0.0) * sig.slow_direction
        quad = coef.get('alpha1_quad', 0.0) * sig.direction
        beta = nuisance @ np.array([coef[k] for k in names])
        inverted, slope = invert_forward(sig.current, a, quad, beta)
        weight = sig.sliding * self._information(slope)
        return inverted, weight, dt

    def predict(self, source, *, cache: dict | None = None, offline: bool = False) -> np.ndarray:
        """Jaw torque estimate (N*m) of a run or log, from its motor-side columns only.

        ``offline``: the estimate of a recorded run, not a real-time one: the observer
        runs forward and backward in time and the two are averaged
        (:func:`two_sided_average`); the start of a run then gets the level the run shows
        once it slides. Default: causal, as the streaming observer.
        """
        inverted, weight, dt = self.inversion(source, cache=cache)
        if not self.settings.hysteresis:
            return inverted
        if self.load_model is not None:
            return self._predict_level(source, inverted, weight, dt, cache, offline)
        tc = self.settings.observer_time_constant
        if offline:
            out = two_sided_average(inverted, weight, tc, dt)
            return np.where(np.isnan(out), self._prior, out)
        gain_per_sample = 1.0 if tc <= 0 else 1.0 - math.exp(-dt / tc)
        return hold_observer(inverted, weight, gain_per_sample, self._prior)

    def _predict_level(self, source, inverted, weight, dt, cache, offline=False) -> np.ndarray:
        """Jaw torque (N*m) as the observed level of the load plus its shape (:class:`LoadModel`).

        Each sliding sample's inverted torque gives the level it implies,
        (tau - A)/(1 + B); the observer averages that level (weights as for the torque,
        ``level_time_constant``) and holds it through stick; the estimate is the level
        put back through the load's shape at the current (s, x). Before the first
        sliding sample: the prior torque. ``offline``: the level averaged forward and
        backward in time.
        """
        sig = self._design(source, cache)[0]
        offset, scale = self.load_model.terms(sig.direction, sig.position)
        measured = (inverted - offset) / scale
        if offline:
            level = two_sided_average(measured, weight, self.settings.level_time_constant, dt)
        else:
            gain = 1.0 - math.exp(-dt / self.settings.level_time_constant)
            level = hold_observer(measured, weight, gain, np.nan)
        out = level * scale + offset
        return np.where(np.isnan(level), self._prior, out)

    def alpha_max(self) -> float:
        """Return the largest branch slope at zero load, |alpha0| + |alpha1| + |alpha2| (A/(N*m))."""
        coef = self.coefficients
        return abs(coef['alpha0']) + abs(coef.get('alpha1', 0.0)) + abs(coef.get('alpha2', 0.0))

    def _information(self, slope):
        """Return the weight (0..1) of an inverted sample.

        The inversion divides the current noise by the branch slope dI/dtau, so its variance
        grows as 1/slope^2; weight = min(slope/alpha_max, 1)^2 (alpha_max: the driving
        branch's slope at zero load).
        """
        return np.minimum(np.abs(slope) / self.alpha_max(), 1.0) ** 2


class LinearCurrentEstimator:
    """Baseline: jaw torque = a * current + b, least squares on the raw current."""

    name = 'linear'

    def __init__(self):
        self.coef: np.ndarray | None = None

    def fit(self, runs: Sequence, *, cache: dict | None = None) -> 'LinearCurrentEstimator':
        i = np.concatenate([motor_side_inputs(r)['current'] for r in runs])
        tau = np.concatenate([_target(r) for r in runs])
        self.coef = np.linalg.lstsq(np.column_stack([i, np.ones_like(i)]), tau, rcond=None)[0]
        return self

    def predict(self, source, *, cache: dict | None = None) -> np.ndarray:
        """Jaw torque (N*m) = a * current + b."""
        if self.coef is None:
            raise EstimatorError('predict before fit')
        return self.coef[0] * motor_side_inputs(source)['current'] + self.coef[1]


def rmse(estimator, runs: Sequence, *, skip_s: float = 0.0) -> float:
    """Root-mean-square jaw torque error (N*m) of a fitted estimator over ``runs``.

    ``skip_s`` leaves out the first seconds of each run (start-up), 0 = all samples.
    """
    se, n = 0.0, 0
    for r in runs:
        err = estimator.predict(r) - _target(r)
        t = motor_side_inputs(r)['t']
        err = err[t - t[0] >= skip_s]
        se += float(np.sum(err ** 2))
        n += err.size
    return math.sqrt(se / n)


def _cached(cache, key, source):
    """Return the value cached under ``key`` for ``source``, or None.

    Caches are keyed by ``id(source)``; Python reuses an id once an object is freed, so an
    entry holds its source and counts only for that very object (a freed run's signals were
    once served for a new run of another length).
    """
    if cache is None:
        return None
    entry = cache.get(key)
    return entry[1] if entry is not None and entry[0] is source else None
