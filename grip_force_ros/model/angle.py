"""Angle transmission: jaw angle from drum angle, wrist angle (coupling) and current (creep).

Paper (theta_4 = jaw rotation in the closing direction)::

    theta_4 = (r0/r_n theta_0 - sum_i dtheta_i) - 3/5 (theta_32 - sum_j dtheta_j)
    dtheta_i = dl_i / r_n
    dl_i = F0 lambda_i r_n / (E A) * int_0^theta_i (1 - eta_i(alpha)) d alpha

The integrand ``1 - eta`` is <= 0 (tension rises along the wrap), so we use its
magnitude: the stretch of the wrapped cable beyond the tension at its slack end
F0 lambda_i, ``dl_i = F0 lambda_i R_i / (E A) int (eta_i - 1) d alpha``, with the arc
length element ``R_i d alpha`` of pulley i (the paper prints r_n there; docs/model.md).
Tension stretches the cable, so the jaw closes less than the drum commands.

Our sign convention (docs/ARCHITECTURE.md): jaw angle positive = open, drum angle
positive = closing, so ``jaw_angle = -theta_4`` with 0 = closed at zero drum angle,
zero wrist angle and zero current.
"""
from __future__ import annotations

import math

import numpy as np

from grip_force_ros.model.friction import chain_tensions, wrap_excess_integral

__all__ = ['cable_section_stiffness', 'wrap_creep_angle', 'jaw_angle_from_drum', 'drum_angle_for_jaw']


def cable_section_stiffness(modulus: float, cable_radius: float) -> float:
    """Axial stiffness E*A of a round cable (N)."""
    return modulus * math.pi * cable_radius ** 2


def wrap_creep_angle(drum_tension, mu, pulley_radii, cable_radius, wrap_angles, stiffness,
                     drive_pulley_radius, gain=0.0):
    """Jaw angle lost to creep on a chain of pulleys, ``sum_i dl_i / r_n`` (rad).

    Parameters
    ----------
    drum_tension : float or array
        F0 (N). Negative tension (the antagonist cable pulls) gives negative creep.
    mu, pulley_radii, cable_radius, wrap_angles, gain
        As in :func:`grip_force_ros.model.friction.chain_tensions`.
    stiffness : float
        E*A (N).
    drive_pulley_radius : float
        r_n (m).
    """
    f0 = np.asarray(drum_tension, float)
    magnitude = np.abs(f0)
    tensions = chain_tensions(magnitude, mu, pulley_radii, cable_radius, wrap_angles, gain)
    total = np.zeros(np.broadcast(magnitude, *map(np.asarray, wrap_angles)).shape)
    for i, (radius, wrap) in enumerate(zip(pulley_radii, wrap_angles)):
        slack_tension = tensions[i + 1]                                 # F0 lambda_i
        mu_here = mu * (1.0 + gain * tensions[i])
        stretch = slack_tension * radius / stiffness * wrap_excess_integral(
            mu_here, radius, cable_radius, wrap)                        # dl_i (m)
        total = total + stretch / drive_pulley_radius                   # dtheta_i = dl_i / r_n
    return np.sign(f0) * total


def jaw_angle_from_drum(drum_angle, wrist_angle, finger_creep, wrist_creep, drum_radius,
                        drive_pulley_radius, coupling):
    """Jaw opening angle (rad) from drum angle, wrist angle and creep angles.

    ``jaw = -theta_4 = -(r0/r_n theta_0 - finger_creep) + coupling (theta_32 - wrist_creep)``.
    """
    closing = (drum_radius / drive_pulley_radius * np.asarray(drum_angle, float) - finger_creep
               - coupling * (np.asarray(wrist_angle, float) - wrist_creep))
    return -closing


def drum_angle_for_jaw(jaw_angle, wrist_angle, finger_creep, wrist_creep, drum_radius,
                       drive_pulley_radius, coupling):
    """Inverse of :func:`jaw_angle_from_drum`: drum angle theta_0 (rad) for a jaw angle."""
    closing = -np.asarray(jaw_angle, float)
    return (closing + finger_creep + coupling * (np.asarray(wrist_angle, float) - wrist_creep)) \
        * drive_pulley_radius / drum_radius
