"""Plant dynamics of the simulated instrument: motor, drum, elastic cable with pulley friction, jaw, contact.

State and coordinates (SI, ARCHITECTURE.md signs)::

    drum angle theta0 (rad, + closing), rate w0       inertia J0 = motor_inertia + m0 r0^2 / 2
    jaw opening angle phi (rad, 0 = closed), rate wj  inertia jaw_inertia
    cable pulled in at the drum   b = r0 theta0        (m, + toward the drum)
    cable pulled in at the jaw    a = r_n (c w - phi)  (m; c = wrist_finger_coupling, w = wrist pitch)
    pulley node position x (m): the cable at the guide pulleys, massless

The cable is two springs in series around the pulley chain: drum side
``T0 = k1 (b - x)`` and jaw side ``Tn = k2 dz(x - a)`` (dz = dead zone of the backlash
effect, identity when off), ``k = E A / L * stiffness_scale`` split by
``cable_jaw_side_fraction``. The node sticks while the pulley friction can hold it
(capstan band ``|T0 - Tn| <= (1 - lambda) max(|T0|, |Tn|)``) and slips otherwise, with
the tension ratio of the model's chain efficiency ``lambda`` taken in the direction of
slip: drum pulling ``Tn = lambda T0``, jaw pulling back ``T0 = lambda Tn``
(``lambda`` from :mod:`grip_force_ros.model.friction` with ``mu * friction_scale``).

Equations of motion (torques in N*m)::

    J0 dw0/dt = gear K I - r0 T0 - drum_damping w0
    Jj dwj/dt = -r_n Tn (1 - f/lambda) + M_contact(phi, wj) - (jaw_damping + viscous) wj
                + pivot friction + hysteresis, creep and position-spring moments (effects)

The instrument's own jaw friction and spring (the ``jaw_*`` parameters,
:mod:`grip_force_ros.model.jaw_friction`, all 0 in the paper's instruments) are the same
physics as those effects, added to them: the Coulomb friction at the jaw ``C(phi) + q tau^2``
(``tau`` the jaw's drive moment at the step's start) adds to ``pivot_coulomb_friction``, the
viscous friction to the jaw damping, the spring ``K(phi)`` to the opening moments. The model
is what the controller is told, the effects are what it is not; with the terms at 0 the
plant's arithmetic is the one without them (the code is skipped).

The position spring (effect ``position_spring`` = S, ``position_spring_rest_angle`` =
phi_r) is a preloaded torsion spring at the jaw: opening moment ``S (1 - phi / phi_r)``
(N*m), S at the closed jaw, 0 at phi_r. It is a jaw torque like the others: it moves the
free jaw (against the cable, which stretches and turns the drum) and, in contact, the
object holds only what the drive moment leaves over, so the load cell reads
``(r_n Tn (1 - f/lambda) - S (1 - phi/phi_r)) G`` at rest: the spring's share comes off the
grip force (an opening spring; never on the load cell directly).

``r_n Tn f/lambda`` is the model's static resistance moment M' = f r_n F0
(``drive_resistance_fraction`` f), applied as the model reads it: a loss proportional to
the tension at the drive pulley, which equals f r_n T0 on the loading branch
(Tn = lambda T0). Tying it to Tn rather than T0 keeps it local to the drive pulley, so a
stuck pulley chain holds the jaw moment (with T0 it would rise as the drum tension
falls). It is not a friction: it does not reverse when the jaw back-drives the cable.

Contact moments: needle and rigid object at the tip arm l, tissue at (l + l')/2,
spring plus damping, never pulling. The load cell reads
``M_contact * G(obj, phi)`` with the model's contact gain G, so the static steady state
on the loading branch is ``GripForceModel.forward(...)``.

Integration: linearly implicit Euler per sub-step for both inertias (the stiffness of
cable and contact in the denominator, damping implicit, stick-slip friction as a velocity
impulse), then the exact node update. Stable for any contact stiffness; sub-step
``1/sim_rate``. Plain float math: this runs at 1 kHz with ~10 sub-steps in real time.
"""
from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass
from typing import Any, Mapping

from grip_force_ros.model import contact as _contact
from grip_force_ros.model import friction as _friction
from grip_force_ros.model.contact import OBJECTS
from grip_force_ros.model.jaw_friction import JawFriction
from grip_force_ros.params.sim import jaw_open_stop
from grip_force_ros.sim.effects import SimError, effect_overrides

__all__ = ['InstrumentSim', 'SimMeasurement', 'OBJECTS', 'chain_efficiency_scalar']

#: Initial slope of the Dahl hysteresis moment per unit change of the drive moment (-):
#: the loop switches sides within about a quarter of its width of tension change.
DAHL_SLOPE = 4.0


@dataclass(frozen=True, slots=True)
class SimMeasurement:
    """What the simulated instrument's sensors report at time ``t``.

    Attributes
    ----------
    t : float
        Simulation time (s).
    motor_angle : float
        Drum angle theta0 (rad), positive closing (encoder noise).
    motor_velocity : float
        Drum rate (rad/s).
    current : float
        Measured motor current (A): current-loop output plus noise.
    wrist_angle : float
        Wrist pitch (rad).
    jaw_angle : float
        Jaw opening angle (rad), 0 = closed.
    jaw_velocity : float
        Jaw opening rate (rad/s).
    grip_force : float
        Load-cell grip force (N); 0 plus noise for 'free'.
    """

    t: float
    motor_angle: float
    motor_velocity: float
    current: float
    wrist_angle: float
    jaw_angle: float
    jaw_velocity: float
    grip_force: float


def chain_efficiency_scalar(mu: float, radii, cable_radius: float, wraps, drum_tension: float = 0.0,
                            gain: float = 0.0) -> float:
    """Chain efficiency lambda_n (-) for one drum tension (N), pure math.

    Same law as :func:`grip_force_ros.model.friction.chain_efficiency`: each pulley sees
    ``mu (1 + gain |T_in|)`` at the tension entering it. |T| because the antagonist
    cable of a negative current rubs the same way.
    """
    tension = abs(drum_tension)
    start = tension if tension > 0.0 else 1.0
    t = start
    for radius, wrap in zip(radii, wraps):
        mu_here = mu * (1.0 + gain * (t if tension > 0.0 else 0.0))
        a, b = _friction.exponents_scalar(mu_here, radius, cable_radius)
        t /= _friction.pulley_ratio_scalar(a, b, wrap)
    return t / start


class InstrumentSim:
    """Simulated cable-driven instrument (one jaw cable, kinematic wrist).

    Parameters
    ----------
    params : ParamSet
        Validated parameters: the 'instrument' group is the plant's geometry
        (the plant differs from it by ``friction_scale`` and ``stiffness_scale``), the
        'sim' group its dynamics and sensors, the 'effects' group the effect strengths.
    obj : str
        Object between the jaws: 'free', 'rigid', 'tissue' or 'needle'. None: the
        ``sim_object`` parameter.
    effects : dict, optional
        Effect name (:data:`EFFECT_NAMES`) -> strength, overriding the 'effects'
        parameters (``{'backlash': 0.02}``). Extra effect parameters such as
        ``viscoelastic_creep_time_constant`` are accepted.
    seed : int
        Seed of the sensor noise (same seed and inputs -> same measurements).

    Raises
    ------
    SimError
        Unknown object or effect, or an effect strength outside its range.
    """

    def __init__(self, params: Any, obj: str | None = 'needle', effects: Mapping[str, float] | None = None,
                 seed: int = 0):
        overrides = effect_overrides(effects)
        if overrides:
            try:
                params = params.replace(**overrides)
            except ValueError as exc:
                raise SimError(str(exc)) from None
        self.params = params
        self._seed = int(seed)
        self._setup_constants()
        self._obj = 'free'
        self.set_object(params.sim_object if obj is None else obj)
        self.reset()

    # ------------------------------------------------------------------ set-up
    def _setup_constants(self) -> None:
        p = self.params
        self._r0 = p.drum_radius
        self._rn = p.drive_pulley_radius
        self._gear_k = p.gear_ratio * p.torque_constant                     # N*m/A at the drum
        stiffness = p.cable_modulus * math.pi * p.cable_radius ** 2 / p.cable_length * p.stiffness_scale
        share = p.cable_jaw_side_fraction
        self._k1 = stiffness / (1.0 - share)                               # N/m, drum side
        self._k2 = stiffness / share                                       # N/m, jaw side
        self._j0 = p.motor_inertia + 0.5 * p.drum_mass * self._r0 ** 2      # kg*m^2
        self._jj = p.jaw_inertia
        self._drum_damping = p.drum_damping
        self._jaw_damping = p.jaw_damping + p.viscous_friction              # nominal + effect
        self._coupling = p.wrist_finger_coupling
        self._resistance_fraction = p.drive_resistance_fraction            # -, f of M' = f r_n F0
        self._mu = p.pulley_friction_coefficient * p.friction_scale
        self._friction_gain = p.tension_friction_gain + p.tension_dependent_friction
        self._tip = p.jaw_moment_arm_tip
        self._inner = p.jaw_moment_arm_inner
        self._tissue_arm = 0.5 * (self._tip + self._inner)
        self._sub_dt_max = 1.0 / p.sim_rate
        self._tau_current = p.current_loop_time_constant
        # effects
        self._pivot_coulomb = p.pivot_coulomb_friction
        # the instrument's own jaw friction and spring (model/jaw_friction.py): the same Coulomb
        # friction at the jaw as the pivot_coulomb_friction effect, added to it
        self._jaw_friction = JawFriction.from_params(p)
        self._jaw_friction_on = self._jaw_friction.active
        if self._jaw_friction_on:
            self._jaw_damping += self._jaw_friction.viscous                # as viscous_friction
        self._hysteresis = p.cable_hysteresis
        self._backlash_half = 0.5 * p.backlash * self._rn                  # m of cable
        self._creep = p.viscoelastic_creep
        self._creep_tau = p.viscoelastic_creep_time_constant
        self._delay = p.sensor_delay
        self._drift = p.torque_constant_drift
        self._drift_tau = p.torque_constant_drift_time_constant
        self._heat_current = p.max_current if p.max_current > 0.0 else 1.0
        self._offset = p.force_sensor_offset
        self._spring_closed = p.position_spring                            # N*m at phi = 0
        self._spring_rate = p.position_spring / p.position_spring_rest_angle  # N*m/rad
        self._noise = (p.current_noise_std, p.motor_angle_noise_std, p.motor_velocity_noise_std,
                       p.wrist_angle_noise_std, p.jaw_angle_noise_std, p.jaw_velocity_noise_std,
                       p.grip_force_noise_std)

    def _efficiency(self, drum_tension: float) -> float:
        p = self.params
        wraps = list(p.guide_pulley_wrap_angles)
        wraps[-1] += p.wrist_wrap_gain * abs(self._wrist)
        return chain_efficiency_scalar(self._mu, p.guide_pulley_radii, p.cable_radius, wraps,
                                       drum_tension, self._friction_gain)

    def _drive_arm(self) -> float:
        """Jaw moment per N of jaw-side tension (m): ``r_n (1 - f/lambda)``, >= 0."""
        lam = self._lambda
        arm = self._rn * (1.0 - self._resistance_fraction / lam) if lam > 0.0 else 0.0
        return arm if arm > 0.0 else 0.0

    # ------------------------------------------------------------------ public API
    @property
    def obj(self) -> str:
        """The object between the jaws."""
        return self._obj

    @property
    def t(self) -> float:
        """Simulation time (s)."""
        return self._t

    def set_object(self, obj: str) -> None:
        """Put ``obj`` ('free', 'rigid', 'tissue', 'needle') between the jaws; the state is kept.

        Raises
        ------
        SimError
            Unknown object.
        """
        if obj not in OBJECTS:
            raise SimError(f'unknown object {obj!r}; expected one of {list(OBJECTS)}')
        p = self.params
        self._obj = obj
        self._tissue = obj == 'tissue'
        self._tissue_exp = p.tissue_model == 'exponential' and p.tissue_exponential_rate > 0.0
        self._tissue_rate = p.tissue_exponential_rate
        if obj == 'needle':
            self._contact_angle, self._contact_k, self._contact_arm = (
                p.needle_contact_angle, p.needle_stiffness, self._tip)
        elif obj == 'rigid':
            self._contact_angle, self._contact_k, self._contact_arm = (
                p.rigid_contact_angle, p.rigid_stiffness, self._tip)
        elif obj == 'tissue':
            self._contact_angle, self._contact_k, self._contact_arm = (
                p.tissue_contact_angle, p.tissue_stiffness, self._tissue_arm)
        else:
            self._contact_angle, self._contact_k, self._contact_arm = (-1.0, 0.0, self._tip)
        self._stop_k = p.rigid_stiffness * self._tip ** 2                  # N*m/rad, jaw hard stops
        self._open_stop = jaw_open_stop(p)                                  # rad
        self._zeta2 = 2.0 * p.contact_damping_ratio
        self._measurement = None

    def set_params(self, params: Any) -> None:
        """Change parameters at runtime (e.g. an effect strength, noise); the state is kept.

        Geometry changes act from the next step on; a new ``sim_seed`` does not re-seed
        (use :meth:`reset`).
        """
        self.params = params
        self._setup_constants()
        self.set_object(self._obj)
        self._lambda = self._efficiency(self._tension_drum)
        self._measurement = None

    def jaw_angle_now(self) -> float:
        """Return the jaw angle (rad) now, noise-free: what the sim's jaw sensor reads."""
        return self._phi

    def jaw_state(self) -> tuple[float, float]:
        """Return the jaw angle (rad) and rate (rad/s) the drum's encoder gives, noise-free.

        The jaw as a drive sees it from the motor side (the dVRK's disc encoders): the drum
        angle through the drum and drive pulley radii and the wrist coupling,
        ``c w - r0 theta0 / r_n`` (the true jaw angle at no cable stretch). A loop closed on it
        is collocated with the motor, as the dVRK's disc PIDs are.
        """
        k = self._r0 / self._rn
        return self._coupling * self._wrist - k * self._theta0, -k * self._w0

    def drum_constants(self) -> tuple[float, float, float]:
        """Return the drum's inertia (kg*m^2), its torque per A (N*m/A) and ``r0 / r_n`` (-)."""
        return self._j0, self._gear_k, self._r0 / self._rn

    def set_wrist_angle(self, wrist_angle: float) -> None:
        """Set the wrist pitch (rad). The wrist is kinematic: it moves the jaw through the coupling.

        Raises
        ------
        SimError
            If not finite.
        """
        wrist_angle = float(wrist_angle)
        if not math.isfinite(wrist_angle):
            raise SimError(f'wrist angle must be finite, got {wrist_angle!r}')
        if wrist_angle == self._wrist:
            return
        self._wrist = wrist_angle
        if self.params.wrist_wrap_gain > 0.0:          # the last wrap angle follows |wrist|
            self._lambda = self._efficiency(self._tension_drum)
        self._measurement = None

    def reset(self) -> None:
        """Go back to rest, time 0.

        No tension, jaw at ``initial_jaw_angle``, wrist at ``initial_wrist_angle``,
        effect states and noise generator re-seeded.
        """
        p = self.params
        self._t = 0.0
        self._rng = random.Random(self._seed)
        self._wrist = p.initial_wrist_angle
        self._tension_drum = 0.0
        self._phi = p.initial_jaw_angle
        self._wj = 0.0
        self._a = self._rn * (self._coupling * self._wrist - self._phi)
        self._x = self._a                                                 # slack-free, no tension
        self._theta0 = self._x / self._r0
        self._w0 = 0.0
        self._i_act = 0.0
        self._i_cmd = 0.0
        self._tension_jaw = 0.0
        self._hyst = 0.0                                                  # N*m, Dahl moment
        self._creep_moment = 0.0                                          # N*m
        self._heat = 0.0                                                  # -, normalised
        self._contact_moment = 0.0
        self._lambda = self._efficiency(0.0)
        self._history = deque([(0.0, 0.0)])
        self._measurement = None

    # ------------------------------------------------------------------ dynamics
    def step(self, current_command: float, dt: float) -> None:
        """Advance the plant by ``dt`` seconds with the motor current command held.

        Parameters
        ----------
        current_command : float
            Current command (A), positive closes. The current loop follows it with
            ``current_loop_time_constant``.
        dt : float
            Step (s), > 0; integrated in sub-steps of at most ``1/sim_rate``.

        Raises
        ------
        SimError
            Non-finite command or non-positive step.
        """
        i_cmd = float(current_command)
        if not math.isfinite(i_cmd):
            raise SimError(f'current command must be finite, got {current_command!r}')
        if not dt > 0.0 or not math.isfinite(dt):
            raise SimError(f'dt must be positive and finite, got {dt!r}')
        n = int(math.ceil(dt / self._sub_dt_max - 1e-9))
        h = dt / n
        self._i_cmd = i_cmd
        # slow states, updated once per step (exact first-order discretisations)
        if self._friction_gain > 0.0:
            self._lambda = self._efficiency(self._tension_drum)
        gear_k = self._gear_k
        if self._drift > 0.0:
            load = (self._i_act / self._heat_current) ** 2
            self._heat += (load - self._heat) * (1.0 - math.exp(-dt / self._drift_tau))
            gear_k *= 1.0 - self._drift * self._heat
        if self._creep > 0.0:
            target = self._creep * self._drive_arm() * self._tension_jaw
            self._creep_moment += (target - self._creep_moment) * (1.0 - math.exp(-dt / self._creep_tau))

        # locals for the inner loop
        r0, rn, k1, k2 = self._r0, self._rn, self._k1, self._k2
        j0, jj = self._j0, self._jj
        lam = self._lambda
        one_minus_lam = 1.0 - lam
        drum_c, jaw_c = self._drum_damping, self._jaw_damping
        kd = k1 * r0 * r0                        # N*m/rad, drum stiffness bound
        drive_arm = self._drive_arm()            # m: jaw moment per N of jaw-side tension
        kj_cable = k2 * rn * drive_arm           # N*m/rad, cable stiffness seen by the jaw
        coulomb = self._pivot_coulomb
        jaw_spring = 0.0
        if self._jaw_friction_on:           # at the step's start: friction along the stroke and load
            fr = self._jaw_friction
            held = drive_arm * self._tension_jaw                               # N*m on the jaw
            coulomb += fr.coulomb_at(self._phi) + fr.load_gain * held * held
            jaw_spring = fr.spring_at(self._phi)                               # N*m, opening
            if fr.spring_slope < 0.0:
                kj_cable -= fr.spring_slope      # its restoring stiffness, implicit as the others
        g2 = self._backlash_half
        hyst_frac = self._hysteresis
        cw = self._coupling * self._wrist
        c_angle, c_k, c_arm = self._contact_angle, self._contact_k, self._contact_arm
        tissue, tissue_exp, tissue_rate = self._tissue, self._tissue_exp, self._tissue_rate
        stop_k, zeta2 = self._stop_k, self._zeta2
        spring_closed, spring_rate = self._spring_closed, self._spring_rate
        kj_cable += spring_rate                  # the position spring's stiffness, implicit too
        open_stop = self._open_stop
        alpha = 1.0 - math.exp(-h / self._tau_current) if self._tau_current > 0.0 else 1.0
        theta0, w0, phi, wj, x = self._theta0, self._w0, self._phi, self._wj, self._x
        i_act, hyst, creep = self._i_act, self._hyst, self._creep_moment
        t0 = self._tension_drum
        tn = self._tension_jaw
        previous_tn = tn
        contact = 0.0
        for _ in range(n):
            i_act += alpha * (i_cmd - i_act)
            # --- drum (implicit in its own stiffness and damping)
            w0 = (j0 * w0 + h * (gear_k * i_act - r0 * t0)) / (j0 + h * drum_c + h * h * kd)
            theta0 += h * w0
            # --- jaw: spring moments at phi, local stiffness, damping
            spring = 0.0
            k_loc = kj_cable
            c_loc = jaw_c
            depth = c_angle - phi
            if depth > 0.0:
                arm2 = c_arm * c_arm
                if tissue and tissue_exp:
                    grow = math.exp(tissue_rate * c_arm * depth)
                    spring = c_k / tissue_rate * (grow - 1.0) * c_arm      # N*m
                    k_c = c_k * grow * arm2
                else:
                    k_c = c_k * arm2
                    spring = k_c * depth
                k_loc += k_c
                c_c = zeta2 * math.sqrt(k_c * jj)
                c_loc += c_c
            else:
                c_c = 0.0
            if phi < 0.0:                                   # jaws touch: hard stop
                spring -= stop_k * phi
                k_loc += stop_k
                c_loc += zeta2 * math.sqrt(stop_k * jj)
            elif phi > open_stop:
                spring -= stop_k * (phi - open_stop)
                k_loc += stop_k
                c_loc += zeta2 * math.sqrt(stop_k * jj)
            # opening moments, N*m (the position spring: S (1 - phi/phi_r) = S - rate*phi)
            drive = -drive_arm * tn + hyst + creep + spring + (spring_closed - spring_rate * phi)
            if jaw_spring != 0.0:
                drive += jaw_spring
            momentum = jj * wj + h * drive
            if coulomb > 0.0:
                if abs(momentum) <= h * coulomb:
                    momentum = 0.0                          # stuck
                elif momentum > 0.0:
                    momentum -= h * coulomb
                else:
                    momentum += h * coulomb
            wj = momentum / (jj + h * c_loc + h * h * k_loc)
            phi += h * wj
            if depth > 0.0:
                contact = spring - c_c * wj
                if contact < 0.0:
                    contact = 0.0
            else:
                contact = 0.0
            # --- pulley node: stick, or slip with the capstan ratio in the slip direction
            b = r0 * theta0
            a = rn * (cw - phi)
            t0 = k1 * (b - x)
            u = x - a
            tn = k2 * (u - g2 if u > g2 else (u + g2 if u < -g2 else 0.0))
            excess = t0 - tn
            big = abs(t0) if abs(t0) > abs(tn) else abs(tn)
            cap = one_minus_lam * big
            if excess > cap or excess < -cap:
                s = b - a
                if excess > 0.0:                            # node slips toward the drum
                    if s > g2:
                        u = (lam * k1 * s + k2 * g2) / (k2 + lam * k1)
                    elif s < -g2:
                        u = (k1 * s - lam * k2 * g2) / (k1 + lam * k2)
                    else:
                        u = s
                else:                                       # node slips toward the jaw
                    if s > g2:
                        u = (k1 * s + lam * k2 * g2) / (k1 + lam * k2)
                    elif s < -g2:
                        u = (lam * k1 * s - k2 * g2) / (k2 + lam * k1)
                    else:
                        u = s
                x = a + u
                t0 = k1 * (s - u)
                tn = k2 * (u - g2 if u > g2 else (u + g2 if u < -g2 else 0.0))
            # --- cable hysteresis (Dahl): a moment opposing changes of the jaw tension
            if hyst_frac > 0.0:
                limit = hyst_frac * drive_arm * abs(tn)
                change = drive_arm * (tn - previous_tn)
                previous_tn = tn
                if limit > 0.0:
                    if change > 0.0:
                        hyst += DAHL_SLOPE * change * (1.0 - hyst / limit)
                    else:
                        hyst += DAHL_SLOPE * change * (1.0 + hyst / limit)
                    if hyst > limit:
                        hyst = limit
                    elif hyst < -limit:
                        hyst = -limit
                else:
                    hyst = 0.0
        self._theta0, self._w0, self._phi, self._wj, self._x = theta0, w0, phi, wj, x
        self._i_act, self._hyst = i_act, hyst
        self._tension_drum, self._tension_jaw = t0, tn
        self._contact_moment = contact
        self._a = rn * (cw - phi)
        self._t += dt
        if self._delay > 0.0:
            self._history.append((self._t, self._true_grip_force()))
            horizon = self._t - self._delay - dt
            while len(self._history) > 2 and self._history[1][0] < horizon:
                self._history.popleft()
        self._measurement = None

    # ------------------------------------------------------------------ sensors
    def _true_grip_force(self) -> float:
        """Grip force (N) of the contact now: contact moment times the model's contact gain."""
        if self._obj == 'free' or self._contact_moment <= 0.0:
            return 0.0
        return self._contact_moment * _contact.contact_gain_scalar(self._obj, self._phi, self._tip,
                                                                   self._inner)

    def _delayed_grip_force(self) -> float:
        if self._delay <= 0.0:
            return self._true_grip_force()
        when = self._t - self._delay
        hist = self._history
        if when <= hist[0][0]:
            return hist[0][1]
        for i in range(len(hist) - 1, 0, -1):
            t_lo, f_lo = hist[i - 1]
            if t_lo <= when:
                t_hi, f_hi = hist[i]
                share = (when - t_lo) / (t_hi - t_lo) if t_hi > t_lo else 1.0
                return f_lo + share * (f_hi - f_lo)
        return hist[0][1]  # pragma: no cover

    def measure(self) -> SimMeasurement:
        """Return the sensor readings now (noisy; the same object until the next :meth:`step`)."""
        if self._measurement is None:
            g = self._rng.gauss
            sc, sm, sv, sw, sj, sjv, sf = self._noise
            self._measurement = SimMeasurement(
                t=self._t,
                motor_angle=self._theta0 + (g(0.0, sm) if sm else 0.0),
                motor_velocity=self._w0 + (g(0.0, sv) if sv else 0.0),
                current=self._i_act + (g(0.0, sc) if sc else 0.0),
                wrist_angle=self._wrist + (g(0.0, sw) if sw else 0.0),
                jaw_angle=self._phi + (g(0.0, sj) if sj else 0.0),
                jaw_velocity=self._wj + (g(0.0, sjv) if sjv else 0.0),
                grip_force=self._delayed_grip_force() + self._offset + (g(0.0, sf) if sf else 0.0),
            )
        return self._measurement

    def truth(self) -> dict[str, float]:
        """Noise-free internal state (for tests and plots; a real instrument has no such call).

        Keys: t (s), motor_angle (rad), motor_velocity (rad/s), current (A, actual),
        current_command (A), wrist_angle, jaw_angle (rad), jaw_velocity (rad/s),
        grip_force (N, undelayed, no offset), drum_tension, jaw_tension (N),
        contact_moment (N*m), efficiency (-), torque_constant (N*m/A, after drift).
        """
        return {'t': self._t, 'motor_angle': self._theta0, 'motor_velocity': self._w0,
                'current': self._i_act, 'current_command': self._i_cmd, 'wrist_angle': self._wrist,
                'jaw_angle': self._phi, 'jaw_velocity': self._wj, 'grip_force': self._true_grip_force(),
                'drum_tension': self._tension_drum, 'jaw_tension': self._tension_jaw,
                'contact_moment': self._contact_moment, 'efficiency': self._lambda,
                'torque_constant': self.params.torque_constant * (1.0 - self._drift * self._heat)}

    def energy(self) -> float:
        """Return the mechanical energy stored in the plant (J).

        Kinetic + cable + contact springs + the position spring (0 at its rest angle).
        """
        k1, k2, g2 = self._k1, self._k2, self._backlash_half
        u = self._x - self._rn * (self._coupling * self._wrist - self._phi)
        slack = u - g2 if u > g2 else (u + g2 if u < -g2 else 0.0)
        cable = 0.5 * k1 * (self._r0 * self._theta0 - self._x) ** 2 + 0.5 * k2 * slack ** 2
        kinetic = 0.5 * self._j0 * self._w0 ** 2 + 0.5 * self._jj * self._wj ** 2
        depth = self._contact_angle - self._phi
        spring = 0.0
        if depth > 0.0:
            d = self._contact_arm * depth
            if self._tissue and self._tissue_exp:
                rate = self._tissue_rate
                spring = self._contact_k / rate * ((math.exp(rate * d) - 1.0) / rate - d)
            else:
                spring = 0.5 * self._contact_k * d * d
        if self._spring_rate > 0.0:            # opening moment rate*(phi_r - phi): potential
            rest = self._spring_closed / self._spring_rate
            spring += 0.5 * self._spring_rate * (rest - self._phi) ** 2
        return kinetic + cable + spring
