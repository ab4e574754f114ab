"""How the diagnosis fits each unmodelled effect: a small augmentation of the model.

The names, units and which effects the diagnosis fits are the effect registry's
(:mod:`grip_force_ros.effects`, :data:`~grip_force_ros.effects.DIAGNOSED`); this module
holds one regressor builder per diagnosed effect (:data:`EFFECTS`).

Every effect adds a few regressors to one or both of two channels:

- force channel: ``y ~ gain * base + sum_j c_j * force_col_j`` where ``y`` is the
  measured grip force (N) or jaw torque (N*m) and ``base`` is the model's nominal
  prediction (the sensor delay shifts it in time instead of adding a column);
- angle channel: ``jaw ~ a0 + a1 * jaw_model + a2 * F0 + a3 * Tn + a4 * jaw_velocity
  + sum_k d_k * angle_col_k`` (rad): the measured jaw angle against the model's jaw angle
  from the drum angle, with the calibrated zero, scale, cable stretch and dynamic lag.

Nonlinear parameters (a width, a time constant, a delay) are picked from a small
grid; the coefficients are linear least squares. Each effect's shape:

| effect | force column(s) | angle column(s) | grid |
|---|---|---|---|
| pivot_coulomb_friction | contact * G * dir(drive torque), or contact * G * dir(motor angle) with the nominal held while stuck | dir(jaw_model) | friction torque, or motor play width |
| viscous_friction | contact * jaw_velocity | - | - |
| cable_hysteresis | nominal * dir(log jaw tension) on stiff objects and nominal * dir(motor angle) on tissue (two coefficients), or nominal * dir(motor angle) | - | relative width and motor width, or motor play width |
| backlash | - | tanh(current / width) | width |
| tension_dependent_friction | nominal * current, nominal * current^2 | - | - |
| viscoelastic_creep | lowpass_tau(nominal) | - | tau |
| sensor_delay | (base = nominal(t - d)) | - | d |
| torque_constant_drift | nominal * lowpass_tau(current^2)/I_max^2 (heat) | - | tau |
| force_sensor_offset | 1 | - | - |
| position_spring | contact * G * P_k(x), k = 0..2 | - | angle (motor or jaw) |

``dir(x)`` is a play operator output in [-1, 1]: the direction of the last motion
of ``x`` with memory (stiction, dead band). Grids of the two friction effects hold
(source, width) pairs: the drive torque / log tension (a jaw held in contact, the sim's
pivot) or the motor angle (a jaw sliding under its load, as on a torque rig, where the
friction direction persists through stick and reversals while the current swings).

``position_spring`` is a jaw torque that depends on where the drive is, not on how it
moves: cable pretension and the jaw's own return spring. ``P_k`` are Legendre
polynomials of ``x`` in [-1, 1], the motor (drum) or jaw angle mapped over the stroke the
training logs cover (:func:`stroke_range`, set on each frame by the engine); ``P_0`` is the
spring's torque at mid-stroke, so on a log loaded everywhere it also holds a constant.
"""  # noqa: E501 - Markdown table rows are kept whole
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from grip_force_ros.lab.diagnosis.frame import hold_where_stuck, lowpass, play, play_sliding
from grip_force_ros.effects import DIAGNOSED, NONE
from grip_force_ros.objects import OBJECTS

#: The effects the diagnosis fits, in the registry's order (``none`` is the verdict when
#: no effect is needed).
EFFECT_NAMES: tuple[str, ...] = DIAGNOSED
__all__ = ['EFFECT_NAMES', 'EFFECTS', 'NONE', 'Design', 'Effect', 'stroke_range', 'stroke_coordinate',
           'spring_summary', 'SPRING_ANGLES']


@dataclass
class Design:
    """Regressors of one effect at one grid value, for one frame."""

    #: the base columns (n, k): the nominal and its derivatives by the re-identified parameters
    force_base: np.ndarray
    force_cols: list = field(default_factory=list)
    angle_cols: list = field(default_factory=list)


@dataclass(frozen=True)
class Effect:
    """One effect: its grid, its regressors and the names of its coefficients."""

    name: str
    grid: tuple
    grid_name: str | None
    grid_unit: str
    build: Callable
    force_params: tuple = ()
    angle_params: tuple = ()
    #: physical meaning of each coefficient: (name, unit, transform(coef, gain))
    describe: tuple = ()
    #: derived figures of the fitted effect: summary(force_coefs, grid_value) -> {name: (value, unit)}
    summary: Callable | None = None

    @property
    def n_params(self) -> int:
        return len(self.force_params) + len(self.angle_params) + (1 if self.grid_name else 0)


#: Jaw torque per rad of cable stretch seen at the jaw, for the angle signature of pivot friction
#: in free motion (N*m/rad; order of the sim's E A r_n^2 / L).
ANGLE_PER_TORQUE = 1.0


#: Full widths (rad of motor angle) of the play whose output is the friction direction when it
#: follows the drive motion (pivot_coulomb_friction, cable_hysteresis on a sliding jaw).
MOTOR_PLAY_WIDTHS = (0.005, 0.02, 0.05)
#: Widths (rad of motor angle) of the drive's direction that a hysteresis follows where the jaw
#: moves with a soft load (tissue).
SOFT_PLAY_WIDTHS = (0.02, 0.1)
#: Object code of the soft contact (the jaw moves with its load).
_TISSUE = OBJECTS.index('tissue')


def _base(f):
    """Return the base columns of a frame: the nominal and its parameter derivatives (set by the engine)."""
    return f['base'] if 'base' in f else f['nominal'][:, None]


def _cached(f, key, make):
    cache = f.setdefault('_cache', {})
    if key not in cache:
        cache[key] = make()
    return cache[key]


def _motor_direction(f, width):
    # direction of the last drive motion with memory: a play of full width ``width`` (rad) on the
    # motor (drum) angle; it holds through stick and reversals, where the current swings across the
    # friction band while the drive does not move (a sign of the velocity would flip at once)
    return _cached(f, ('play_motor', width), lambda: play(f['motor'], width))


def _coulomb(f, grid_value):
    source, width = grid_value
    if source == 'motor_angle':
        # the jaw slides under load (a rig whose load follows the stroke): the friction opposes the
        # motion, its direction follows the drive's angle through stick; while the drive sticks
        # (inside the play's band: standing, or reversing) the friction takes up any change of the
        # current, so the transmitted load is the one of the last sliding sample
        force_dir, sliding = _cached(f, ('play_sliding_motor', width),
                                     lambda: play_sliding(f['motor'], width))
        base = _cached(f, ('held_base', width), lambda: hold_where_stuck(_base(f), sliding))
        angle_dir = _cached(f, ('play_jaw_model', width),
                            lambda: play(f['jaw_model'], width))
        return Design(base, [f['contact'] * f['gain'] * force_dir], [angle_dir])
    tau = width
    # the pivot sticks while the drive torque changes by less than 2 tau: a play on the torque
    force_dir = _cached(f, ('play_torque', tau), lambda: play(f['torque'], 2.0 * tau))
    angle_dir = _cached(f, ('play_jaw_model', 2.0 * tau / ANGLE_PER_TORQUE),
                        lambda: play(f['jaw_model'], 2.0 * tau / ANGLE_PER_TORQUE))
    return Design(_base(f), [f['contact'] * f['gain'] * force_dir], [angle_dir])


def _viscous(f, _):
    return Design(_base(f), [f['contact'] * f['jaw_velocity']])


def _hysteresis(f, grid_value):
    source, width = grid_value[:2]
    soft = f['object'] == _TISSUE
    if source == 'motor_angle':
        # friction proportional to the cable tension, its direction following the drive motion
        # with memory: a transmission efficiency that differs between driving and back-driving
        direction = soft_direction = _motor_direction(f, width)
    else:
        # Dahl loop: a moment proportional to the tension, flipping after a relative change of the
        # tension where the jaw is blocked (a stiff object: the moment goes into the grip); where
        # the jaw moves with its load (a soft object: the stuck cable takes most of the moment),
        # it shows with the direction of the drive's motion, with its own size and sign
        log_tension = np.log(np.maximum(np.abs(f['jaw_tension']), 1e-3))
        direction = _cached(f, ('play_log_tension', width), lambda: play(log_tension, width))
        soft_direction = _motor_direction(f, grid_value[2])
    return Design(_base(f), [f['nominal'] * np.where(soft, 0.0, direction),
                             f['nominal'] * np.where(soft, soft_direction, 0.0)])


def _backlash(f, current_width):
    # the cable is taut on the side the current pulls: the jaw sits half the dead band
    # to that side of where the drum puts it; the side flips as the current changes sign
    return Design(_base(f), [], [np.tanh(f['current'] / current_width)])


def _tension(f, _):
    # efficiency falling with tension: first and second order in the current
    return Design(_base(f), [f['nominal'] * f['current'], f['nominal'] * f['current'] ** 2])


def _creep(f, tau):
    return Design(_base(f), [lowpass(f['nominal'], float(f['dt']), tau, initial=0.0)])


def _delay(f, d):
    # the sensor sees the whole force late: every base column delayed
    base = _base(f)
    return Design(np.column_stack([np.interp(f['t'] - d, f['t'], base[:, j]) for j in range(base.shape[1])]))


def _drift(f, tau):
    i_ref = float(f['max_current']) if 'max_current' in f else max(float(np.max(np.abs(f['current']))), 1e-9)
    heat = lowpass((f['current'] / i_ref) ** 2, float(f['dt']), float(tau), initial=0.0)
    return Design(_base(f), [f['nominal'] * heat])


def _offset(f, _):
    return Design(_base(f), [np.ones_like(f['nominal'])])


#: Angle signals a position spring may follow (frame key of each).
SPRING_ANGLES = {'motor_angle': 'motor', 'jaw_angle': 'jaw'}
#: Highest Legendre order of the position spring (P_0..P_SPRING_ORDER: SPRING_ORDER + 1 columns).
SPRING_ORDER = 2
#: Share of the samples left outside the stroke at each end (robust to noise and outliers).
STROKE_QUANTILE = 0.005


def stroke_range(angles: np.ndarray) -> tuple[float, float]:
    """Return the stroke an angle covers (rad): its STROKE_QUANTILE and 1 - STROKE_QUANTILE quantiles.

    A stroke narrower than 1 mrad is widened to 1 mrad about its middle (a jaw that never
    moves leaves the spring a constant, not a division by zero).
    """
    lo, hi = (float(q) for q in np.quantile(angles, [STROKE_QUANTILE, 1.0 - STROKE_QUANTILE]))
    if hi - lo < 1e-3:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 5e-4, mid + 5e-4
    return lo, hi


def stroke_coordinate(angle: np.ndarray, stroke: tuple[float, float]) -> np.ndarray:
    """``angle`` (rad) mapped to [-1, 1] over ``stroke`` = (low, high) rad (beyond it: outside)."""
    lo, hi = stroke
    return 2.0 * (np.asarray(angle, float) - lo) / (hi - lo) - 1.0


def _spring(f, source):
    key = SPRING_ANGLES[source]
    # the engine sets the stroke of the training logs on every frame, so that one spring
    # means one torque per angle across logs; a frame alone uses its own stroke
    stroke = f.get('stroke', {}).get(key) or stroke_range(f[key])
    x = stroke_coordinate(f[key], stroke)
    legendre = np.polynomial.legendre.legvander(x, SPRING_ORDER)
    # jaw torque of the spring (N*m) -> measured column: G converts it to grip force (1 for torque)
    scale = f['contact'] * f['gain']
    return Design(_base(f), [scale * legendre[:, k] for k in range(SPRING_ORDER + 1)])


def spring_summary(coefs, _grid_value=None) -> dict:
    """Peak-to-peak (N*m) and the ends (N*m at x = -1, +1) of a fitted spring over its stroke."""
    x = np.linspace(-1.0, 1.0, 201)
    torque = np.polynomial.legendre.legval(x, np.asarray(coefs, float))
    return {'spring_peak_to_peak': (float(np.ptp(torque)), 'N*m'),
            'spring_at_stroke_low': (float(torque[0]), 'N*m'),
            'spring_at_stroke_high': (float(torque[-1]), 'N*m')}


def _rel(coef, gain):
    return coef / gain if gain else float('nan')


EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect('pivot_coulomb_friction',
           tuple(('drive_torque', v) for v in (0.002, 0.005, 0.01, 0.02))
           + tuple(('motor_angle', v) for v in MOTOR_PLAY_WIDTHS),
           'friction_torque_grid', 'N*m (drive_torque) or rad (motor_angle play width)',
           _coulomb,
           ('force_step',), ('angle_step',),
           (('force_step', 'unit of y', lambda c, g: c), ('angle_step', 'rad', lambda c, g: c))),
    Effect('viscous_friction', (None,), None, '', _viscous,
           ('force_per_jaw_velocity',), (),
           (('force_per_jaw_velocity', 'unit of y*s/rad', lambda c, g: c),)),
    Effect('cable_hysteresis',
           tuple(('log_tension', v, m) for v in (0.02, 0.05, 0.1, 0.2) for m in SOFT_PLAY_WIDTHS)
           + tuple(('motor_angle', v) for v in MOTOR_PLAY_WIDTHS),
           'direction_state_width', '- (log_tension) or rad (motor_angle play width)', _hysteresis,
           ('loop_fraction', 'loop_fraction_soft'), (),
           (('loop_fraction', '-', lambda c, g: -_rel(c, g)),
            ('loop_fraction_soft', '-', lambda c, g: -_rel(c, g)))),
    Effect('backlash', (0.002, 0.005, 0.01, 0.02), 'current_width', 'A', _backlash,
           (), ('dead_band',), (('dead_band', 'rad', lambda c, g: -2.0 * c),)),
    Effect('tension_dependent_friction', (None,), None, '', _tension,
           ('efficiency_loss_per_amp', 'efficiency_loss_per_amp2'), (),
           (('efficiency_loss_per_amp', '1/A', lambda c, g: -_rel(c, g)),
            ('efficiency_loss_per_amp2', '1/A^2', lambda c, g: -_rel(c, g)))),
    Effect('viscoelastic_creep', (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0), 'time_constant', 's', _creep,
           ('relaxing_fraction',), (), (('relaxing_fraction', '-', lambda c, g: -_rel(c, g)),)),
    # below ~10 ms a delay cannot be told from the plant's own mechanical response (cable and
    # contact dynamics) at a 200 Hz analysis rate
    Effect('sensor_delay', (0.01, 0.015, 0.02, 0.03, 0.04, 0.055, 0.075, 0.1, 0.15, 0.2, 0.3),
           'delay', 's', _delay),
    Effect('torque_constant_drift', (5.0, 10.0, 20.0, 40.0), 'time_constant', 's', _drift,
           ('gain_loss',), (), (('gain_loss', '- (at full heat)', lambda c, g: -_rel(c, g)),)),
    Effect('force_sensor_offset', (None,), None, '', _offset,
           ('offset',), (), (('offset', 'unit of y', lambda c, g: c),)),
    Effect('position_spring', tuple(SPRING_ANGLES), 'spring_angle', '- (which angle the spring follows)',
           _spring, tuple(f'spring_legendre_{k}' for k in range(SPRING_ORDER + 1)), (),
           tuple((f'spring_legendre_{k}', 'N*m (jaw torque)', lambda c, g: c)
                 for k in range(SPRING_ORDER + 1)),
           spring_summary),
)}
if set(EFFECTS) != set(EFFECT_NAMES):  # pragma: no cover - a programming error
    raise RuntimeError(f'diagnosis builders {sorted(EFFECTS)} do not match the registry\'s diagnosed '
                       f'effects {sorted(EFFECT_NAMES)}')
