"""The vectorised path of the grip-force model: many samples at once, numpy arrays.

The exact chain efficiency lambda_n over arrays of drum tension (N) and wrist angle
(rad), with the constant-friction parts computed once and one scratch block reused for
every pulley; the contact gain (1/m); and the nonlinear inverse over arrays (Newton on
the samples not yet converged, the rare rest handed to the scalar solve). With tension-
dependent friction and no wrist effect the fitted tables replace the last two
(:mod:`grip_force_ros.model.fitted_path`); they are checked against these.

:class:`ArrayPath` is a part of :class:`~grip_force_ros.model.GripForceModel` (a mixin:
it shares the model's constants), not a model on its own.
"""
from __future__ import annotations

import numpy as np

from grip_force_ros.model import contact as _contact
from grip_force_ros.model.contact import ModelError

__all__ = ['ArrayPath']


class ArrayPath:
    """Vectorised helpers of :class:`~grip_force_ros.model.GripForceModel`.

    Reads the model's constants (``tension_per_amp`` (N/A), ``mu``, ``friction_gain``
    (1/N), ``resistance_fraction``, ``wraps`` (rad), ``wrist_wrap_gain``, ``affine``,
    ``_rn``, ``_tip``, ``_inner`` (m)) and the scalar path's (``_exps``,
    ``_fixed_efficiency``, ``_rho``); its own come from :meth:`_init_array_path`.
    """

    def _init_array_path(self) -> None:
        """Constants of the vectorised path (docs/model.md, speed).

        With constant friction only the last guide pulley's wrap depends on the wrist,
        and only when wrist_wrap_gain != 0; everything else is one number per instrument.
        """
        self._wrist_matters = self.wrist_wrap_gain != 0.0 and self.mu > 0.0
        self._efficiency_at_rest = self._efficiency_scalar(0.0, 0.0)    # lambda_n at zero wrist (-)
        self._torque_per_amp_at_rest = self.tension_per_amp * self._rn * (
            self._efficiency_at_rest - self.resistance_fraction)           # dM/dI at zero wrist (N*m/A)
        self._start_table = None if self.affine else self._current_table()   # see _starting_currents

    def _contact_gain(self, obj: str, jaw):
        """Grip force per unit drive torque (1/m): a float where it does not depend on the jaw."""
        if obj in ('needle', 'free'):
            return _contact.contact_gain_scalar(obj, 0.0, self._tip, self._inner)
        return _contact.contact_gain(obj, jaw, self._tip, self._inner)

    def _efficiency_at_zero_tension(self, wrist):
        """Constant-friction lambda_n (-): a float unless the wrist matters (then an array).

        Only the last guide pulley depends on the wrist; its wrap grows by
        ``wrist_wrap_gain |wrist|``. The others are ``self._fixed_efficiency``.
        """
        if not self._wrist_matters:
            return self._efficiency_at_rest
        if wrist.ndim == 0:
            return self._efficiency_scalar(0.0, float(wrist))
        a, b = self._exps[-1]
        weight = a / (a - b)
        wrap = np.abs(wrist)
        wrap *= self.wrist_wrap_gain
        wrap += self.wraps[-1]                                     # theta_n (rad)
        eta = np.exp(b * wrap)
        eta *= weight
        rising = np.exp(np.multiply(wrap, a, out=wrap), out=wrap)
        rising *= 1.0 - weight
        eta += rising                             # eta_n = w e^(b theta) + (1 - w) e^(a theta)
        return np.divide(self._fixed_efficiency, eta, out=eta)     # lambda_n = fixed / eta_n

    def _chain_efficiency(self, drum_tension, wrist):
        """lambda_n (-) at drum tension F0 (N) and wrist (rad): float, or array broadcasting with both.

        Same as :func:`friction.chain_efficiency` (the reference the tests hold it to),
        with the constant-friction parts computed once.
        """
        at_zero = self._efficiency_at_zero_tension(wrist)
        if self.affine or self.mu == 0.0:                          # no tension dependence
            return at_zero
        if drum_tension.ndim == 0 and wrist.ndim == 0:
            return self._efficiency_scalar(float(drum_tension), float(wrist))
        loaded = drum_tension > 0.0
        start = np.where(loaded, drum_tension, 1.0)                # probe tension where F0 <= 0 (N)
        last_wrap = self.wraps[-1] + self.wrist_wrap_gain * np.abs(wrist)
        mu, gain = self.mu, self.friction_gain
        tension = start.copy()
        # scratch arrays, one block reused for every pulley (fresh arrays cost page faults)
        scratch = np.empty((5,) + tension.shape)
        mu_here, root, a, b, weight = (scratch[i, ...] for i in range(5))
        for i, rho in enumerate(self._rho):
            wrap = last_wrap if i == len(self._rho) - 1 else self.wraps[i]
            np.multiply(tension, mu * gain, out=mu_here)
            mu_here += mu                                           # mu (1 + g F) (-)
            np.square(mu_here, out=root)
            root *= 4.0 * rho
            root += (1.0 + rho) ** 2
            np.sqrt(root, out=root)
            root += 1.0 + rho                                       # (1 + rho) + sqrt(...)
            np.multiply(mu_here, 2.0 * rho, out=a)
            a /= root                                               # a, cancellation-free (1/rad)
            np.divide(root, mu_here, out=b)
            b *= -0.5                                               # b = -((1 + rho) + sqrt)/(2 mu)
            np.subtract(a, b, out=weight)
            np.divide(a, weight, out=weight)                        # w = a / (a - b)
            a *= wrap
            b *= wrap
            eta = np.exp(a, out=a)
            eta *= np.subtract(1.0, weight, out=mu_here)            # (1 - w) e^(a theta)
            # eta_i = w e^(b theta) + (1 - w) e^(a theta); b theta is ~ -100 on real pulleys, and
            # below -40 the first term (< 4e-18 w) is under the last bit of eta (>= 1 - w ~ 1)
            if b.size and b.max() > -40.0:
                np.exp(b, out=b)
                b *= weight
                eta += b
            tension /= eta                                          # F_i = F_(i-1) / eta_i (N)
        tension /= start                                            # lambda_n (-)
        if not loaded.all():
            np.copyto(tension, at_zero, where=~loaded)
        return tension

    def _torque_per_amp_at_zero_tension(self, wrist):
        """dM/dI at zero current (N*m/A), float or array; ModelError if it is not positive."""
        if not self._wrist_matters:
            if self._torque_per_amp_at_rest <= 0.0:
                raise ModelError(self._no_grip_message(self._efficiency_at_rest))
            return self._torque_per_amp_at_rest
        lam = self._efficiency_at_zero_tension(wrist)
        per_amp = self.tension_per_amp * self._rn * (lam - self.resistance_fraction)
        if np.min(per_amp) <= 0.0:
            raise ModelError(self._no_grip_message(float(np.min(lam))))
        return per_amp

    def _torque_array(self, current, wrist):
        """Drive torque M (N*m) at zero velocities, arrays (the nonlinear inverse's function)."""
        drum_tension = self.tension_per_amp * current
        lam = self._chain_efficiency(drum_tension, wrist)
        return self._rn * drum_tension * (lam - self.resistance_fraction)

    def _current_table(self, nodes: int = 129):
        """(linear currents, currents) (A, A): M(I) / (dM/dI at 0) against I at zero wrist.

        Over [0, 2 max_current], cut where M stops rising; ``nodes`` scalar evaluations
        (~0.5 ms, at construction). None when M does not rise at all.
        """
        if self._torque_per_amp_at_rest <= 0.0:
            return None
        currents = np.linspace(0.0, 2.0 * max(self.params.max_current, 1e-3), nodes)       # A
        torques = np.array([self._torque_scalar(float(i), 0.0) for i in currents])         # N*m
        falling = np.flatnonzero(np.diff(torques) <= 0.0)
        end = falling[0] + 1 if falling.size else nodes
        return torques[:end] / self._torque_per_amp_at_rest, currents[:end]

    def _starting_currents(self, linear_current):
        """Return Newton's starting currents (A) from ``torque / per_amp`` (A).

        ``torque / per_amp`` is the current without tension-dependent friction.
        The table of :meth:`_current_table` maps one to the other by linear
        interpolation: exact at the nodes, ~1e-4 relative between them. With the wrist
        mattering it is only a good guess; past the table it is clamped (Newton then
        climbs, M being concave).
        """
        return np.interp(linear_current, *self._start_table)

    def _solve_current_array(self, torque, wrist, per_amp):
        """Currents with M(I) = torque (N*m), tension-dependent friction, all samples at once.

        Newton with a forward-difference slope, as :meth:`_newton_current`, on the
        samples not yet converged. It starts from :meth:`_starting_currents` (within
        ~1e-4 where the wrist does not matter) and accepts a sample
        once its step is below 1e-7 of the current: the slope is exact to ~1e-8, so
        the error after that step is ~1e-15. Samples where Newton gives up (past the
        peak of M, or no convergence in 30 steps) go to the per-sample
        :meth:`_solve_current` (bracket + brentq), which also raises for unreachable
        torques. A torque <= 0 is linear: ``torque / per_amp``.
        """
        torque = np.asarray(torque, float)
        wrist = np.broadcast_to(wrist, torque.shape)
        current = np.array(np.broadcast_to(torque / per_amp, torque.shape), float).ravel()
        todo = np.flatnonzero(torque.ravel() > 0.0)           # torque <= 0: current is exact
        need, w = torque.ravel()[todo], wrist.ravel()[todo]
        guess = self._starting_currents(current[todo])
        for _ in range(30):
            if todo.size == 0:
                break
            value = self._torque_array(guess, w) - need
            step_size = 1e-7 * guess
            with np.errstate(divide='ignore', invalid='ignore'):     # 0/0 fails the slope test below
                slope = (self._torque_array(guess + step_size, w) - need - value) / step_size
                step = -value / slope
            new = guess + step
            failed = ~(slope > 0.0) | ~(new > 0.0)
            done = ~failed & (np.abs(step) <= 1e-7 * new)
            current[todo[done]] = new[done]
            for k in np.flatnonzero(failed):                      # rare: the bracketed scalar solve
                current[todo[k]] = self._solve_current(float(need[k]), float(w[k]), 0.0)
            keep = ~(done | failed)
            todo, need, w, guess = todo[keep], need[keep], w[keep], new[keep]
        for k in range(todo.size):                                # not converged in 30 steps
            current[todo[k]] = self._solve_current(float(need[k]), float(w[k]), 0.0)
        return current.reshape(torque.shape)
