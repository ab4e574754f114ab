"""Torque transmission: motor current -> drum tension -> pulley chain -> jaw drive torque.

Paper chain (SI)::

    M0 = K I                       motor torque (N*m), K torque constant (N*m/A)
    F0 = gear K I / r0             drum tension (N); paper: F0 = M0/r0 = 1.77 I/r0
    F_n' = F0 lambda_n             tension reaching the drive pulley (N)
    M  = F0 lambda_n r_n - M'      torque on the jaw drive pulley (N*m)

The resistance moment as printed in the paper is
``M' = (2 r_n M0 - r0 r_n (m_n thd_n - m0 thd_0)) / (2 r0)``. Its static part with
``M0 = F0 r0`` (the paper's own use of M0 as drum torque) is ``r_n F0``; with
lambda_n < 1 that makes M negative for every current, so we read the leading 2 as a
typo and keep ``fraction * r_n F0`` with ``fraction = drive_resistance_fraction``
(default 0.5; the as-printed reading is 1.0, none is 0). See docs/model.md.
The velocity part ``r_n (m_n thd_n - m0 thd_0)/2`` has units kg*m/s, not N*m; we
keep it numerically as printed (its size is ~1e-6 N*m per rad/s, negligible).
"""
from __future__ import annotations

import numpy as np

__all__ = ['drum_tension', 'drum_tension_per_amp', 'static_resistance', 'inertial_moment',
           'drive_torque']


def drum_tension_per_amp(torque_constant: float, gear_ratio: float, drum_radius: float) -> float:
    """Drum tension per ampere ``gear K / r0`` (N/A)."""
    return gear_ratio * torque_constant / drum_radius


def drum_tension(current, torque_constant, gear_ratio, drum_radius):
    """Cable tension leaving the drum ``F0 = gear K I / r0`` (N).

    Parameters
    ----------
    current : float or array
        Motor current I (A); positive closes the jaw.
    torque_constant : float
        Motor torque constant K (N*m/A).
    gear_ratio : float
        Motor-to-drum reduction (-).
    drum_radius : float
        Drum radius r0 (m).
    """
    return np.asarray(current, float) * drum_tension_per_amp(torque_constant, gear_ratio, drum_radius)


def static_resistance(drum_tension_n, drive_pulley_radius, fraction):
    """Return the static part of the resistance moment M' (N*m): ``fraction * r_n * F0``.

    Paper: ``r_n M0 / r0`` with ``M0 = F0 r0`` (fraction 1 as printed; 0.5 if the
    numerator's 2 is a typo).
    """
    return fraction * drive_pulley_radius * np.asarray(drum_tension_n, float)


def inertial_moment(jaw_closing_rate, drum_rate, drive_pulley_radius, jaw_mass, drum_mass):
    """Velocity part of M', added to M: ``r_n (m_n thd_n - m0 thd_0) / 2`` (numerically N*m).

    Parameters
    ----------
    jaw_closing_rate : float or array
        thd_n, jaw rotation rate in the closing direction (rad/s) = -jaw opening rate.
    drum_rate : float or array
        thd_0, drum rate (rad/s), positive closing.
    drive_pulley_radius, jaw_mass, drum_mass : float
        r_n (m), m_n (kg), m0 (kg).

    Notes
    -----
    As printed the term has units kg*m/s; we use its SI number as N*m.
    """
    return 0.5 * drive_pulley_radius * (jaw_mass * np.asarray(jaw_closing_rate, float)
                                        - drum_mass * np.asarray(drum_rate, float))


def drive_torque(drum_tension_n, efficiency, drive_pulley_radius, resistance_fraction,
                 inertial=0.0):
    """Torque on the jaw drive pulley ``M = F0 lambda_n r_n - M'`` (N*m).

    ``M' = resistance_fraction r_n F0 - inertial``; so
    ``M = r_n F0 (lambda_n - resistance_fraction) + inertial``.
    """
    f0 = np.asarray(drum_tension_n, float)
    return drive_pulley_radius * f0 * (np.asarray(efficiency, float) - resistance_fraction) + inertial
