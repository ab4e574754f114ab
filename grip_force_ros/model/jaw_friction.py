"""Friction, spring and load-dependent loss at the jaw: the transmission terms of a real instrument.

The pulley chain (``friction.py``, ``transmission.py``, the stick band of ``hysteresis.py``)
gives the drive torque ``M`` the cable puts on the jaw pulley (N*m, the *chain torque*).
A real da Vinci instrument loses more on the way to the object (docs/real_data.md): a
Coulomb friction larger than the loads, whose direction sticks at each reversal, a
position spring, viscous friction and a friction that grows with the load and changes
along the stroke. With ``tau`` the torque the jaw holds (N*m, closing positive)::

    M = tau + s * (C(phi) + q * tau**2) + K(phi) + d * w                     (jaw torque balance)
    C(phi) = max(C0 + C1 * (phi - phi_r), 0)                                  friction along the stroke
    K(phi) = K0 + k1 * (phi - phi_r) + k2 * (phi - phi_r)**2                  position spring
    s' = sign(dx) + (s - sign(dx)) * exp(-|dx| / width)                       Dahl friction state

with ``phi`` the jaw angle (rad, positive open), ``w = -jaw_velocity`` the jaw's closing
rate (rad/s), ``x`` the drive angle (the drum angle ``motor_angle``, rad, positive
closing) and ``s`` in [-1, 1] the friction state: +1 while the drive slides closing (the
friction takes torque from the grip), -1 while it slides opening (the friction holds the
grip), in between during a reversal, while the jaw sticks and the current does not show
the load. ``C0, C1, width, K0, k1, k2, phi_r, d, q`` are the instrument parameters
``jaw_coulomb_friction`` (N*m), ``jaw_coulomb_friction_slope`` (N*m/rad),
``jaw_friction_width`` (rad), ``jaw_spring_torque`` (N*m), ``jaw_spring_slope`` (N*m/rad),
``jaw_spring_curvature`` (N*m/rad^2), ``jaw_spring_rest_angle`` (rad),
``jaw_viscous_friction`` (N*m*s/rad) and ``jaw_efficiency_load_gain`` (1/(N*m)).
The direction-dependent efficiency is the pulley chain's own (``pulley_friction_coefficient``
through the stick band: lambda on the loading edge, 1/lambda on the unloading one);
``q`` makes it fall with the load.

All zero (the default) is the paper's instrument: :attr:`JawFriction.active` is False and
the users skip this module entirely, so their results are those of the chain alone, bit
for bit.

Forward (chain torque -> held torque) solves the balance for ``tau`` on the root continuous
with the linear one (:func:`solve_branch`); inverse (held torque -> chain torque) is the
balance itself. Scalar methods take plain floats (the 1 kHz loop), the ``*_array``
functions numpy arrays; both evaluate the same expressions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from grip_force_ros.model.contact import ModelError

__all__ = ['JawFriction', 'FrictionState', 'dahl_step', 'dahl_direction', 'solve_branch',
           'two_branch_gain_efficiency', 'SLIDING_THRESHOLD']

#: |s| at and above which the friction direction counts as known (the jaw slides).
SLIDING_THRESHOLD = 0.9


def dahl_step(state: float, displacement: float, width: float) -> float:
    """Move the friction state ``state`` by one drive displacement (Dahl model), plain floats.

    Parameters
    ----------
    state : float
        Friction state s in [-1, 1] before the step.
    displacement : float
        Drive angle change dx (rad), positive closing; 0 leaves the state (it sticks).
    width : float
        Drive angle (rad) over which the friction reverses (e-folding), > 0.

    Returns
    -------
    float
        ``sign(dx) + (s - sign(dx)) * exp(-|dx| / width)``.
    """
    if displacement == 0.0:
        return state
    target = 1.0 if displacement > 0.0 else -1.0
    return target + (state - target) * math.exp(-abs(displacement) / width)


def dahl_direction(angle: np.ndarray, width: float, start: float = 0.0) -> np.ndarray:
    """Friction direction state s in [-1, 1] driven by displacement (Dahl model), a whole record.

    Each displacement dx moves s towards sign(dx) by the fraction
    1 - exp(-|dx|/width): no motion, no change (the state sticks).

    Parameters
    ----------
    angle : ndarray
        Drive angle (rad), positive closing.
    width : float
        Angle (rad) over which the friction reverses (e-folding), > 0.
    start : float
        Initial state.

    Returns
    -------
    ndarray
        The state after each sample (the first sample has no displacement: ``start``).

    Raises
    ------
    ModelError
        If ``width`` is not positive.
    """
    if width <= 0:
        raise ModelError(f'hysteresis width must be > 0 rad, got {width!r}')
    dx = np.diff(angle, prepend=angle[0])
    decay = np.exp(-np.abs(dx) / width)
    target = np.sign(dx)
    out = np.empty(angle.size)
    s = float(start)
    for i, (d, g, tgt) in enumerate(zip(dx.tolist(), decay.tolist(), target.tolist())):
        if d != 0.0:
            s = tgt + (s - tgt) * g
        out[i] = s
    return out


def solve_branch(value, a, quad, beta):
    """Solve ``value = a*tau + quad*tau**2 + beta`` for tau on the branch continuous with the linear root.

    Parameters
    ----------
    value, beta : ndarray or float
        The left side and the part free of tau (same unit U, e.g. A or N*m).
    a : ndarray or float
        Linear coefficient (U/(N*m)), > 0 for a physical transmission.
    quad : ndarray or float
        Quadratic coefficient (U/(N*m)^2); 0 gives tau = (value - beta)/a.

    Returns
    -------
    (ndarray, ndarray)
        tau = 2y/(a + sqrt(a^2 + 4 quad y)) (y = value - beta; where the square root would
        be negative, the turning point -a/(2 quad)), and |d value/d tau| there (U/(N*m)).
    """
    y = value - beta
    a = np.where(np.abs(a) < 1e-6, 1e-6, a)
    if np.all(np.asarray(quad) == 0.0):
        return y / a, np.abs(a)
    a = np.maximum(a, 1e-6)
    root = np.sqrt(np.maximum(a * a + 4.0 * quad * y, 0.0))
    return 2.0 * y / (a + root), root


def two_branch_gain_efficiency(alpha_drive: float, alpha_back: float) -> tuple[float, float]:
    """Loss-free gain and one-way efficiency of a transmission from its two branch slopes.

    A capstan-like friction proportional to tension costs the driving direction what it
    gives the back-driven one: current per torque ``alpha_drive = 1/(G eta)`` while the
    motor drives, ``alpha_back = eta/G`` while the load back-drives it.

    Parameters
    ----------
    alpha_drive, alpha_back : float
        Branch slopes dI/dtau (A/(N*m)) while driving (closing) and back-driven (opening).

    Returns
    -------
    (float, float)
        ``G = 1/sqrt(alpha_drive alpha_back)`` (N*m/A) and ``eta = sqrt(alpha_back/alpha_drive)``
        (-); NaN, NaN unless both slopes are positive.
    """
    if alpha_drive > 0 and alpha_back > 0:
        return 1.0 / math.sqrt(alpha_drive * alpha_back), math.sqrt(alpha_back / alpha_drive)
    return float('nan'), float('nan')


@dataclass(frozen=True)
class JawFriction:
    """The jaw's friction, spring and load loss of one instrument (module docstring).

    Attributes
    ----------
    coulomb : float
        C0, Coulomb friction at the jaw at ``rest_angle`` (N*m), >= 0.
    coulomb_slope : float
        C1, change of the Coulomb friction per rad of jaw opening (N*m/rad).
    width : float
        Dahl width of the friction state over the drive angle (rad), > 0.
    spring_torque : float
        K0, spring moment at ``rest_angle`` (N*m); positive takes torque from the grip.
    spring_slope : float
        k1 (N*m/rad); negative: the spring closes the jaw as it opens (restoring).
    spring_curvature : float
        k2 (N*m/rad^2).
    rest_angle : float
        phi_r, the jaw angle (rad) about which friction and spring are expanded.
    viscous : float
        d, viscous friction on the jaw's closing rate (N*m*s/rad).
    load_gain : float
        q, friction growing with the square of the held torque (1/(N*m)), >= 0.
    """

    coulomb: float = 0.0
    coulomb_slope: float = 0.0
    width: float = 0.02
    spring_torque: float = 0.0
    spring_slope: float = 0.0
    spring_curvature: float = 0.0
    rest_angle: float = 0.0
    viscous: float = 0.0
    load_gain: float = 0.0

    def __post_init__(self):
        if not self.width > 0.0:
            raise ModelError(f'jaw_friction_width must be > 0 rad, got {self.width!r}')
        if self.coulomb < 0.0 or self.load_gain < 0.0:
            raise ModelError('jaw_coulomb_friction and jaw_efficiency_load_gain must be >= 0, '
                             f'got {self.coulomb!r} N*m, {self.load_gain!r} 1/(N*m)')

    @classmethod
    def from_params(cls, params: Any) -> 'JawFriction':
        """Build from the instrument parameters (``jaw_*`` of the schema)."""
        def get(name, default=0.0):          # parameter objects built by other means may lack them
            return float(getattr(params, name, default))
        return cls(get('jaw_coulomb_friction'), get('jaw_coulomb_friction_slope'),
                   get('jaw_friction_width', 0.02), get('jaw_spring_torque'), get('jaw_spring_slope'),
                   get('jaw_spring_curvature'), get('jaw_spring_rest_angle'),
                   get('jaw_viscous_friction'), get('jaw_efficiency_load_gain'))

    @property
    def active(self) -> bool:
        """True when any term is nonzero; False: the chain alone (the users skip this module)."""
        return (self.coulomb != 0.0 or self.coulomb_slope != 0.0 or self.spring_torque != 0.0
                or self.spring_slope != 0.0 or self.spring_curvature != 0.0 or self.viscous != 0.0
                or self.load_gain != 0.0)

    # ---------------------------------------------------------------- scalar (plain floats)
    def coulomb_at(self, jaw_angle: float) -> float:
        """Coulomb friction C(phi) (N*m) at the jaw angle (rad), >= 0."""
        c = self.coulomb + self.coulomb_slope * (jaw_angle - self.rest_angle)
        return c if c > 0.0 else 0.0

    def spring_at(self, jaw_angle: float) -> float:
        """Spring moment K(phi) (N*m) at the jaw angle (rad); positive takes torque from the grip."""
        d = jaw_angle - self.rest_angle
        return self.spring_torque + (self.spring_slope + self.spring_curvature * d) * d

    def chain_torque(self, jaw_torque: float, jaw_angle: float, direction: float,
                     jaw_velocity: float = 0.0) -> float:
        """Inverse: the chain torque M (N*m) that holds ``jaw_torque`` (N*m) in friction state ``direction``.

        Parameters
        ----------
        jaw_torque : float
            Torque the jaw holds tau (N*m), closing positive.
        jaw_angle : float
            Jaw angle phi (rad), positive open.
        direction : float
            Friction state s in [-1, 1] (+1 sliding closing).
        jaw_velocity : float
            Jaw opening rate (rad/s); the viscous term acts on its negative.
        """
        friction = self.coulomb_at(jaw_angle) + self.load_gain * jaw_torque * jaw_torque
        return (jaw_torque + direction * friction + self.spring_at(jaw_angle)
                - self.viscous * jaw_velocity)

    def jaw_torque(self, chain_torque: float, jaw_angle: float, direction: float,
                   jaw_velocity: float = 0.0) -> float:
        """Forward: the torque (N*m) the jaw holds for a chain torque ``chain_torque`` (N*m).

        The root of :meth:`chain_torque` continuous with the linear one (:func:`solve_branch`);
        arguments as there.
        """
        y = chain_torque - (direction * self.coulomb_at(jaw_angle) + self.spring_at(jaw_angle)
                            - self.viscous * jaw_velocity)
        quad = direction * self.load_gain
        if quad == 0.0:
            return y
        return 2.0 * y / (1.0 + math.sqrt(max(1.0 + 4.0 * quad * y, 0.0)))

    # ---------------------------------------------------------------- arrays
    def chain_torque_array(self, jaw_torque, jaw_angle, direction, jaw_velocity=0.0) -> np.ndarray:
        """:meth:`chain_torque` over numpy arrays (broadcast), N*m."""
        tau = np.asarray(jaw_torque, dtype=np.float64)
        d = np.asarray(jaw_angle, dtype=np.float64) - self.rest_angle
        s = np.asarray(direction, dtype=np.float64)
        c = np.maximum(self.coulomb + self.coulomb_slope * d, 0.0)
        k = self.spring_torque + (self.spring_slope + self.spring_curvature * d) * d
        return tau + s * (c + self.load_gain * tau * tau) + k - self.viscous * np.asarray(jaw_velocity, float)

    def jaw_torque_array(self, chain_torque, jaw_angle, direction, jaw_velocity=0.0) -> np.ndarray:
        """:meth:`jaw_torque` over numpy arrays (broadcast), N*m."""
        d = np.asarray(jaw_angle, dtype=np.float64) - self.rest_angle
        s = np.asarray(direction, dtype=np.float64)
        c = np.maximum(self.coulomb + self.coulomb_slope * d, 0.0)
        k = self.spring_torque + (self.spring_slope + self.spring_curvature * d) * d
        beta = s * c + k - self.viscous * np.asarray(jaw_velocity, float)
        tau, _ = solve_branch(np.asarray(chain_torque, dtype=np.float64), 1.0, s * self.load_gain, beta)
        return tau


class FrictionState:
    """The jaw friction's direction state, stepped with the drive angle (Dahl model).

    >>> st = FrictionState(0.02)
    >>> st.step(0.0); st.step(0.1)            # drum angle (rad): closing by 0.1 rad
    0.0
    0.9932620530009145
    >>> st.sliding
    True

    Parameters
    ----------
    width : float
        Dahl width over the drive angle (rad), > 0 (``jaw_friction_width``).
    start : float
        Initial state s in [-1, 1]; 0 = unknown.
    """

    __slots__ = ('width', 'direction', 'angle', 'slid')

    def __init__(self, width: float, start: float = 0.0):
        if not width > 0.0:
            raise ModelError(f'friction state width must be > 0 rad, got {width!r}')
        self.width = float(width)
        self.direction = float(start)
        self.angle = math.nan          # rad, last drive angle (NaN: none yet)
        self.slid = False              # the drive has slid since the reset

    def reset(self, start: float = 0.0) -> None:
        """Forget the history: state ``start``, no drive angle yet."""
        self.direction = float(start)
        self.angle = math.nan
        self.slid = False

    def step(self, drive_angle: float) -> float:
        """Take the drive angle (rad, positive closing) now; return the state s in [-1, 1]."""
        previous = self.angle
        self.angle = drive_angle
        if previous == previous:       # not NaN
            self.direction = dahl_step(self.direction, drive_angle - previous, self.width)
        if self.sliding:
            self.slid = True
        return self.direction

    @property
    def sliding(self) -> bool:
        """True when |s| >= :data:`SLIDING_THRESHOLD`: the friction direction is known."""
        return abs(self.direction) >= SLIDING_THRESHOLD
