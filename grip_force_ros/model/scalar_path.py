"""The control-loop fast path of the grip-force model: one sample, plain floats.

At 1 kHz numpy's per-call overhead dominates a single sample, so these methods use
``math`` on Python floats: the chain efficiency lambda_n pulley by pulley, the drive
torque M (N*m), the grip force (N), and the current (A) for a force (closed form with
constant friction; the fitted table's row when there is one; else Newton, then a
bracket and brentq, which also serve the vectorised path for the samples it hands over).

:class:`ScalarPath` is a part of :class:`~grip_force_ros.model.GripForceModel` (a mixin:
it shares the model's constants), not a model on its own.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from grip_force_ros.model import contact as _contact
from grip_force_ros.model import friction as _friction
from grip_force_ros.model.contact import ModelError

__all__ = ['ScalarPath']


class ScalarPath:
    """Scalar methods of :class:`~grip_force_ros.model.GripForceModel`.

    Reads the model's constants (``tension_per_amp`` (N/A), ``mu``, ``friction_gain``
    (1/N), ``resistance_fraction``, ``wraps`` (rad), ``wrist_wrap_gain``, ``affine``,
    ``_rn``, ``_tip``, ``_inner`` (m)) and, in :meth:`current_for_force_scalar`, the rows
    of the fitted current table (:class:`~grip_force_ros.model.fitted_path.FittedPath`).
    Its own constants come from :meth:`_init_scalar_path`.
    """

    def _init_scalar_path(self, cable_radius: float) -> None:
        """Per-pulley constants of the scalar chain; ``cable_radius`` in m."""
        self._exps = [_friction.exponents_scalar(self.mu, r, cable_radius) for r in self.radii]
        fixed = 1.0
        for (a, b), wrap in zip(self._exps[:-1], self.wraps[:-1]):
            fixed /= _friction.pulley_ratio_scalar(a, b, wrap)
        self._fixed_efficiency = fixed            # all pulleys but the last (wrist-independent)
        self._rho = tuple((r - cable_radius) / cable_radius for r in self.radii)

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
        """Return the current (A) for a target grip force (N), zero velocities (control-loop fast path).

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
            return self._affine_current(torque, wrist_angle)
        rows = self._current_rows
        if rows is not None:                      # the vectorised path's table, ~1 us instead of ~15
            position = torque / self._current_fit[0].step                 # M / step (-), > 0
            if position < len(rows):
                index = int(position)
                within = position - index
                value = 0.0
                for c in reversed(rows[index]):
                    value = value * within + c
                return value * position                                   # I (A)
        return self._solve_current(torque, wrist_angle, 0.0)

    # ---------------------------------------------------------------- with the jaw friction
    def jaw_torque_scalar(self, current: float, wrist_angle: float, jaw_angle: float,
                          direction: float = 1.0, jaw_velocity: float = 0.0) -> float:
        """Torque the jaw holds (N*m) for one sample, friction state ``direction`` (control-loop fast path).

        Parameters
        ----------
        current : float
            Motor current (A), positive closes.
        wrist_angle, jaw_angle : float
            Wrist pitch and jaw opening angle (rad).
        direction : float
            Friction state s in [-1, 1] of the jaw friction (+1 sliding closing).
        jaw_velocity : float
            Jaw opening rate (rad/s), for the jaw's viscous friction.

        Returns
        -------
        float
            The chain torque M (loading edge) through
            :meth:`~grip_force_ros.model.jaw_friction.JawFriction.jaw_torque`; M itself
            when the instrument has no jaw friction terms.
        """
        torque = self._torque_scalar(current, wrist_angle)
        friction = self.jaw_friction
        if not friction.active:
            return torque
        return friction.jaw_torque(torque, jaw_angle, direction, jaw_velocity)

    def grip_force_friction_scalar(self, current: float, wrist_angle: float, jaw_angle: float,
                                   obj: str = 'needle', direction: float = 1.0,
                                   jaw_velocity: float = 0.0) -> float:
        """Grip force (N) for one sample with the jaw friction in state ``direction``.

        :meth:`grip_force_scalar` (bit for bit) when the instrument has no jaw friction
        terms; arguments as :meth:`jaw_torque_scalar`.
        """
        if not self.jaw_friction.active:
            return self.grip_force_scalar(current, wrist_angle, jaw_angle, obj)
        torque = self.jaw_torque_scalar(current, wrist_angle, jaw_angle, direction, jaw_velocity)
        if torque <= 0.0:
            return 0.0
        return torque * _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)

    def current_for_force_friction_scalar(self, grip_force: float, wrist_angle: float,
                                          jaw_angle: float, obj: str = 'needle',
                                          direction: float = 1.0,
                                          jaw_velocity: float = 0.0) -> float:
        """Return the current (A) for a grip force (N) on the branch of friction state ``direction``.

        The chain torque that holds the force against the jaw friction
        (:meth:`~grip_force_ros.model.jaw_friction.JawFriction.chain_torque`), then the
        chain's loading-edge current for it. :meth:`current_for_force_scalar` (bit for
        bit) when the instrument has no jaw friction terms.

        Raises
        ------
        ModelError
            As :meth:`current_for_force_scalar`.
        """
        friction = self.jaw_friction
        if not friction.active:
            return self.current_for_force_scalar(grip_force, wrist_angle, jaw_angle, obj)
        if not grip_force >= 0.0 or grip_force == math.inf:
            raise ModelError(f'grip force must be finite and >= 0 N, got {grip_force!r}')
        torque = 0.0
        if grip_force > 0.0:
            gain = _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)
            if gain <= 0.0:
                raise ModelError(f'no contact: a positive grip force cannot be produced with '
                                 f'obj={obj!r} at jaw angle {jaw_angle!r} rad')
            torque = grip_force / gain
        return self.current_for_chain_torque_scalar(
            friction.chain_torque(torque, jaw_angle, direction, jaw_velocity), wrist_angle)

    def force_through_jaw_friction_scalar(self, chain_force: float, jaw_angle: float, obj: str,
                                          direction: float, jaw_velocity: float = 0.0,
                                          current: float = 0.0, wrist_angle: float = 0.0) -> float:
        """Grip force (N) the jaw holds when the chain alone would give ``chain_force`` (N).

        For an estimate that already follows the chain's stick band
        (:class:`~grip_force_ros.model.hysteresis.HystereticGripForce`): its force, as a
        chain torque through the contact gain, through the jaw friction in state
        ``direction`` (jaw angle in rad, jaw opening rate in rad/s), and back. 0 with no
        contact. A chain force of 0 (the chain cannot squeeze) is the loading-edge chain
        torque of ``current`` (A) at ``wrist_angle`` (rad) where that is negative, else 0:
        a current opening the jaw takes from what the friction holds.
        """
        gain = _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)
        if gain <= 0.0:
            return 0.0
        if chain_force > 0.0:
            chain = chain_force / gain
        else:
            chain = self._torque_scalar(current, wrist_angle)
            if chain > 0.0:
                chain = 0.0
        torque = self.jaw_friction.jaw_torque(chain, jaw_angle, direction, jaw_velocity)
        return torque * gain if torque > 0.0 else 0.0

    def chain_force_for_jaw_friction_scalar(self, grip_force: float, jaw_angle: float, obj: str,
                                            direction: float, jaw_velocity: float = 0.0) -> float:
        """Return the chain's grip force (N) that holds ``grip_force`` (N) against the jaw friction.

        The inverse of :meth:`force_through_jaw_friction_scalar`, for a chain inverse that
        takes a force (the stick band's ``current_for_force``); 0 where the jaw friction
        or spring alone holds the force. ``grip_force`` as given with no contact (the
        chain inverse refuses it).
        """
        gain = _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)
        if gain <= 0.0:
            return grip_force
        torque = self.jaw_friction.chain_torque(grip_force / gain, jaw_angle, direction, jaw_velocity)
        return torque * gain if torque > 0.0 else 0.0

    def current_for_chain_torque_scalar(self, torque: float, wrist_angle: float) -> float:
        """Return the loading-edge current (A) with chain torque M(I) = ``torque`` (N*m), at rest.

        Negative torques (the jaw friction or spring holding more than the grip needs)
        give the negative current of the linear part.
        """
        if self.affine:
            return self._affine_current(torque, wrist_angle)
        return self._solve_current(torque, wrist_angle, 0.0)

    def _affine_current(self, torque: float, wrist_angle: float) -> float:
        """Return the current (A) giving chain torque ``torque`` (N*m) on an affine chain, at rest."""
        lam = self._efficiency_scalar(0.0, wrist_angle)
        per_amp = self.tension_per_amp * self._rn * (lam - self.resistance_fraction)
        if per_amp <= 0.0:
            raise ModelError(self._no_grip_message(lam))
        return torque / per_amp

    def _solve_current(self, torque: float, wrist_angle: float, inertial: float) -> float:
        """Solve for the current with M(I) + inertial = torque, tension-dependent friction (brentq)."""
        need = torque - inertial
        if need <= 0.0:
            return need / self._slope_at_zero(wrist_angle)
        slope0 = self._slope_at_zero(wrist_angle)
        guess = need / slope0                         # friction only grows: M(I) <= slope0 I
        newton = self._newton_current(need, wrist_angle, guess)
        if newton is not None:
            return newton
        low, high, before = 0.0, guess, 0.0
        for _ in range(200):
            value = self._torque_scalar(high, wrist_angle)
            if value >= need:
                break
            before, low, previous = low, high, value
            high *= 1.5
            if self._torque_scalar(high, wrist_angle) <= previous:
                # the 1.5x step passed the peak of M: it lies in (before, high); the torque
                # is reachable if the peak reaches it (then on the rising side, [0, peak])
                peak = minimize_scalar(lambda i: -self._torque_scalar(i, wrist_angle), bounds=(before, high),
                                       method='bounded', options={'xatol': 1e-13 * high})
                if -peak.fun < need:
                    raise ModelError(f'drive torque {need:.4g} N*m is beyond the largest this instrument '
                                     f'reaches with tension-dependent friction ({-peak.fun:.4g} N*m)')
                low, high = 0.0, float(peak.x)
                break
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
