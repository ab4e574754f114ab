"""GripForceModel: forward and inverse grip-force model of one instrument.

Forward: (current, wrist angle, jaw angle, velocities, object) -> grip force, needle
pull-out force, jaw drive torque, chain efficiency, drum tension. Inverse: target grip
force -> current. Vectorised (numpy broadcasting) plus scalar fast paths for the 1 kHz
control loop. See docs/model.md for the equations and the readings of the paper.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq

from grip_force_ros.model import angle as _angle
from grip_force_ros.model import contact as _contact
from grip_force_ros.model import friction as _friction
from grip_force_ros.model import transmission as _tx
from grip_force_ros.model.contact import OBJECTS, ModelError, check_object
from grip_force_ros.params import ParameterError, check_consistency

__all__ = ['GripForceModel', 'ForwardResult', 'ModelError', 'OBJECTS', 'check_instrument']


@dataclass(frozen=True)
class ForwardResult:
    """Output of :meth:`GripForceModel.forward` (arrays, broadcast shape of the inputs).

    Attributes
    ----------
    grip_force : ndarray
        Grip force F_J (N), >= 0.
    pull_out_force : ndarray
        Needle pull-out force F_L (N); 0 for 'free', NaN for 'rigid'/'tissue' (not modelled).
    jaw_torque : ndarray
        Drive-pulley torque M (N*m), unclipped (negative = the cable cannot squeeze).
    efficiency : ndarray
        Chain efficiency lambda_n (-).
    drum_tension : ndarray
        Drum tension F0 (N).
    """

    grip_force: np.ndarray
    pull_out_force: np.ndarray
    jaw_torque: np.ndarray
    efficiency: np.ndarray
    drum_tension: np.ndarray


def check_instrument(params: Any) -> None:
    """Cross-field checks the per-key ranges cannot express.

    :func:`grip_force_ros.params.make_params` already runs them on every load; this
    re-check covers parameter objects built by other means.

    Raises
    ------
    ModelError
        Naming the keys and values (e.g. cable thicker than a pulley).
    """
    try:
        check_consistency(params)
    except ParameterError as exc:
        raise ModelError(str(exc)) from None


class GripForceModel:
    """Grip-force model of one cable-driven instrument.

    Parameters
    ----------
    params : ParamSet
        Validated parameters (``grip_force_ros.params``); the 'instrument' group is used.
    losses : bool
        True: pulley friction, creep and the static resistance moment. False: the
        ideal instrument (lambda_n = 1, no creep, no static resistance); the inertial
        part of M' stays.

    Raises
    ------
    ModelError
        If the geometry is inconsistent (see :func:`check_instrument`).
    """

    def __init__(self, params: Any, losses: bool = True):
        check_instrument(params)
        p = params
        self.params = params
        self.losses = bool(losses)
        self.tension_per_amp = _tx.drum_tension_per_amp(p.torque_constant, p.gear_ratio, p.drum_radius)
        self.mu = p.pulley_friction_coefficient if losses else 0.0
        self.friction_gain = p.tension_friction_gain if losses else 0.0
        self.resistance_fraction = p.drive_resistance_fraction if losses else 0.0
        self.radii = tuple(p.guide_pulley_radii)
        self.wraps = tuple(p.guide_pulley_wrap_angles)
        self.wrist_wrap_gain = p.wrist_wrap_gain
        self.stiffness = _angle.cable_section_stiffness(p.cable_modulus, p.cable_radius)
        self.affine = self.friction_gain == 0.0   # grip force affine in current
        # scalar fast-path constants
        self._exps = [_friction.exponents_scalar(self.mu, r, p.cable_radius) for r in self.radii]
        fixed = 1.0
        for (a, b), wrap in zip(self._exps[:-1], self.wraps[:-1]):
            fixed /= _friction.pulley_ratio_scalar(a, b, wrap)
        self._fixed_efficiency = fixed            # all pulleys but the last (wrist-independent)
        self._rho = tuple((r - p.cable_radius) / p.cable_radius for r in self.radii)
        self._rn = p.drive_pulley_radius
        self._tip, self._inner = p.jaw_moment_arm_tip, p.jaw_moment_arm_inner
        self._pull_per_grip = _contact.PULL_OUT_PER_MU * p.needle_friction_coefficient

    # ------------------------------------------------------------------ helpers
    def wrap_angles(self, wrist_angle=0.0):
        """Wrap angles of the guide pulleys (rad); the last grows by ``wrist_wrap_gain |wrist|``."""
        last = self.wraps[-1] + self.wrist_wrap_gain * np.abs(np.asarray(wrist_angle, float))
        return [*self.wraps[:-1], last]

    def efficiency(self, current=0.0, wrist_angle=0.0):
        """Chain efficiency lambda_n (-) at a current (A) and wrist angle (rad)."""
        f0 = self.tension_per_amp * np.asarray(current, float)
        return _friction.chain_efficiency(self.mu, self.radii, self.params.cable_radius,
                                          self.wrap_angles(wrist_angle), f0, self.friction_gain)

    def torque_coefficients(self, wrist_angle: float = 0.0) -> tuple[float, float]:
        """Slope (N*m/A) and offset (N*m) of M(I) at zero velocities (constant friction).

        Raises
        ------
        ModelError
            With tension-dependent friction M(I) is not affine.
        """
        if not self.affine:
            raise ModelError('torque is not affine in current when tension_friction_gain > 0')
        lam = float(self.efficiency(0.0, wrist_angle))
        return self.tension_per_amp * self._rn * (lam - self.resistance_fraction), 0.0

    def creep_angles(self, current, wrist_angle=0.0):
        """Creep angles (rad): (finger chain, wrist cable), both >= 0 for closing current."""
        if not self.losses:
            zero = np.zeros(np.broadcast(np.asarray(current, float), np.asarray(wrist_angle, float)).shape)
            return zero, zero
        p = self.params
        f0 = self.tension_per_amp * np.asarray(current, float)
        finger = _angle.wrap_creep_angle(f0, self.mu, self.radii, p.cable_radius,
                                         self.wrap_angles(wrist_angle), self.stiffness, self._rn,
                                         self.friction_gain)
        # The wrist cable's own tension is not in the paper (it lumps everything into the
        # jaw current); we load it with the same drum tension, on pulleys of the last
        # guide-pulley radius.
        wrist_wraps = tuple(p.wrist_cable_wrap_angles)
        wrist = _angle.wrap_creep_angle(f0, self.mu, (self.radii[-1],) * len(wrist_wraps),
                                        p.cable_radius, wrist_wraps, self.stiffness, self._rn,
                                        self.friction_gain)
        return finger, wrist

    # ------------------------------------------------------------------ vectorised API
    def drive_torque(self, current, wrist_angle=0.0, motor_velocity=0.0, jaw_velocity=0.0):
        """Drive-pulley torque M (N*m), and (efficiency, drum tension)."""
        f0 = self.tension_per_amp * np.asarray(current, float)
        lam = _friction.chain_efficiency(self.mu, self.radii, self.params.cable_radius,
                                         self.wrap_angles(wrist_angle), f0, self.friction_gain)
        inertial = _tx.inertial_moment(-np.asarray(jaw_velocity, float), motor_velocity, self._rn,
                                       self.params.jaw_mass, self.params.drum_mass)
        torque = _tx.drive_torque(f0, lam, self._rn, self.resistance_fraction, inertial)
        return torque, lam, f0

    def forward(self, current, wrist_angle, jaw_angle, obj: str = 'needle', motor_velocity=0.0,
                jaw_velocity=0.0) -> ForwardResult:
        """Grip force and more from the motor current (arrays broadcast).

        Parameters
        ----------
        current : float or array
            Motor current (A), positive closes.
        wrist_angle : float or array
            Wrist pitch (rad).
        jaw_angle : float or array
            Jaw opening angle (rad), 0 = closed.
        obj : str
            One of :data:`OBJECTS`.
        motor_velocity, jaw_velocity : float or array
            Drum rate (rad/s, positive closing) and jaw opening rate (rad/s); only the
            (tiny) inertial term of M' uses them.

        Returns
        -------
        ForwardResult
        """
        check_object(obj)
        current, wrist, jaw, mv, jv = np.broadcast_arrays(
            *(np.asarray(x, float) for x in (current, wrist_angle, jaw_angle, motor_velocity, jaw_velocity)))
        torque, lam, f0 = self.drive_torque(current, wrist, mv, jv)
        gain = _contact.contact_gain(obj, jaw, self._tip, self._inner)
        grip = np.maximum(torque, 0.0) * gain
        if obj == 'needle':
            pull = grip * self._pull_per_grip
        elif obj == 'free':
            pull = np.zeros_like(grip)
        else:
            pull = np.full_like(grip, np.nan)
        return ForwardResult(grip, pull, torque, np.broadcast_to(lam, grip.shape).copy(), f0)

    def inverse(self, grip_force, wrist_angle, jaw_angle, obj: str = 'needle', motor_velocity=0.0,
                jaw_velocity=0.0):
        """Current (A) that gives ``grip_force`` (N) (arrays broadcast).

        A zero force returns the current at which the jaw just starts to squeeze.

        Raises
        ------
        ModelError
            Negative or non-finite force; a positive force with no contact ('free',
            jaw open past pi/2); a force the instrument cannot reach.
        """
        check_object(obj)
        force, wrist, jaw, mv, jv = np.broadcast_arrays(
            *(np.asarray(x, float) for x in (grip_force, wrist_angle, jaw_angle, motor_velocity, jaw_velocity)))
        if not np.all(np.isfinite(force)) or np.any(force < 0.0):
            raise ModelError(f'grip force must be finite and >= 0 N, got {force[~(force >= 0)][:3]!r}')
        gain = _contact.contact_gain(obj, jaw, self._tip, self._inner)
        if np.any((gain <= 0.0) & (force > 0.0)):
            raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                             'at these jaw angles')
        with np.errstate(divide='ignore', invalid='ignore'):
            torque = np.where(force > 0.0, force / gain, 0.0)                 # M needed (N*m)
        inertial = _tx.inertial_moment(-jv, mv, self._rn, self.params.jaw_mass, self.params.drum_mass)
        if self.affine:
            lam = _friction.chain_efficiency(self.mu, self.radii, self.params.cable_radius,
                                             self.wrap_angles(wrist))
            per_amp = self.tension_per_amp * self._rn * (lam - self.resistance_fraction)
            if np.any(per_amp <= 0.0):
                raise ModelError(self._no_grip_message(float(np.min(lam))))
            return (torque - inertial) / per_amp
        flat = [self._solve_current(t, w, i) for t, w, i in
                zip(torque.ravel(), np.broadcast_to(wrist, torque.shape).ravel(), inertial.ravel())]
        return np.asarray(flat, float).reshape(torque.shape)

    def jaw_angle(self, motor_angle, wrist_angle, current):
        """Jaw opening angle (rad) from drum angle (rad), wrist pitch (rad), current (A).

        ``jaw = -(r0/r_n) theta_0 + creep_finger + coupling (theta_32 - creep_wrist)``;
        0 = closed at zero drum angle, zero wrist angle and zero current.
        """
        finger, wrist_creep = self.creep_angles(current, wrist_angle)
        return _angle.jaw_angle_from_drum(motor_angle, wrist_angle, finger, wrist_creep,
                                          self.params.drum_radius, self._rn,
                                          self.params.wrist_finger_coupling)

    def motor_angle(self, jaw_angle, wrist_angle, current):
        """Inverse of :meth:`jaw_angle`: drum angle (rad) that gives ``jaw_angle``."""
        finger, wrist_creep = self.creep_angles(current, wrist_angle)
        return _angle.drum_angle_for_jaw(jaw_angle, wrist_angle, finger, wrist_creep,
                                         self.params.drum_radius, self._rn,
                                         self.params.wrist_finger_coupling)

    def creep_coefficient(self, wrist_angle: float = 0.0) -> float:
        """d(theta_4)/dI of the paper's convention (rad/A): -(finger - 0.6 wrist creep) per A."""
        finger, wrist = self.creep_angles(1.0, wrist_angle)
        return -float(finger - self.params.wrist_finger_coupling * wrist)

    # ------------------------------------------------------------------ scalar fast path
    def _efficiency_scalar(self, drum_tension: float, wrist_angle: float) -> float:
        last_wrap = self.wraps[-1] + self.wrist_wrap_gain * abs(wrist_angle)
        if self.affine:
            a, b = self._exps[-1]
            return self._fixed_efficiency / _friction.pulley_ratio_scalar(a, b, last_wrap)
        loaded = drum_tension > 0.0
        start = drum_tension if loaded else 1.0
        tension = start
        mu, gain, exp, sqrt = self.mu, self.friction_gain, math.exp, math.sqrt
        last = len(self._rho) - 1
        for i, rho in enumerate(self._rho):
            wrap = last_wrap if i == last else self.wraps[i]
            mu_here = mu * (1.0 + gain * tension) if loaded else mu        # mu(F) = mu (1 + g F)
            if mu_here <= 0.0:
                continue
            root = sqrt((1.0 + rho) ** 2 + 4.0 * mu_here * mu_here * rho)
            a = 2.0 * mu_here * rho / ((1.0 + rho) + root)
            b = -((1.0 + rho) + root) / (2.0 * mu_here)
            weight = a / (a - b)
            tension /= weight * exp(b * wrap) + (1.0 - weight) * exp(a * wrap)   # / eta_i
        return tension / start

    def _torque_scalar(self, current: float, wrist_angle: float) -> float:
        f0 = self.tension_per_amp * current
        lam = self._efficiency_scalar(f0, wrist_angle)
        return self._rn * f0 * (lam - self.resistance_fraction)

    def grip_force_scalar(self, current: float, wrist_angle: float, jaw_angle: float,
                          obj: str = 'needle') -> float:
        """Grip force (N) for one sample, zero velocities (control-loop fast path)."""
        torque = self._torque_scalar(current, wrist_angle)
        if torque <= 0.0:
            return 0.0
        return torque * _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)

    def current_for_force_scalar(self, grip_force: float, wrist_angle: float, jaw_angle: float,
                                 obj: str = 'needle') -> float:
        """Current (A) for a target grip force (N), zero velocities (control-loop fast path).

        Raises
        ------
        ModelError
            As :meth:`inverse`.
        """
        if not grip_force >= 0.0 or grip_force == math.inf:
            raise ModelError(f'grip force must be finite and >= 0 N, got {grip_force!r}')
        if grip_force == 0.0:
            return 0.0
        gain = _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)
        if gain <= 0.0:
            raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                             f'at jaw angle {jaw_angle!r} rad')
        torque = grip_force / gain
        if self.affine:
            lam = self._efficiency_scalar(0.0, wrist_angle)
            per_amp = self.tension_per_amp * self._rn * (lam - self.resistance_fraction)
            if per_amp <= 0.0:
                raise ModelError(self._no_grip_message(lam))
            return torque / per_amp
        return self._solve_current(torque, wrist_angle, 0.0)

    # ------------------------------------------------------------------ nonlinear inverse
    def _solve_current(self, torque: float, wrist_angle: float, inertial: float) -> float:
        """Current with M(I) + inertial = torque, tension-dependent friction (brentq)."""
        need = torque - inertial
        if need <= 0.0:
            return need / self._slope_at_zero(wrist_angle)
        slope0 = self._slope_at_zero(wrist_angle)
        guess = need / slope0                         # friction only grows: M(I) <= slope0 I
        newton = self._newton_current(need, wrist_angle, guess)
        if newton is not None:
            return newton
        low, high = 0.0, guess
        for _ in range(200):
            value = self._torque_scalar(high, wrist_angle)
            if value >= need:
                break
            low, previous = high, value
            high *= 1.5
            if self._torque_scalar(high, wrist_angle) <= previous:
                raise ModelError(f'drive torque {need:.4g} N*m is beyond the largest this instrument '
                                 f'reaches with tension-dependent friction ({previous:.4g} N*m)')
        else:  # pragma: no cover - guarded by the monotonicity check
            raise ModelError(f'drive torque {need:.4g} N*m not reached')
        return brentq(lambda i: self._torque_scalar(i, wrist_angle) - need, low, high,
                      xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=200)

    def _newton_current(self, need: float, wrist_angle: float, start: float) -> float | None:
        """Newton from ``start``; None (hand over to brentq) if it does not converge.

        The slope is a forward difference. A non-positive slope (past the peak of M)
        or a step out of (0, inf) gives up.
        """
        current = start
        for _ in range(30):
            value = self._torque_scalar(current, wrist_angle) - need
            step_size = 1e-7 * current
            slope = (self._torque_scalar(current + step_size, wrist_angle) - need - value) / step_size
            if not slope > 0.0:
                return None
            step = -value / slope
            current += step
            if not current > 0.0:
                return None
            if abs(step) <= 1e-13 * current:
                return current
        return None

    def _slope_at_zero(self, wrist_angle: float) -> float:
        lam = self._efficiency_scalar(0.0, wrist_angle)
        per_amp = self.tension_per_amp * self._rn * (lam - self.resistance_fraction)
        if per_amp <= 0.0:
            raise ModelError(self._no_grip_message(lam))
        return per_amp

    def _no_grip_message(self, lam: float) -> str:
        return (f'chain efficiency lambda_n = {lam:.4g} is not above drive_resistance_fraction = '
                f'{self.resistance_fraction:.4g}: the model gives no grip force at any current')
