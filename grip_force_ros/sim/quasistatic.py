"""Quasi-static reference of the sim: the model's forward map plus the capstan stick band.

The model (:class:`grip_force_ros.model.GripForceModel`) gives the loading branch
``Tn = lambda T0``. The sim's pulley chain also sticks and slips back (``T0 = lambda
Tn``) when the current falls, so for slow inputs its jaw-side tension is a *play
operator* of the drum tension::

    Tn[k] = clip(Tn[k-1], lambda T0[k], T0[k] / lambda)      (T0 >= 0; mirrored for T0 < 0)

This module evaluates that, with the model's own efficiency, resistance fraction and
contact gain, for whole current histories: a nominal that knows the direction of slip,
for calibration and the sim-to-real diagnosis (effect-free sim logs follow it; the
model's forward map alone only follows their loading branches).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from grip_force_ros.model import GripForceModel
from grip_force_ros.model import contact as _contact

__all__ = ['capstan_play', 'quasi_static_grip_force']


def capstan_play(drum_tension, efficiency, initial: float = 0.0) -> np.ndarray:
    """Jaw-side tension (N) of a stick-slip pulley chain driven by ``drum_tension`` (N).

    Parameters
    ----------
    drum_tension : array_like, shape (n,)
        Drum-side tension history T0 (N), signed (negative: the opening cable).
    efficiency : float or array_like, shape (n,)
        Chain efficiency lambda (-), in (0, 1].
    initial : float
        Jaw-side tension before the first sample (N).

    Returns
    -------
    ndarray, shape (n,)
        Tn, always within ``[lambda T0, T0/lambda]`` (ordered by sign).
    """
    t0 = np.asarray(drum_tension, float)
    lam = np.broadcast_to(np.asarray(efficiency, float), t0.shape)
    low = np.where(t0 >= 0.0, lam * t0, t0 / lam).tolist()
    high = np.where(t0 >= 0.0, t0 / lam, lam * t0).tolist()
    out = np.empty(t0.shape)
    tn = float(initial)
    for k in range(t0.size):
        if tn < low[k]:
            tn = low[k]
        elif tn > high[k]:
            tn = high[k]
        out[k] = tn
    return out


def quasi_static_grip_force(params: Any, current, wrist_angle, jaw_angle, obj: str = 'needle',
                            torque_constant_scale=1.0) -> np.ndarray:
    """Grip force (N) of the sim's plant for slow inputs, stick band included.

    Parameters
    ----------
    params : ParamSet
        Instrument parameters of the plant (pass ``pulley_friction_coefficient`` times
        ``friction_scale`` to mimic a mismatched plant).
    current : array_like, shape (n,)
        Motor current history (A), in time order.
    wrist_angle, jaw_angle : float or array_like, shape (n,)
        Wrist pitch and jaw opening (rad).
    obj : str
        Object between the jaws.
    torque_constant_scale : float or array_like
        K / K_nominal (e.g. a drift); 1 = nominal.

    Returns
    -------
    ndarray, shape (n,)
        Grip force (N). On a monotonically rising current it equals
        ``GripForceModel(params).forward(...).grip_force``.
    """
    model = GripForceModel(params)
    current = np.asarray(current, float)
    wrist = np.broadcast_to(np.asarray(wrist_angle, float), current.shape)
    jaw = np.broadcast_to(np.asarray(jaw_angle, float), current.shape)
    drum = model.tension_per_amp * current * np.asarray(torque_constant_scale, float)
    lam = np.broadcast_to(model.efficiency(current * np.asarray(torque_constant_scale, float), wrist),
                          current.shape)
    jaw_tension = capstan_play(drum, lam)
    arm = np.maximum(params.drive_pulley_radius * (1.0 - params.drive_resistance_fraction / lam), 0.0)
    gain = _contact.contact_gain(obj, jaw, params.jaw_moment_arm_tip, params.jaw_moment_arm_inner)
    return np.maximum(arm * jaw_tension, 0.0) * gain
