"""Direction-aware (hysteretic) grip force: the capstan stick band of the pulley chain.

The paper's model (:class:`~grip_force_ros.model.GripForceModel`) is the *loading*
branch: the drum pulls, the cable slips toward the jaw over every pulley and the jaw
side gets ``Tn = lambda T0`` of the drum tension ``T0``. When the current falls the
friction reverses: the cable sticks on the pulleys and the jaw side keeps its tension
until the drum side falls below ``lambda Tn`` (the jaw now pulls the cable back and
loses to friction). For any drum tension the jaw-side tension is therefore somewhere
in the stick band::

    lambda T0 <= Tn <= T0 / lambda          (T0 >= 0; mirrored for T0 < 0)

and where exactly depends on the history: ``Tn`` moves only when it is pushed out
of the band, to the nearer edge. That is a *play operator* (backlash) on the tension::

    Tn[k] = clip(Tn[k-1], lambda T0[k], T0[k] / lambda)

The grip force follows from ``Tn`` with the model's static resistance moment
``M' = f r_n Tn / lambda`` (``f`` = drive_resistance_fraction; equal to the paper's
``f r_n F0`` on the loading branch) and contact gain ``G``::

    F_J = max(r_n Tn (1 - f / lambda), 0) * G(obj, jaw angle)

On the loading edge ``Tn = lambda T0`` this is exactly the paper's
``r_n F0 (lambda - f) G``, and :class:`HystereticGripForce` returns the model's own
:meth:`~grip_force_ros.model.GripForceModel.grip_force_scalar` there (bit for bit).
Only a falling current differs: with lambda = 0.647 the drum current may drop by
``1 - lambda^2 = 58%`` before the jaw loses any force, and holding a force on the
unloading branch needs ``lambda^2`` times the loading current.

With tension-dependent friction lambda is evaluated at the present drum tension (as
the simulator does). Everything is SI (A, N, m, rad).
"""
from __future__ import annotations

import numpy as np

from grip_force_ros.model import contact as _contact
from grip_force_ros.model.contact import ModelError, check_object

__all__ = ['play_operator', 'hysteretic_grip_force', 'HystereticGripForce', 'BRANCHES']

#: Branches of :meth:`HystereticGripForce.current_for_force`.
BRANCHES = ('loading', 'unloading', 'middle')


def play_operator(drum_tension, efficiency, initial: float = 0.0) -> np.ndarray:
    """Jaw-side tension (N) of a stick-slip pulley chain driven by ``drum_tension`` (N).

    Parameters
    ----------
    drum_tension : array_like, shape (n,)
        Drum-side tension history T0 (N), in time order, signed (negative: the opening
        cable pulls).
    efficiency : float or array_like, shape (n,)
        Chain efficiency lambda (-), in (0, 1].
    initial : float
        Jaw-side tension before the first sample (N).

    Returns
    -------
    ndarray, shape (n,)
        Tn, always within ``[lambda T0, T0 / lambda]`` (ordered by sign); equal to
        ``lambda T0`` while ``|T0|`` only rises from ``initial = 0``.
    """
    t0 = np.asarray(drum_tension, float)
    lam = np.broadcast_to(np.asarray(efficiency, float), t0.shape)
    low = np.where(t0 >= 0.0, lam * t0, t0 / lam).ravel().tolist()
    high = np.where(t0 >= 0.0, t0 / lam, lam * t0).ravel().tolist()
    out = np.empty(t0.size)
    tn = float(initial)
    for k in range(t0.size):          # sequential by nature; plain floats are fastest
        if tn < low[k]:
            tn = low[k]
        elif tn > high[k]:
            tn = high[k]
        out[k] = tn
    return out.reshape(t0.shape)


def hysteretic_grip_force(model, current, wrist_angle, jaw_angle, obj: str = 'needle',
                          initial_jaw_tension: float = 0.0, torque_constant_scale=1.0):
    """Grip force (N) over a current history, stick band included (vectorised).

    Parameters
    ----------
    model : GripForceModel
        The instrument (its efficiency, resistance fraction and contact gain).
    current : array_like, shape (n,)
        Motor current history (A), in time order.
    wrist_angle, jaw_angle : float or array_like, shape (n,)
        Wrist pitch and jaw opening (rad).
    obj : str
        Object between the jaws.
    initial_jaw_tension : float
        Jaw-side tension before the first sample (N).
    torque_constant_scale : float or array_like
        K / K_nominal (e.g. a thermal drift); 1 = nominal.

    Returns
    -------
    grip_force : ndarray, shape (n,)
        Grip force (N). Where the current only rises (from rest) it equals
        ``model.forward(current, ...).grip_force`` (to rounding).
    jaw_tension : ndarray, shape (n,)
        Jaw-side tension Tn (N).
    """
    check_object(obj)
    current = np.asarray(current, float)
    effective = current * np.asarray(torque_constant_scale, float)        # A at nominal K
    wrist = np.broadcast_to(np.asarray(wrist_angle, float), current.shape)
    jaw = np.broadcast_to(np.asarray(jaw_angle, float), current.shape)
    drum = model.tension_per_amp * effective
    lam = np.broadcast_to(model.efficiency(effective, wrist), current.shape)
    tension = play_operator(drum, lam, initial_jaw_tension)
    rn, f = model.params.drive_pulley_radius, model.resistance_fraction
    loading = tension == np.where(drum >= 0.0, lam * drum, drum / lam)
    torque = np.where(loading, rn * drum * (lam - f), rn * tension * (1.0 - f / lam))
    gain = _contact.contact_gain(obj, jaw, model.params.jaw_moment_arm_tip,
                                 model.params.jaw_moment_arm_inner)
    return np.maximum(torque, 0.0) * gain, tension


class HystereticGripForce:
    """Stateful direction-aware grip-force estimate (scalar fast path for the 1 kHz loop).

    Parameters
    ----------
    model : GripForceModel
        The loading-branch model of the instrument.
    initial_jaw_tension : float
        Jaw-side tension at start (N); 0 = cable at rest.

    Notes
    -----
    :meth:`update` moves the play operator with one current sample and returns the grip
    force; :meth:`current_for_force` is the inverse on the branch the target lies on
    from the present state (it does not change the state).
    """

    __slots__ = ('model', 'jaw_tension', 'efficiency', 'on_loading_edge', '_per_amp', '_rn',
                 '_f', '_tip', '_inner', '_efficiency')

    def __init__(self, model, initial_jaw_tension: float = 0.0):
        self.model = model
        self._per_amp = model.tension_per_amp                       # N/A
        self._rn = model.params.drive_pulley_radius                 # m
        self._f = model.resistance_fraction                         # -
        self._tip = model.params.jaw_moment_arm_tip                 # m
        self._inner = model.params.jaw_moment_arm_inner             # m
        self._efficiency = model._efficiency_scalar                 # (T0 N, wrist rad) -> lambda
        self.reset(initial_jaw_tension)

    def reset(self, jaw_tension: float = 0.0) -> None:
        """Set the jaw-side tension state (N)."""
        self.jaw_tension = float(jaw_tension)                       # Tn (N)
        self.efficiency = self._efficiency(max(self.jaw_tension, 0.0), 0.0)   # lambda (-)
        self.on_loading_edge = self.jaw_tension == 0.0

    def drive_torque(self, current: float, wrist_angle: float) -> float:
        """Advance the play with one current sample (A); the jaw drive torque M (N*m)."""
        drum = self._per_amp * current                               # T0 (N)
        lam = self._efficiency(drum, wrist_angle)
        self.efficiency = lam
        if drum >= 0.0:
            low, high = lam * drum, drum / lam
        else:
            low, high = drum / lam, lam * drum
        tension = self.jaw_tension
        if tension <= low:                                           # pulled along by the drum
            self.jaw_tension = low
            self.on_loading_edge = drum >= 0.0
            if drum >= 0.0:                                          # the paper's forward map
                return self._rn * drum * (lam - self._f)
            tension = low
        elif tension > high:                                         # slips back
            self.jaw_tension = tension = high
            self.on_loading_edge = drum < 0.0
        else:
            self.on_loading_edge = False
        return self._rn * tension * (1.0 - self._f / lam)

    def update(self, current: float, wrist_angle: float, jaw_angle: float,
               obj: str = 'needle') -> float:
        """Advance with one measured current (A); grip force (N), >= 0.

        Equals ``model.grip_force_scalar(current, ...)`` whenever the current has only
        risen since the jaw-side tension was last at the loading edge.
        """
        torque = self.drive_torque(current, wrist_angle)
        if torque <= 0.0:
            return 0.0
        return torque * _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)

    def force(self, jaw_angle: float, obj: str = 'needle') -> float:
        """Grip force of the present state, N (lambda of the last update), without moving it."""
        tension = self.jaw_tension
        if tension <= 0.0:
            return 0.0
        lam = self.efficiency
        torque = self._rn * tension * (1.0 - self._f / lam)
        if torque <= 0.0:
            return 0.0
        return torque * _contact.contact_gain_scalar(obj, jaw_angle, self._tip, self._inner)

    def current_for_force(self, grip_force: float, wrist_angle: float, jaw_angle: float,
                          obj: str = 'needle', branch: str | None = None) -> float:
        """Return the current (A) for the grip force ``grip_force`` (N) on one branch of the stick band.

        ``'loading'``: the paper's inverse (``model.current_for_force_scalar``), drum
        tension ``Tn*/lambda``: the force is reached from below. ``'unloading'``: drum
        tension ``lambda Tn*``, the cable slips back to ``Tn*``: the force is reached from
        above, with ``lambda^2`` times the loading current (constant friction).
        ``'middle'``: drum tension ``Tn*``, the geometric middle of the band around
        ``Tn*``: it holds a force already reached from either side with the largest
        margin (a factor ``1/lambda``) to both edges. Default (None): ``'unloading'``
        when the target is below the force of the present state, else ``'loading'``.

        With tension-dependent friction lambda is evaluated at the resulting drum
        tension (two fixed-point passes; the resistance moment keeps the loading lambda).

        Raises
        ------
        ModelError
            As :meth:`GripForceModel.current_for_force_scalar`; an unknown branch.
        """
        loading_current = self.model.current_for_force_scalar(grip_force, wrist_angle, jaw_angle, obj)
        if branch is None:
            branch = 'unloading' if grip_force < self.force(jaw_angle, obj) else 'loading'
        if branch == 'loading' or loading_current <= 0.0:
            if branch not in BRANCHES:
                raise ModelError(f'unknown branch {branch!r}; one of {BRANCHES}')
            return loading_current
        drum = self._per_amp * loading_current                       # T0 of the loading edge
        target_tension = self._efficiency(drum, wrist_angle) * drum  # Tn* (N)
        if branch == 'middle':
            return target_tension / self._per_amp
        if branch != 'unloading':
            raise ModelError(f'unknown branch {branch!r}; one of {BRANCHES}')
        unload_drum = self._efficiency(drum, wrist_angle) * target_tension
        for _ in range(2):                                           # lambda(T0) when friction
            unload_drum = self._efficiency(unload_drum, wrist_angle) * target_tension
        return unload_drum / self._per_amp
