"""Loop analysis and PID design with python-control, on a linear plant at the grip point.

Plant (continuous time, linearised around a grip at half the current limit):

- current loop: the actual current follows the command with a first-order lag
  (``current_loop_time_constant``);
- motor + drum: inertia ``motor_inertia + drum_mass*r0**2/2`` (kg*m^2), viscous damping
  ``drum_damping``, driven by ``gear_ratio*torque_constant*i`` (N*m);
- cable: a spring of stiffness ``E*pi*r**2/cable_length`` (N/m) between the drum
  (``r0*theta0``) and the jaw drive pulley (``r_n*q``); the jaw side receives the tension
  times the chain efficiency minus the static resistance (the model's slope dM/dI);
- jaw: inertia ``jaw_inertia``, damping ``jaw_damping``, pressing an object of contact
  stiffness k_c at arm l (needle/rigid: l = jaw_moment_arm_tip; tissue: (l + l')/2),
  contact damping ``contact_damping_ratio`` of critical;
- output: grip force ``k_c*l*q`` (N) in grip; jaw closing angle q (rad) in free motion.

The controller is the discrete PID of :class:`grip_force_ros.control.pid.PID` exactly
(forward-Euler integrator, backward-Euler filtered derivative), with one period of
computation delay, at the period of the instrument states it steps on. The gains are
designed at the instrument's ``gain_design_rate`` (1 kHz: the crtk profile's state rate)
and must hold there and at every faster rate of the range; below it the controller runs them
through the gain schedule (:mod:`grip_force_ros.control.schedule`), whose knees
:func:`schedule_knees` finds: the smallest knee of each loop that keeps the design margins
at every rate of :data:`GRID_RATES` below the design rate. :func:`analyse` reports every
loop with the scheduled gains at every rate of the grid (``STATE_RATE_MIN`` ..
``STATE_RATE_MAX``, 100 .. 1500 Hz, params/controller.py), the instrument's
``expected_state_rate`` and ``gain_design_rate`` included. Three loops are analysed:

- ``force_sensor``: force PID on the load-cell force (the mechanical plant above);
- ``force_estimate``: force PID on the model estimate from the measured current (current
  loop lag only: the estimate is a static function of the measured current);
- ``jaw``: jaw-angle PID in free motion.

Gains are designed so that the WORST case over the plant set {nominal, cable stiffness
x0.8 and x1.2, friction x0.8 and x1.2, and for the force loops the pulleys' unloading edge
(the stick band's other edge, where the force moves 1/lambda^2 times faster with the current
than on the loading edge, docs/control.md)} keeps gain margin >= 6 dB and phase margin >= 45
deg (design targets a little above: :data:`DESIGN_GM_DB`, :data:`DESIGN_PM_DEG`), and the
force gains serve both force loops. Among those, the design with the shortest settling,
then the highest nominal crossover frequency, wins (:func:`_search`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import product

import numpy as np

from grip_force_ros.control.schedule import GAIN_KEYS, scheduled_gains
from grip_force_ros.params.controller import STATE_RATE_MAX, STATE_RATE_MIN


#: Margins claimed (and tested) for every loop and every plant variant.
CLAIM_GM_DB = 6.0
CLAIM_PM_DEG = 45.0
#: Design targets (headroom over the claim).
DESIGN_GM_DB = 7.0
DESIGN_PM_DEG = 50.0
#: Largest sensitivity peak |S| allowed by the design (-).
DESIGN_MS = 2.0

#: Rise time of the ramped target in the step figure (s): a master closing in 25 ms is fast.
RAMP_TIME = 0.025

#: State rates (Hz) at which the schedule is checked: across the range, denser where the
#: crossover moves most (below the knees); analyse adds the expected and the design rate.
GRID_RATES = (STATE_RATE_MIN, 125.0, 150.0, 200.0, 250.0, 300.0, 400.0, 500.0, 600.0, 800.0,
              1000.0, 1250.0, STATE_RATE_MAX)
#: Knee candidates of the schedule (Hz): the E12 series from 100 Hz to 100 kHz (a knee far
#: above the range makes the crossover proportional to the rate); the smallest that keeps
#: the design margins wins (the most bandwidth at the slow rates).
KNEES = tuple(float(f'{m * 10.0 ** e:.3g}') for e in (2, 3, 4)
              for m in (1.0, 1.2, 1.5, 1.8, 2.2, 2.7, 3.3, 3.9, 4.7, 5.6, 6.8, 8.2)) + (1.0e5,)
#: Plant variants of the force loops only: name -> edge of the pulleys' stick band.
EDGE_VARIANTS = {'unloading edge': 'unloading'}
#: Plant variants: name -> (cable stiffness scale, friction coefficient scale).
VARIANTS = {'nominal': (1.0, 1.0), 'stiffness x0.8': (0.8, 1.0), 'stiffness x1.2': (1.2, 1.0),
            'friction x0.8': (1.0, 0.8), 'friction x1.2': (1.0, 1.2)}

#: Plant data the instrument YAML may not carry (the 'sim' group defines them): fallbacks.
_PLANT_DEFAULTS = {'cable_length': 0.09, 'motor_inertia': 1.0e-5, 'jaw_inertia': 4.8e-8,
                   'drum_damping': 2.0e-4, 'jaw_damping': 1.0e-5,
                   'current_loop_time_constant': 2.0e-4, 'needle_stiffness': 2.0e5,
                   'tissue_stiffness': 2.0e3, 'rigid_stiffness': 1.0e6,
                   'contact_damping_ratio': 0.3}


def _get(params, name):
    try:
        return params[name]
    except KeyError:
        return _PLANT_DEFAULTS[name]


@dataclass
class PlantData:
    """Linear-plant numbers (SI) derived from a ParamSet."""

    torque_per_amp: float        # N*m/A at the drum: gear_ratio * torque_constant
    drum_radius: float           # m
    drive_radius: float          # m
    jaw_side_gain: float         # - jaw torque / (r_n * tension): efficiency minus resistance
    cable_stiffness: float       # N/m
    drum_inertia: float          # kg*m^2 (motor + drum)
    drum_damping: float          # N*m*s/rad
    jaw_inertia: float           # kg*m^2
    jaw_damping: float           # N*m*s/rad
    contact_stiffness: float     # N/m at the contact arm
    contact_arm: float           # m
    contact_damping_ratio: float  # -
    current_lag: float           # s
    estimate_gain: float         # N/A, d(model grip force)/d(current) at the operating point

    @property
    def force_per_amp(self) -> float:
        """Static grip force per ampere (N/A)."""
        return (self.torque_per_amp / self.drum_radius * self.drive_radius * self.jaw_side_gain
                / self.contact_arm)


def plant_data(params, model=None, stiffness_scale: float = 1.0,
               friction_scale: float = 1.0, edge: str = 'loading') -> PlantData:
    """Linear plant numbers at the grip operating point (half the current limit).

    ``edge``: 'loading' (the paper's model), or 'unloading': the other edge of the pulleys'
    stick band, where the cable slips back and the jaw-side tension moves with the drum
    tension over the chain efficiency lambda instead of times it: the force per ampere
    (and the estimate's) is 1/lambda^2 times the loading edge's.
    """
    from grip_force_ros.model import GripForceModel
    p = params
    if friction_scale != 1.0:
        p = p.replace(pulley_friction_coefficient=min(1.0, p.pulley_friction_coefficient
                                                      * friction_scale))
    m = GripForceModel(p) if (model is None or friction_scale != 1.0) else model
    obj = p.object_kind if p.object_kind != 'free' else 'needle'
    current = 0.5 * p.max_current if p.max_current > 0 else 0.25        # A, operating point
    step = 1e-4 * max(current, 1e-3)
    torque_slope = (float(m.forward(current + step, 0.0, 0.05, obj).jaw_torque)
                    - float(m.forward(current - step, 0.0, 0.05, obj).jaw_torque)) / (2 * step)
    tension_per_amp = p.gear_ratio * p.torque_constant / p.drum_radius
    jaw_side_gain = torque_slope / (tension_per_amp * p.drive_pulley_radius)
    if obj == 'tissue':
        arm = 0.5 * (p.jaw_moment_arm_tip + p.jaw_moment_arm_inner)
    else:
        arm = p.jaw_moment_arm_tip
    jaw = _get(p, {'needle': 'needle_stiffness', 'tissue': 'tissue_stiffness',
                   'rigid': 'rigid_stiffness'}[obj])
    jaw_angle = 0.05                                                     # rad, near closed
    estimate = (m.grip_force_scalar(current + step, 0.0, jaw_angle, obj)
                - m.grip_force_scalar(current - step, 0.0, jaw_angle, obj)) / (2 * step)
    if edge == 'unloading':
        lam = float(m.forward(current, 0.0, jaw_angle, obj).efficiency)
        jaw_side_gain /= lam ** 2
        estimate /= lam ** 2
    elif edge != 'loading':
        raise ValueError(f"edge must be 'loading' or 'unloading', got {edge!r}")
    return PlantData(
        torque_per_amp=p.gear_ratio * p.torque_constant, drum_radius=p.drum_radius,
        drive_radius=p.drive_pulley_radius, jaw_side_gain=max(jaw_side_gain, 1e-6),
        cable_stiffness=stiffness_scale * p.cable_modulus * math.pi * p.cable_radius ** 2
        / _get(p, 'cable_length'),
        drum_inertia=_get(p, 'motor_inertia') + 0.5 * p.drum_mass * p.drum_radius ** 2,
        drum_damping=_get(p, 'drum_damping'), jaw_inertia=_get(p, 'jaw_inertia'),
        jaw_damping=_get(p, 'jaw_damping'), contact_stiffness=jaw, contact_arm=arm,
        contact_damping_ratio=_get(p, 'contact_damping_ratio'),
        current_lag=_get(p, 'current_loop_time_constant'), estimate_gain=estimate)


def plant_statespace(d: PlantData, loop: str):
    """Continuous state-space plant (A, B, C, D) of one loop; input current command (A).

    ``loop``: 'force_sensor' (output grip force, N), 'force_estimate' (output model
    estimate, N) or 'jaw' (output jaw closing angle, rad, no contact).
    """
    lag = max(d.current_lag, 1e-6)
    if loop == 'force_estimate':
        return (np.array([[-1.0 / lag]]), np.array([[1.0 / lag]]),
                np.array([[d.estimate_gain]]), np.array([[0.0]]))
    # states: current i, drum angle th, drum velocity w, jaw closing angle q, jaw velocity v
    k, r0, rn = d.cable_stiffness, d.drum_radius, d.drive_radius
    j0, jj = d.drum_inertia, d.jaw_inertia
    if loop == 'force_sensor':
        k_rot = d.contact_stiffness * d.contact_arm ** 2                       # N*m/rad
        c_rot = 2.0 * d.contact_damping_ratio * math.sqrt(k_rot * jj)          # N*m*s/rad
    elif loop == 'jaw':
        k_rot = c_rot = 0.0
    else:
        raise ValueError(f'unknown loop {loop!r}')
    g = d.jaw_side_gain
    a = np.zeros((5, 5))
    a[0, 0] = -1.0 / lag
    a[1, 2] = 1.0
    # J0 w' = Kg i - r0 k (r0 th - rn q) - b0 w
    a[2, 0] = d.torque_per_amp / j0
    a[2, 1] = -r0 * k * r0 / j0
    a[2, 3] = r0 * k * rn / j0
    a[2, 2] = -d.drum_damping / j0
    a[3, 4] = 1.0
    # Jj v' = g rn k (r0 th - rn q) - k_rot q - (bj + c_rot) v
    a[4, 1] = g * rn * k * r0 / jj
    a[4, 3] = -(g * rn * k * rn + k_rot) / jj
    a[4, 4] = -(d.jaw_damping + c_rot) / jj
    b = np.zeros((5, 1))
    b[0, 0] = 1.0 / lag
    c = np.zeros((1, 5))
    if loop == 'force_sensor':
        c[0, 3] = d.contact_stiffness * d.contact_arm          # F = k_c l q
    else:
        c[0, 3] = 1.0
    return a, b, c, np.zeros((1, 1))


def discrete_plant(d: PlantData, loop: str, period: float):
    """ZOH-discretised plant with one period of computation delay (python-control TF)."""
    import control
    sys_c = control.ss(*plant_statespace(d, loop))
    sys_d = control.c2d(sys_c, period, method='zoh')
    delay = control.tf([1.0], [1.0, 0.0], period)                          # z^-1
    return control.minreal(control.ss2tf(sys_d) * delay, verbose=False)


def pid_tf(kp: float, ki: float, kd: float, filter_time: float, period: float):
    """Discrete transfer function of :class:`PID` (error -> output), python-control TF.

    ``kp + ki T / (z - 1) + kd (z - 1) / ((tf + T) z - tf)`` over one denominator
    (:func:`_pid_polys`), T = ``period``.
    """
    import control
    num, den = _pid_polys(kp, ki, kd, filter_time, period)
    return control.tf(num, den, period)


# ---------------------------------------------------------------------- fast frequency grid
def _freq_grid(period: float, n: int = 700) -> np.ndarray:
    """Frequencies (rad/s) up to Nyquist, log-spaced, plus a dense linear top decade."""
    nyquist = math.pi / period
    return np.unique(np.concatenate([np.logspace(-1, math.log10(0.9999 * nyquist), n),
                                     np.linspace(0.1 * nyquist, 0.9999 * nyquist, n)]))


class _Plant:
    """A discrete plant as polynomials in z and its response on a frequency grid."""

    def __init__(self, tf, w: np.ndarray, period: float):
        self.num = np.atleast_1d(np.squeeze(np.asarray(tf.num[0][0], float)))
        self.den = np.atleast_1d(np.squeeze(np.asarray(tf.den[0][0], float)))
        z = np.exp(1j * w * period)
        self.resp = np.polyval(self.num, z) / np.polyval(self.den, z)


def _pid_polys(kp, ki, kd, tf, period):
    """Numerator and denominator (in z) of the discrete PID."""
    a = tf + period
    den = np.polymul([1.0, -1.0], [a, -tf])
    num = (kp * den + np.concatenate(([0.0], ki * period * np.array([a, -tf])))
           + kd * np.array([1.0, -2.0, 1.0]))
    return num, den


def _closed_loop_stable(cnum, cden, plant: _Plant) -> bool:
    char = np.polyadd(np.polymul(cden, plant.den), np.polymul(cnum, plant.num))
    roots = np.roots(char)
    return bool(np.all(np.abs(roots) < 1.0 - 1e-9))


def _margins_grid(loop_resp: np.ndarray, w: np.ndarray):
    """(GM dB, PM deg, first crossover rad/s, Ms) from a sampled loop response.

    PM is the angular distance of L from -1 at each gain crossover (the smallest);
    stability is checked separately (closed-loop poles).
    """
    mag = np.abs(loop_resp)
    ms = float(np.max(1.0 / np.abs(1.0 + loop_resp)))
    wrapped = np.degrees(np.angle(loop_resp))                 # (-180, 180]
    above = mag >= 1.0
    cross = np.nonzero(above[:-1] & ~above[1:])[0]
    if cross.size == 0:
        return -math.inf, -math.inf, 0.0, ms
    pm = float(np.min(180.0 - np.abs(wrapped[cross])))
    wc = float(w[cross[0]])
    flips = np.nonzero((np.abs(np.diff(wrapped)) > 180.0))[0]   # the phase passes +-180 deg
    gm = math.inf
    if flips.size:
        gm = float(np.min(-20.0 * np.log10(np.maximum(np.maximum(mag[flips], mag[flips + 1]), 1e-300))))
    return gm, pm, wc, ms


# ---------------------------------------------------------------------- design
@dataclass
class LoopReport:
    """Margins of one loop on one plant variant at one state rate, with the scheduled gains."""

    loop: str
    variant: str
    rate_hz: float
    gain_margin_db: float
    phase_margin_deg: float
    crossover_hz: float
    bandwidth_hz: float
    stable: bool
    gain_scale: float = 1.0     # -, the schedule's crossover scale of this loop at rate_hz


@dataclass
class TuneResult:
    """Designed gains (with the schedule's parameters) and the analysis of every loop.

    ``schedule``: the gains the controller runs at the instrument's ``expected_state_rate``
    (:class:`~grip_force_ros.control.schedule.ScheduledGains`).
    """

    gains: dict
    reports: list = field(default_factory=list)
    period: float = 1e-3
    schedule: object = None

    def worst(self, loop: str, rate: float | None = None) -> tuple[float, float]:
        """Worst (GM dB, PM deg) of a loop over the plant variants (and rates, or at ``rate``)."""
        rs = [r for r in self.reports if r.loop == loop and rate in (None, r.rate_hz)]
        return min(r.gain_margin_db for r in rs), min(r.phase_margin_deg for r in rs)

    def to_dict(self) -> dict:
        """JSON-ready: the gains, the schedule at the expected rate, every report."""
        out = {'gains': self.gains, 'control_period_s': self.period,
               'state_rates_hz': sorted({r.rate_hz for r in self.reports}),
               'claimed': {'gain_margin_db': CLAIM_GM_DB, 'phase_margin_deg': CLAIM_PM_DEG},
               'loops': {}}
        if self.schedule is not None:
            sch = self.schedule
            out['gain_schedule'] = {
                'gain_design_rate_hz': sch.design_rate, 'expected_state_rate_hz': sch.rate,
                'scale': {'force': sch.force_scale, 'jaw': sch.jaw_scale},
                'effective_gains': sch.as_params(),
                'scale_by_rate': {f'{rate:g}': {r.loop: r.gain_scale for r in self.reports
                                                if r.rate_hz == rate}
                                  for rate in out['state_rates_hz']}}
        for r in self.reports:
            out['loops'].setdefault(r.loop, {})[f'{r.variant} @ {r.rate_hz:g} Hz'] = {
                'gain_margin_db': _finite(r.gain_margin_db), 'phase_margin_deg': _finite(r.phase_margin_deg),
                'crossover_hz': r.crossover_hz, 'bandwidth_hz': r.bandwidth_hz, 'stable': r.stable,
                'gain_scale': r.gain_scale}
        return out


def _finite(x: float):
    return x if math.isfinite(x) else None


def _step_settling(cnum, cden, plant: "_Plant", feedforward: float, period: float,
                   horizon: float = 0.3) -> float:
    """5% settling time (s) of the closed-loop unit step, feedforward + PID, on ``plant``."""
    from scipy.signal import lfilter
    num = np.polymul(plant.num, np.polyadd(feedforward * cden, cnum))
    den = np.polyadd(np.polymul(plant.den, cden), np.polymul(plant.num, cnum))
    n = int(round(horizon / period))
    y = lfilter(num / den[0], den / den[0], np.ones(n))
    t = np.arange(n) * period
    final = 1.0
    outside = np.nonzero(np.abs(y - final) > 0.05)[0]
    if not outside.size:
        return 0.0
    return float(t[outside[-1]] + period) if outside[-1] + 1 < n else math.inf


def _meets(kp, ki, kd, tf, plants, w, period, gm_min, pm_min, ms_max) -> bool:
    """Tell whether the PID meets the margins and is stable on every plant at ``period``."""
    cnum, cden = _pid_polys(kp, ki, kd, tf, period)
    z = np.exp(1j * w * period)
    c = np.polyval(cnum, z) / np.polyval(cden, z)
    for plant in plants:
        gm, pm, _, ms = _margins_grid(c * plant.resp, w)
        if not (gm >= gm_min and pm >= pm_min and ms <= ms_max):
            return False
    return all(_closed_loop_stable(cnum, cden, pl) for pl in plants)


def _search(plants: list, w: np.ndarray, period: float, kp_grid, ki_grid,
            kd_grid, tf_grid, feedforward=(0.0,), gm_min=DESIGN_GM_DB,
            pm_min=DESIGN_PM_DEG, ms_max=DESIGN_MS, also=()):
    """Best (kp, ki, kd, tf) meeting the margins on every plant (``plants[0]`` nominal).

    ``also``: further ``(plants, w, period)`` groups (the same plants at other state rates)
    on which a candidate must meet the margins and be stable too; the ranking uses the
    first group only.

    Best = shortest 5% settling (in 5 ms bins) of the nominal unit step, the worst over the
    ``feedforward`` values (A per unit target added to the PID output), then the highest
    nominal gain crossover. The force loop is ranked with a feedforward 30% too low and
    30% too high: the PID must correct a model that is off, quickly and without ringing.
    (The force loop with a load cell is limited by the lightly damped drum-on-cable mode:
    with one period of delay a derivative adds little damping, so the feedforward step
    rings at the plant's own frequency whatever the PID; see docs/control.md.)
    """
    best, best_score = None, (-math.inf, -math.inf)
    z = np.exp(1j * w * period)
    for kp, ki, kd, tf in product(kp_grid, ki_grid, kd_grid, tf_grid):
        cnum, cden = _pid_polys(kp, ki, kd, tf, period)
        c = np.polyval(cnum, z) / np.polyval(cden, z)
        ok = True
        wc0 = 0.0
        for idx, plant in enumerate(plants):
            gm, pm, wc, ms = _margins_grid(c * plant.resp, w)
            if not (gm >= gm_min and pm >= pm_min and ms <= ms_max):
                ok = False
                break
            if idx == 0:
                wc0 = wc
        if not ok:
            continue
        settle = max(_step_settling(cnum, cden, plants[0], ff, period) for ff in feedforward)
        score = (-(math.floor(settle / 0.005) if math.isfinite(settle) else 1e9), wc0)
        if score > best_score and all(_closed_loop_stable(cnum, cden, pl) for pl in plants) \
                and all(_meets(kp, ki, kd, tf, pl, w2, p2, gm_min, pm_min, ms_max)
                        for pl, w2, p2 in also):
            best, best_score = (float(kp), float(ki), float(kd), float(tf)), score
    return best


def _refine(responses, w, period, start, rounds=2, feedforward=(0.0,), also=()):
    """Local refinement of a grid optimum on a finer multiplicative grid."""
    best = start
    for _ in range(rounds):
        kp, ki, kd, tf = best
        f = np.array([0.6, 0.8, 1.0, 1.25, 1.6])
        cand = _search(responses, w, period, kp * f if kp else [0.0], ki * f, kd * f if kd else [0.0],
                       [tf], feedforward=feedforward, also=also)
        if cand is None:
            break
        best = cand
    return best


def variant_data(params, model=None) -> dict:
    """Plant numbers of every variant: :data:`VARIANTS`, then :data:`EDGE_VARIANTS`."""
    out = {name: plant_data(params, model, s, f) for name, (s, f) in VARIANTS.items()}
    out.update({name: plant_data(params, model, edge=e) for name, e in EDGE_VARIANTS.items()})
    return out


def _loop_plants(data: dict, group: str) -> list:
    """Return the (loop, PlantData) pairs of a gain group.

    'force': both force loops on every variant and edge; 'jaw': the jaw loop on every
    variant of :data:`VARIANTS`.
    """
    if group == 'force':
        return [(loop, d) for loop in ('force_sensor', 'force_estimate') for d in data.values()]
    return [('jaw', data[name]) for name in VARIANTS]


def _plant_group(data: dict, group: str, period: float, n: int = 300):
    """``(plants, w, period)``: the discrete plants of a gain group at ``period`` (s)."""
    w = _freq_grid(period, n)
    return [_Plant(discrete_plant(d, loop, period), w, period)
            for loop, d in _loop_plants(data, group)], w, period


def schedule_knees(params, model=None, data: dict | None = None) -> dict:
    """Find the knee (Hz) of each loop's gain schedule.

    The smallest of :data:`KNEES` that keeps the design margins with the scheduled gains at
    every rate of :data:`GRID_RATES` below ``gain_design_rate``, on every plant variant (and
    the unloading edge for the force loop).

    Returns
    -------
    dict
        ``{'force_schedule_knee': Hz, 'jaw_schedule_knee': Hz}``.

    Raises
    ------
    ValueError
        No knee up to 100 kHz (crossover proportional to the rate) keeps the margins: the
        gains need a lower ``gain_design_rate``.
    """
    design_rate = params.gain_design_rate
    data = variant_data(params, model) if data is None else data
    slower = [r for r in GRID_RATES if r < design_rate]
    out = {}
    for group in ('force', 'jaw'):
        checks = [(r, _plant_group(data, group, 1.0 / r)) for r in slower]
        key = f'{group}_schedule_knee'
        for knee in KNEES:
            p = params.replace(**{key: knee})
            if all(_meets(*getattr(scheduled_gains(p, r), group), plants, w, period,
                          DESIGN_GM_DB, DESIGN_PM_DEG, DESIGN_MS)
                   for r, (plants, w, period) in checks):
                out[key] = knee
                break
        else:
            raise ValueError(f'no {group} gain schedule with a knee up to {KNEES[-1]:g} Hz keeps the '
                             f'margins below the design rate {design_rate:g} Hz: design at a lower '
                             "'gain_design_rate'")
    return out


def design(params, model=None) -> TuneResult:
    """Design force and jaw PID gains and their schedule for an instrument (module docstring).

    The gains are designed at ``gain_design_rate`` and must meet the margins unscaled at the
    faster rates of :data:`GRID_RATES` too; then :func:`schedule_knees` finds the schedule.

    Returns
    -------
    TuneResult
        ``gains`` holds the controller parameter names (force_kp, force_ki, force_kd,
        force_derivative_filter_time, jaw_kp, jaw_ki, jaw_kd, jaw_derivative_filter_time,
        gain_design_rate, force_schedule_knee, jaw_schedule_knee).
    """
    rate = params.gain_design_rate
    period = 1.0 / rate
    w = _freq_grid(period, 500)
    data = variant_data(params, model)
    nominal = data['nominal']
    gain = nominal.force_per_amp                                   # N/A

    force_resp = _plant_group(data, 'force', period, 500)[0]
    # the same plants at the faster rates of the range: the gains run unscaled there
    faster = [1.0 / r for r in GRID_RATES if r > rate]
    force_also = [_plant_group(data, 'force', p2) for p2 in faster]
    jaw_also = [_plant_group(data, 'jaw', p2) for p2 in faster]
    # gains are scaled by 1/gain so the grid fits any instrument
    inv = 1.0 / gain
    best = _search(force_resp, w, period,
                   kp_grid=inv * np.array([0.0, 0.02, 0.05, 0.1, 0.2, 0.4]),
                   ki_grid=inv * np.array([1.0, 2.0, 4.0, 8.0, 15.0, 30.0, 60.0, 120.0]),
                   kd_grid=inv * np.array([0.0, 1e-4, 3e-4, 1e-3, 2e-3, 4e-3]),
                   tf_grid=[0.5e-3, 2e-3], feedforward=(0.7 * inv, 1.3 * inv), also=force_also)
    if best is None:
        raise ValueError('no force PID on the design grid meets the margins on every plant variant '
                         f'at {rate:g} Hz and above')
    force = _refine(force_resp, w, period, best, feedforward=(0.7 * inv, 1.3 * inv),
                    also=force_also)

    jaw_resp = _plant_group(data, 'jaw', period, 500)[0]
    jaw_gain = (nominal.torque_per_amp / nominal.drum_radius * nominal.drive_radius
                * nominal.jaw_side_gain)                           # N*m/A at the jaw
    inv_j = nominal.drum_inertia * (nominal.drum_radius / nominal.drive_radius) / jaw_gain
    best = _search(jaw_resp, w, period,
                   kp_grid=inv_j * np.array([100.0, 300.0, 1e3, 3e3, 1e4, 3e4]),
                   ki_grid=inv_j * np.array([1e3, 1e4, 1e5, 3e5]),
                   kd_grid=inv_j * np.array([1.0, 3.0, 10.0, 30.0, 100.0]),
                   tf_grid=[0.5e-3, 2e-3], also=jaw_also)
    if best is None:
        raise ValueError('no jaw PID on the design grid meets the margins on every plant variant '
                         f'at {rate:g} Hz and above')
    jaw = _refine(jaw_resp, w, period, best, also=jaw_also)

    gains = dict(zip(GAIN_KEYS['force'] + GAIN_KEYS['jaw'], force + jaw))
    gains = {k: float(f'{v:.3g}') for k, v in gains.items()}
    gains['gain_design_rate'] = float(rate)
    gains.update(schedule_knees(params.replace(**gains), model, data))
    return analyse(params.replace(**gains), model)


# ---------------------------------------------------------------------- analysis
def _controller_tf(params, loop: str, rate: float):
    """Return the PID (python-control TF) the controller runs in ``loop`` at ``rate`` Hz (scheduled)."""
    gains = scheduled_gains(params, rate)
    return pid_tf(*(gains.jaw if loop == 'jaw' else gains.force), 1.0 / rate)


def _variant(params, variant: str, model=None) -> PlantData:
    """Plant numbers of one variant (a key of :data:`VARIANTS` or :data:`EDGE_VARIANTS`)."""
    if variant in EDGE_VARIANTS:
        return plant_data(params, model, edge=EDGE_VARIANTS[variant])
    s, f = VARIANTS[variant]
    return plant_data(params, model, s, f)


def loop_transfer(params, loop: str, variant: str = 'nominal', model=None,
                  rate: float | None = None):
    """Discrete open loop L(z) = PID(z) * z^-1 * plant(z), the gains scheduled at ``rate``.

    ``rate``: the state rate (Hz) the PID steps at (default ``expected_state_rate``); the
    gains are the controller's at that rate (:func:`~grip_force_ros.control.schedule.
    scheduled_gains`). ``variant``: a key of :data:`VARIANTS` or (force loops)
    :data:`EDGE_VARIANTS`.
    """
    rate = float(rate or params.expected_state_rate)
    return (_controller_tf(params, loop, rate)
            * discrete_plant(_variant(params, variant, model), loop, 1.0 / rate))


def margins(loop_tf, period: float, n: int = 1500) -> tuple[float, float, float, float]:
    """Gain margin (dB), phase margin (deg), and their frequencies (rad/s) of a discrete loop.

    ``loop_tf`` is a python-control discrete transfer function L(z). The frequency response
    is sampled on a dense grid up to Nyquist and every crossing is refined with ``brentq``
    on the exact response. As ``control.margin``: the phase margin is the smallest over the
    gain crossovers; the gain margin is the one closest to 0 dB over the phase crossovers
    (a gain-reduction margin would come out negative). ``test_tune.py`` checks agreement with
    ``control.margin`` on a dense FRD, which is ~50x slower.

    Returns
    -------
    (gm_db, pm_deg, w_gm, w_pm); inf / nan when there is no crossing.
    """
    from scipy.optimize import brentq
    num = np.atleast_1d(np.squeeze(np.asarray(loop_tf.num[0][0], float)))
    den = np.atleast_1d(np.squeeze(np.asarray(loop_tf.den[0][0], float)))

    def resp(w):
        z = np.exp(1j * np.asarray(w) * period)
        return np.polyval(num, z) / np.polyval(den, z)

    w = _freq_grid(period, n)
    nyquist = math.pi / period
    w = np.append(w, nyquist)
    val = resp(w)
    mag = np.abs(val)
    pm, w_pm = math.inf, math.nan
    for i in np.nonzero(np.diff(np.sign(mag - 1.0)) != 0)[0]:
        wc = brentq(lambda x: abs(resp(x)) - 1.0, w[i], w[i + 1], xtol=1e-10)
        phase = math.degrees(abs(np.angle(resp(wc))))
        if 180.0 - phase < pm:
            pm, w_pm = 180.0 - phase, wc
    best, w_gm = math.inf, math.nan           # |log10(1/|L|)| closest to 0
    crossings = [(w[i], w[i + 1]) for i in np.nonzero(np.diff(np.sign(val.imag)) != 0)[0]]
    for lo, hi in crossings:
        wp = brentq(lambda x: resp(x).imag, lo, hi, xtol=1e-10)
        v = resp(wp)
        if v.real < 0 and abs(v) > 0:
            gm = -20.0 * math.log10(abs(v))
            if abs(gm) < abs(best):
                best, w_gm = gm, wp
    v = resp(nyquist)                           # L is real at the Nyquist frequency
    if v.real < 0 and abs(v) > 0:
        gm = -20.0 * math.log10(abs(v))
        if abs(gm) < abs(best):
            best, w_gm = gm, nyquist
    return best, pm, w_gm, w_pm


def _bandwidth_hz(closed, period) -> float:
    """-3 dB bandwidth (Hz) of a discrete closed loop, from its frequency response."""
    w = _freq_grid(period, 2000)
    mag = np.abs(closed(np.exp(1j * w * period)))
    dc = mag[0]
    below = np.nonzero(mag < dc / math.sqrt(2.0))[0]
    return float(w[below[0]] / (2 * math.pi)) if below.size else float(w[-1] / (2 * math.pi))


def analysis_rates(params) -> tuple[float, ...]:
    """State rates (Hz) :func:`analyse` checks: :data:`GRID_RATES`, the expected and the design rate."""
    return tuple(sorted(set(GRID_RATES) | {float(params.expected_state_rate),
                                           float(params.gain_design_rate)}))


def loop_variants(loop: str) -> tuple[str, ...]:
    """Plant variants of ``loop``: every :data:`VARIANTS`, for the force loops the edges too."""
    return tuple(VARIANTS) + (tuple(EDGE_VARIANTS) if loop != 'jaw' else ())


def analyse(params, model=None, loops=('force_sensor', 'force_estimate', 'jaw'),
            rates=None) -> TuneResult:
    """Margins (python-control), crossover and closed-loop bandwidth of each loop and variant.

    At every state rate of ``rates`` (Hz; default :func:`analysis_rates`), each with the
    gains the controller runs there (the schedule of ``params``).
    """
    import control
    data = variant_data(params, model)
    reports = []
    for rate in (rates or analysis_rates(params)):
        period = 1.0 / rate
        sch = scheduled_gains(params, rate)
        for loop in loops:
            c = _controller_tf(params, loop, rate)
            for variant in loop_variants(loop):
                lt = c * discrete_plant(data[variant], loop, period)
                gm_db, pm, _, wp = margins(lt, period)
                closed = control.feedback(lt, 1)
                stable = bool(np.all(np.abs(control.poles(closed)) < 1.0))
                reports.append(LoopReport(loop, variant, rate, gm_db, pm,
                                          wp / (2 * math.pi) if math.isfinite(wp) else 0.0,
                                          _bandwidth_hz(closed, period), stable,
                                          sch.jaw_scale if loop == 'jaw' else sch.force_scale))
    period = 1.0 / params.expected_state_rate
    gains = {k: params[k] for k in GAIN_KEYS['force'] + GAIN_KEYS['jaw']
             + ('gain_design_rate', 'force_schedule_knee', 'jaw_schedule_knee')}
    return TuneResult(gains=gains, reports=reports, period=period, schedule=scheduled_gains(params))


def step_responses(params, duration: float = 0.2, model=None, rate: float | None = None) -> dict:
    """Closed-loop responses to a unit target step (nominal plant), python-control.

    At the state rate ``rate`` (Hz; default ``expected_state_rate``), with the gains the
    controller runs there (scheduled).

    Returns
    -------
    dict
        loop -> (t [s], y [output unit per unit target]): 'force_sensor' and
        'force_estimate' with the ideal feedforward (current = target / force_per_amp + PID),
        'force_sensor (PID only)', and 'jaw' (PID only).
    """
    import control
    rate = float(rate or params.expected_state_rate)
    period = 1.0 / rate
    d = plant_data(params, model)
    out = {}
    t = np.arange(0.0, duration, period)
    for loop in ('force_sensor', 'force_estimate', 'jaw'):
        plant = discrete_plant(d, loop, period)
        c = _controller_tf(params, loop, rate)
        closed = control.feedback(c * plant, 1)
        if loop == 'jaw':
            out['jaw (PID only)'] = control.step_response(closed, T=t)
            continue
        ff = 1.0 / (d.force_per_amp if loop == 'force_sensor' else d.estimate_gain)
        with_ff = control.feedback(plant, c) * (ff + c)        # y = P (ff + C) / (1 + P C) r
        out[f'{loop} (feedforward + PID)'] = control.step_response(with_ff, T=t)
        if loop == 'force_sensor':
            out[f'{loop} (PID only)'] = control.step_response(closed, T=t)
            ramp = np.minimum(t / RAMP_TIME, 1.0)
            out[f'{loop} (feedforward + PID, target ramped over {RAMP_TIME * 1e3:.0f} ms)'] = \
                control.forced_response(with_ff, T=t, U=ramp)
    return {k: (np.asarray(v.time), np.asarray(v.outputs).ravel()) for k, v in out.items()}


def settling_time(t: np.ndarray, y: np.ndarray, band: float = 0.05) -> float:
    """Time (s) after which ``y`` stays within ``band`` of its final value."""
    final = y[-1]
    outside = np.nonzero(np.abs(y - final) > band * max(abs(final), 1e-12))[0]
    return float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(t) else (
        0.0 if not outside.size else float(t[-1]))
