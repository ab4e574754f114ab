"""Contact: jaw drive torque -> grip force on a rigid object, tissue or a suture needle.

Paper::

    F_N = M / l                         normal force at distance l from the pivot (N)
    rigid:  F_J = F_N cos(opening)      opening = gripping angle (rad)
    tissue: F_J = 2 M cos(opening) / (l + l')     force acting at (l + l')/2
    needle: F_J = F_N1 = M / l1
            F_L = mu' (F_N1 + F_N2 + F_N3) = (sqrt2 + 1) mu' F_N1     (pull-out, Amontons)

Tissue: the paper prints ``2M / ((l + l') cos)``; dividing by cos grows without bound
as the jaw opens (infinite at pi/2) and contradicts the rigid case ``F_N cos``, so we
multiply (see docs/model.md). Needle: the paper prints ``F_N1 = sqrt2 F_N2 + sqrt2
F_N3``, which with F_N2 = F_N3 would give ``(1 + 1/sqrt2) mu' F_N1``; force balance
with contacts at 45 deg gives ``F_N1 = (F_N2 + F_N3)/sqrt2`` and the paper's own
``(sqrt2 + 1)``, which we use.
"""
from __future__ import annotations

import math

import numpy as np

from grip_force_ros.objects import OBJECTS

__all__ = ['OBJECTS', 'ModelError', 'contact_gain', 'contact_gain_scalar', 'needle_normal_forces',
           'needle_pull_out', 'PULL_OUT_PER_MU']


#: F_L / (mu' F_N1) for the three-point needle contact (-).
PULL_OUT_PER_MU = math.sqrt(2.0) + 1.0


class ModelError(ValueError):
    """An input the model cannot evaluate (unknown object, unreachable force, bad geometry)."""


def check_object(obj: str) -> str:
    """Return ``obj`` if it is one of :data:`OBJECTS`, else raise :class:`ModelError`."""
    if obj not in OBJECTS:
        raise ModelError(f'unknown object {obj!r}; expected one of {list(OBJECTS)}')
    return obj


def contact_gain(obj, jaw_angle, tip_arm, inner_arm):
    """Grip force per unit drive torque G (1/m): ``F_J = max(M, 0) * G``.

    Parameters
    ----------
    obj : str
        One of :data:`OBJECTS`.
    jaw_angle : float or array
        Jaw opening / gripping angle (rad); G is clipped at 0 past pi/2.
    tip_arm : float
        l, pivot to contact point (m).
    inner_arm : float
        l', inner end of a distributed (tissue) contact (m).
    """
    check_object(obj)
    angle = np.asarray(jaw_angle, float)
    if obj == 'free':
        return np.zeros_like(angle)
    if obj == 'needle':
        return np.full_like(angle, 1.0 / tip_arm)                  # F_J = F_N1 = M / l1
    cosine = np.maximum(np.cos(angle), 0.0)
    if obj == 'rigid':
        return cosine / tip_arm                                    # F_J = (M / l) cos
    return 2.0 * cosine / (tip_arm + inner_arm)                    # F_J = 2 M cos / (l + l')


def contact_gain_scalar(obj: str, jaw_angle: float, tip_arm: float, inner_arm: float) -> float:
    """Scalar :func:`contact_gain` (pure math)."""
    if obj == 'needle':
        return 1.0 / tip_arm
    if obj == 'rigid':
        return max(math.cos(jaw_angle), 0.0) / tip_arm
    if obj == 'tissue':
        return 2.0 * max(math.cos(jaw_angle), 0.0) / (tip_arm + inner_arm)
    if obj == 'free':
        return 0.0
    raise ModelError(f'unknown object {obj!r}; expected one of {list(OBJECTS)}')


def needle_normal_forces(grip_force):
    """Return the normal forces (F_N1, F_N2, F_N3) on a needle held in three points (N).

    F_N1 = grip force (one jaw face); F_N2 = F_N3 = F_N1/sqrt2 (45 deg contacts on
    the other jaw, force balance ``F_N1 = (F_N2 + F_N3) cos 45``).
    """
    f1 = np.asarray(grip_force, float)
    return f1, f1 / math.sqrt(2.0), f1 / math.sqrt(2.0)


def needle_pull_out(grip_force, needle_friction):
    """Needle pull-out force ``F_L = mu' (F_N1 + F_N2 + F_N3) = (sqrt2 + 1) mu' F_J`` (N)."""
    return PULL_OUT_PER_MU * needle_friction * np.asarray(grip_force, float)
