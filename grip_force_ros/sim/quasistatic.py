"""Quasi-static reference of the sim: the model's forward map plus the capstan stick band.

The model (:class:`grip_force_ros.model.GripForceModel`) gives the loading branch
``Tn = lambda T0``. The sim's pulley chain also sticks and slips back (``T0 = lambda
Tn``) when the current falls, so for slow inputs its jaw-side tension is a *play
operator* of the drum tension::

    Tn[k] = clip(Tn[k-1], lambda T0[k], T0[k] / lambda)      (T0 >= 0; mirrored for T0 < 0)

The play operator and the grip force on it live in :mod:`grip_force_ros.model.hysteresis`
(the controller's sensorless estimate uses the same code); this module evaluates them,
with the model's own efficiency, resistance fraction and
contact gain, for whole current histories: a nominal that knows the direction of slip,
for calibration and the sim-to-real diagnosis (effect-free sim logs follow it; the
model's forward map alone only follows their loading branches).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from grip_force_ros.model import GripForceModel
from grip_force_ros.model.hysteresis import hysteretic_grip_force, play_operator

__all__ = ['capstan_play', 'quasi_static_grip_force']


#: The stick band as a play operator on the tension; one implementation, in the model.
capstan_play = play_operator


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
    force, _ = hysteretic_grip_force(GripForceModel(params), current, wrist_angle, jaw_angle, obj,
                                     torque_constant_scale=torque_constant_scale)
    return force
