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
from scipy.optimize import brentq, minimize_scalar

from grip_force_ros.model import angle as _angle
from grip_force_ros.model import contact as _contact
from grip_force_ros.model import friction as _friction
from grip_force_ros.model import tables as _tables
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


def _broadcast_shape(*arrays: np.ndarray) -> tuple:
    """Broadcast shape of ``arrays``; the usual cases (one shape, or one shape and
    scalars) without ``numpy.broadcast_shapes`` (~2 us a call, a share of a 10 000-sample forward)."""
    shapes = {a.shape for a in arrays}
    if len(shapes) > 1:
        shapes.discard(())
    if len(shapes) == 1:
        return shapes.pop()
    return np.broadcast_shapes(*(a.shape for a in arrays))


def _moving(motor_velocity, jaw_velocity, motor_array: np.ndarray, jaw_array: np.ndarray) -> bool:
    """True if any velocity (rad/s) is nonzero (or NaN); the float defaults without an array pass."""
    if type(motor_velocity) is float and type(jaw_velocity) is float:
        return motor_velocity != 0.0 or jaw_velocity != 0.0
    return bool(motor_array.any() or jaw_array.any())


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

    #: Capability: this model describes the pulleys' stick band, so
    #: :class:`~grip_force_ros.model.hysteresis.HystereticGripForce` can follow it and the
    #: controller uses the direction-aware estimate and feedforward. A model object without
    #: it (or False) is used as the loading branch only.
    supports_stick_band = True

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
        # vectorised fast-path constants (docs/model.md, speed): with constant friction
        # only the last guide pulley's wrap depends on the wrist, and only when
        # wrist_wrap_gain != 0; everything else is one number per instrument.
        self._wrist_matters = self.wrist_wrap_gain != 0.0 and self.mu > 0.0
        self._efficiency_at_rest = self._efficiency_scalar(0.0, 0.0)    # lambda_n at zero wrist (-)
        self._torque_per_amp_at_rest = self.tension_per_amp * self._rn * (
            self._efficiency_at_rest - self.resistance_fraction)           # dM/dI at zero wrist (N*m/A)
        self._start_table = None if self.affine else self._current_table()   # see _starting_currents
        # nonlinear but wrist-independent: lambda_n(F0) and I(M) are 1-D maps, fitted
        # (docs/model.md, speed; grip_force_ros.model.tables): I(M) now, lambda_n(F0) on
        # the first vectorised forward
        self._one_dimensional = not self.affine and self.mu > 0.0 and not self._wrist_matters
        self._efficiency_fit = None               # (coefficients in F0, top F0 (N)), built lazily
        self._current_fit = None                  # PiecewisePolynomial of I(M) per position, see below
        self._current_rows = None                 # its coefficients per interval, Python floats
        self._rising = None                       # see _rising_current
        if self._one_dimensional:                 # built now: the scalar inverse of the control step uses it
            self._current_fit_built()

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
        current, wrist, jaw, mv, jv = (np.asarray(x, float) for x in (
            current, wrist_angle, jaw_angle, motor_velocity, jaw_velocity))
        shape = _broadcast_shape(current, wrist, jaw, mv, jv)
        if current.shape != shape:
            current = np.broadcast_to(current, shape)
        # The five outputs share one fresh block: one large allocation the allocator
        # reuses from call to call, where five separate ones cost a page fault per
        # 4 kB on every call (most of the time of a large forward; docs/model.md, speed).
        block = np.empty((5,) + shape)
        grip, pull, torque, efficiency, drum_tension = (block[i, ...] for i in range(5))  # arrays, even 0-d
        np.multiply(self.tension_per_amp, current, out=drum_tension)            # F0 (N)
        if self._one_dimensional and shape != ():
            self._efficiency_from_fit(drum_tension, out=efficiency)           # lambda_n (-)
        else:
            efficiency[...] = self._chain_efficiency(drum_tension, wrist)     # lambda_n (-)
        if self.affine and not self._wrist_matters:           # lam is the constant _efficiency_at_rest
            np.multiply(self._torque_per_amp_at_rest, current, out=torque)
        else:
            np.subtract(efficiency, self.resistance_fraction, out=torque)
            torque *= drum_tension
            torque *= self._rn                                # M = r_n F0 (lambda_n - fraction) (N*m)
        if _moving(motor_velocity, jaw_velocity, mv, jv):
            torque += _tx.inertial_moment(-jv, mv, self._rn, self.params.jaw_mass, self.params.drum_mass)
        np.clip(torque, 0.0, np.inf, out=grip)                # max(M, 0), NaN stays NaN
        grip *= self._contact_gain(obj, jaw)                  # F_J (N)
        if obj == 'needle':
            np.multiply(grip, self._pull_per_grip, out=pull)  # F_L (N)
        else:
            pull.fill(0.0 if obj == 'free' else np.nan)
        if shape == ():   # scalar inputs: the same types as ever (numpy scalars, 0-d arrays)
            return ForwardResult(grip[()], pull[()] if obj == 'needle' else pull, torque[()], efficiency,
                                 drum_tension[()])
        return ForwardResult(grip, pull, torque, efficiency, drum_tension)

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
        force, wrist, jaw, mv, jv = (np.asarray(x, float) for x in (
            grip_force, wrist_angle, jaw_angle, motor_velocity, jaw_velocity))
        shape = _broadcast_shape(force, wrist, jaw, mv, jv)
        if force.shape != shape:
            force = np.broadcast_to(force, shape)
        low, high = (force.min(), force.max()) if force.size else (0.0, 0.0)    # N
        if not (low >= 0.0 and high < math.inf):                              # NaN fails both
            raise ModelError(f'grip force must be finite and >= 0 N, got {force[~(force >= 0.0)][:3]!r}')
        gain = self._contact_gain(obj, jaw)                   # F_J / max(M, 0) (1/m)
        moving = _moving(motor_velocity, jaw_velocity, mv, jv)
        if isinstance(gain, float):
            if gain <= 0.0 and high > 0.0:
                raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                                 'at these jaw angles')
            if self._one_dimensional and shape != () and gain > 0.0 and not moving:
                self._torque_per_amp_at_zero_tension(wrist)   # ModelError if no current grips
                return self._current_for_force_from_fit(force, gain, high)
            torque = force / gain if gain > 0.0 else np.zeros(shape)          # M needed (N*m)
        else:
            if np.any((gain <= 0.0) & (force > 0.0)):
                raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                                 'at these jaw angles')
            with np.errstate(divide='ignore', invalid='ignore'):
                torque = np.where(force > 0.0, force / gain, 0.0)
        if moving:
            torque -= _tx.inertial_moment(-jv, mv, self._rn, self.params.jaw_mass, self.params.drum_mass)
        per_amp = self._torque_per_amp_at_zero_tension(wrist)   # dM/dI at I = 0 (N*m/A)
        if self.affine:
            torque /= per_amp                                      # in place: one fresh array per call
            return torque                                          # current (A)
        if self._one_dimensional and shape != ():
            return self._current_from_fit(torque, per_amp)
        return self._solve_current_array(torque, wrist, per_amp)

    # ------------------------------------------------------------------ vectorised helpers
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

    # Tolerances of the fitted maps (relative, checked when they are built): the exact
    # chain itself rounds at ~1e-15, the Newton solve it replaces stops at ~1e-15.
    EFFICIENCY_FIT_TOLERANCE = 1e-14
    CURRENT_FIT_TOLERANCE = 5e-14
    CURRENT_FIT_INTERVALS, CURRENT_FIT_DEGREE = 2048, 3     # cubics: the gather costs a pass per row

    def _rising_current(self) -> float:
        """A current (A) safely below the peak of M(I) at zero wrist (or 2 max_current).

        Two nodes short of the last rising node of a 2049-node grid over [0, 2 max_current],
        refined on a second grid up to the first falling node when the peak comes early
        (vectorised exact torque, ~0.3 ms). 0 when M does not rise.
        """
        if self._rising is not None:
            return self._rising
        high = 2.0 * max(self.params.max_current, 1e-3)                     # A
        zero = np.zeros(())
        for _ in range(2):
            grid = np.linspace(0.0, high, 2049)                                # A
            with np.errstate(all='ignore'):
                falling = np.flatnonzero(~(np.diff(self._torque_array(grid, zero)) > 0.0))
            if falling.size == 0:
                self._rising = high
                return high
            if falling[0] >= 256:
                break
            high = grid[falling[0] + 1]                                        # the peak is before this
        self._rising = float(grid[max(falling[0] - 2, 0)])
        return self._rising

    def _efficiency_fit_built(self):
        """(coefficients in F0 (increasing powers, N^-k), top F0 (N)) of lambda_n(F0); None if no fit.

        Over F0 at [0, 2 max_current], or if no polynomial of degree <= 16 fits there
        (steep tension gains), over [0, 2 I_rising] and [0, I_rising] (:meth:`_rising_current`).
        """
        if self._efficiency_fit is None:
            zero = np.zeros(())

            def exact(f0):
                return self._chain_efficiency(np.asarray(f0, float), zero)
            full = 2.0 * max(self.params.max_current, 1e-3)                    # A
            rising = self._rising_current()
            self._efficiency_fit = (False,)
            for current in sorted({full, min(full, 2.0 * rising), rising}, reverse=True):
                if current <= 0.0:
                    continue
                top = self.tension_per_amp * current                            # N
                with np.errstate(all='ignore'):
                    coefficients = _tables.fit_polynomial(exact, 0.0, top, self.EFFICIENCY_FIT_TOLERANCE)
                if coefficients is not None:
                    self._efficiency_fit = (coefficients, top)
                    break
        return None if len(self._efficiency_fit) == 1 else self._efficiency_fit

    def _efficiency_from_fit(self, drum_tension, out):
        """lambda_n (-) at drum tensions F0 (N) into ``out``, wrist-independent chain.

        The fitted polynomial on (0, top]; the constant-friction value where F0 <= 0 (or
        NaN), the exact chain above ``top``. Equal to :meth:`_chain_efficiency` within
        :attr:`EFFICIENCY_FIT_TOLERANCE`.
        """
        fit = self._efficiency_fit_built()
        if fit is None or drum_tension.size == 0:
            out[...] = self._chain_efficiency(drum_tension, np.zeros(()))
            return out
        coefficients, top = fit
        low, high = drum_tension.min(), drum_tension.max()
        inside = low > 0.0 and high <= top
        # samples outside are replaced below; clipped, they cannot overflow on the way
        _tables.horner(coefficients, drum_tension if inside else np.clip(drum_tension, 0.0, top), out=out)
        if not low > 0.0:                                         # unloaded (or NaN): lambda at zero
            np.copyto(out, self._efficiency_at_rest, where=~(drum_tension > 0.0))
        if not high <= top:                                       # beyond the fit (or NaN)
            beyond = drum_tension > top
            out[beyond] = self._chain_efficiency(drum_tension[beyond], np.zeros(()))
        return out

    def _current_fit_built(self):
        """PiecewisePolynomial of I(M) / (M / step) (A) over [0, M(I_rising)); None if none.

        ``I_rising`` from :meth:`_rising_current`; the table may end earlier (the first
        interval that misses :attr:`CURRENT_FIT_TOLERANCE`).

        Divided by the position ``M / step`` (intervals, -), not by M: the caller has
        the position at hand and multiplies by it (``I = fit * position``).
        """
        if self._current_fit is None:
            per_amp = self._torque_per_amp_at_rest
            fit = None
            rising = self._rising_current() if per_amp > 0.0 else 0.0   # A
            if rising > 0.0:
                top = self._torque_scalar(rising, 0.0)                   # N*m, clear of the peak
                step = top / self.CURRENT_FIT_INTERVALS                  # N*m
                zero = np.zeros(())

                def exact(torque):
                    return self._solve_current_array(torque, zero, per_amp) / (torque / step)
                try:
                    with np.errstate(all='ignore'):
                        fit = _tables.fit_piecewise(exact, top, self.CURRENT_FIT_INTERVALS,
                                                    self.CURRENT_FIT_DEGREE, self.CURRENT_FIT_TOLERANCE)
                except ModelError:          # the exact solve failed somewhere: no table, exact path
                    fit = None
            self._current_fit = (False,) if fit is None else (fit,)
            if fit is not None:
                self._current_rows = fit.coefficients.T.tolist()
        return self._current_fit[0] or None

    def _current_from_fit(self, torque, per_amp):
        """Currents (A) with M(I) = torque (N*m), wrist-independent chain, all samples at once.

        From the fitted table (:meth:`_current_fit_built`); ``torque / per_amp`` where
        torque <= 0 (linear), :meth:`_solve_current_array` above the table (which
        raises for unreachable torques). Equal to the exact solve within
        :attr:`CURRENT_FIT_TOLERANCE`.
        """
        fit = self._current_fit_built()
        if fit is None or torque.size == 0:
            return self._solve_current_array(torque, np.zeros(()), per_amp)
        position = np.multiply(torque, 1.0 / fit.step)             # M / step (-)
        low, high = position.min(), position.max()
        beyond = None if high < fit.intervals else ~(position < fit.intervals)
        if not (low > 0.0 and beyond is None):                    # replaced below; clipped, no overflow
            np.clip(position, 0.0, fit.last_position, out=position)
        current = fit.at_positions(position)
        current *= position                                       # I (A)
        if not low > 0.0:                                         # linear below zero torque
            idle = ~(torque > 0.0)
            current[idle] = torque[idle] / per_amp
        if beyond is not None:                                    # beyond the table: Newton
            current[beyond] = self._solve_current_array(torque[beyond], np.zeros(()), per_amp)
        return current

    def _current_for_force_from_fit(self, force, gain, largest):
        """Currents (A) for grip forces (N) >= 0 at a constant contact gain (1/m), at rest.

        As :meth:`_current_from_fit` on ``force / gain`` without forming the torques:
        one array pass fewer. ``largest`` is ``force.max()`` (N).
        """
        fit = self._current_fit_built()
        if fit is None:
            return self._solve_current_array(force / gain, np.zeros(()), self._torque_per_amp_at_rest)
        per_position = 1.0 / (gain * fit.step)                    # positions per newton (1/N)
        position = np.multiply(force, per_position)               # M / step (-), >= 0
        beyond = None
        if not largest * per_position < fit.intervals:            # = position.max() < intervals
            beyond = ~(position < fit.intervals)
            np.minimum(position, fit.last_position, out=position)   # replaced below; clipped, no overflow
        current = fit.at_positions(position)
        current *= position                                       # I (A); 0 at zero force
        if beyond is not None:                                    # beyond the table: Newton
            current[beyond] = self._solve_current_array(force[beyond] / gain, np.zeros(()),
                                                        self._torque_per_amp_at_rest)
        return current

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
        """Newton's starting currents (A) from ``torque / per_amp`` (A), the current without
        tension-dependent friction.

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
