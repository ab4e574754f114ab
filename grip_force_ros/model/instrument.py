"""GripForceModel: forward and inverse grip-force model of one instrument.

Forward: (current, wrist angle, jaw angle, velocities, object) -> grip force, needle
pull-out force, jaw drive torque, chain efficiency, drum tension. Inverse: target grip
force -> current. See docs/model.md for the equations and the readings of the paper.

One model, three ways of computing it, one module each (mixed into the class, sharing
the constants set in ``__init__``):

- ``scalar_path.py`` (:class:`ScalarPath`): one sample, plain floats, for the 1 kHz
  control loop (``grip_force_scalar``, ``current_for_force_scalar``);
- ``array_path.py`` (:class:`ArrayPath`): the exact calculation over numpy arrays;
- ``fitted_path.py`` (:class:`FittedPath`): fitted tables that replace the exact chain
  and inverse where the chain is nonlinear but wrist-independent.

This module holds the public vectorised API (``forward``, ``inverse``, ``jaw_angle``,
``motor_angle``), which picks the path per call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from grip_force_ros.model import angle as _angle
from grip_force_ros.model import contact as _contact
from grip_force_ros.model import friction as _friction
from grip_force_ros.model import transmission as _tx
from grip_force_ros.model.array_path import ArrayPath
from grip_force_ros.model.contact import OBJECTS, ModelError, check_object
from grip_force_ros.model.fitted_path import FittedPath
from grip_force_ros.model.jaw_friction import JawFriction
from grip_force_ros.model.scalar_path import ScalarPath
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
    """Return the broadcast shape of ``arrays``.

    The usual cases (one shape, or one shape and scalars) without
    ``numpy.broadcast_shapes`` (~2 us a call, a share of a 10 000-sample forward).
    """
    shapes = {a.shape for a in arrays}
    if len(shapes) > 1:
        shapes.discard(())
    if len(shapes) == 1:
        return shapes.pop()
    return np.broadcast_shapes(*(a.shape for a in arrays))


def _moving(motor_velocity, jaw_velocity, motor_array: np.ndarray, jaw_array: np.ndarray) -> bool:
    """Tell whether any velocity (rad/s) is nonzero (or NaN); float defaults need no array."""
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


class GripForceModel(ScalarPath, ArrayPath, FittedPath):
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
        self._rn = p.drive_pulley_radius
        self._tip, self._inner = p.jaw_moment_arm_tip, p.jaw_moment_arm_inner
        self._pull_per_grip = _contact.PULL_OUT_PER_MU * p.needle_friction_coefficient
        #: friction, spring and load loss at the jaw (jaw_friction.py); none for the ideal instrument
        self.jaw_friction = JawFriction.from_params(p) if losses else JawFriction()
        self._init_scalar_path(p.cable_radius)    # scalar_path.py: the control-loop fast path
        self._init_array_path()                   # array_path.py: vectorised constants
        self._init_fitted_path()                  # fitted_path.py: the tables, where they apply

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
                jaw_velocity=0.0, direction=None) -> ForwardResult:
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
            Drum rate (rad/s, positive closing) and jaw opening rate (rad/s); the (tiny)
            inertial term of M' uses them, the jaw's viscous friction the jaw rate.
        direction : float or array, optional
            Friction state s in [-1, 1] of the jaw friction (``jaw_friction.py``: +1 sliding
            closing, -1 opening). None, or an instrument without jaw friction terms: the
            chain alone (the paper's model). With it, ``jaw_torque`` is the torque the
            jaw holds and the grip force follows it.

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
        if direction is not None and self.jaw_friction.active:
            torque[...] = self.jaw_friction.jaw_torque_array(torque, jaw, direction, jv)
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
                jaw_velocity=0.0, direction=None):
        """Return the current (A) that gives ``grip_force`` (N) (arrays broadcast).

        A zero force returns the current at which the jaw just starts to squeeze.
        ``direction``: the friction state s in [-1, 1] of the jaw friction, as in
        :meth:`forward` (None: the chain alone); the current is on that branch.

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
        friction = direction is not None and self.jaw_friction.active
        if isinstance(gain, float):
            if gain <= 0.0 and high > 0.0:
                raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                                 'at these jaw angles')
            if self._one_dimensional and shape != () and gain > 0.0 and not moving and not friction:
                self._torque_per_amp_at_zero_tension(wrist)   # ModelError if no current grips
                return self._current_for_force_from_fit(force, gain, high)
            torque = force / gain if gain > 0.0 else np.zeros(shape)          # M needed (N*m)
        else:
            if np.any((gain <= 0.0) & (force > 0.0)):
                raise ModelError(f'no contact: a positive grip force cannot be produced with obj={obj!r} '
                                 'at these jaw angles')
            with np.errstate(divide='ignore', invalid='ignore'):
                torque = np.where(force > 0.0, force / gain, 0.0)
        if friction:                                          # the chain torque that holds it
            torque = self.jaw_friction.chain_torque_array(torque, jaw, direction, jv)
        if moving:
            torque -= _tx.inertial_moment(-jv, mv, self._rn, self.params.jaw_mass, self.params.drum_mass)
        per_amp = self._torque_per_amp_at_zero_tension(wrist)   # dM/dI at I = 0 (N*m/A)
        if self.affine:
            torque /= per_amp                                      # in place: one fresh array per call
            return torque                                          # current (A)
        if self._one_dimensional and shape != ():
            return self._current_from_fit(torque, per_amp)
        return self._solve_current_array(torque, wrist, per_amp)

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
