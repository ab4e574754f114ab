"""Could this instrument be built? Checks of an instrument's parameters against physics.

The per-key ranges of the schema and its cross checks (``params.check_consistency``)
cannot see these; they need the model's transmission:

* the cable must carry the drum tension of the current limit: stress
  ``F0 / (pi r^2)`` with ``F0 = gear K max_current / r0`` (N) on the cable's nominal
  section, at most ``cable_yield_strength`` (Pa);
* the chain efficiency ``lambda_n`` must be positive (and at most 1) at rest and at the
  current limit;
* the jaw torque ``M = r_n F0 (lambda_n - fraction)`` must close the jaw (> 0) up to the
  current limit: with ``lambda_n <= fraction`` the static resistance eats the whole drive
  torque and no current grips.

``grip-force params --check`` and the nodes (at start, for an instrument file) run
:func:`check_physical`; :func:`cable_load` gives the figures.
"""
from __future__ import annotations

import math
from typing import Any

from grip_force_ros.model import friction as _friction
from grip_force_ros.model import transmission as _tx
from grip_force_ros.model.contact import ModelError

__all__ = ['cable_load', 'check_physical', 'physical_problems']


def cable_load(params: Any, current: float | None = None) -> dict:
    """Drum tension and cable stress at ``current`` (default: ``max_current``).

    Returns
    -------
    dict
        ``current`` (A), ``drum_tension`` (N), ``section`` (m^2, pi r^2), ``stress`` (Pa),
        ``yield_strength`` (Pa), ``share`` (stress / yield strength), ``min_cable_radius``
        (m: the thinnest cable of this strength that carries it) and ``max_current_for_cable``
        (A: the largest current this cable carries).
    """
    p = params
    current = float(p['max_current'] if current is None else current)
    per_amp = _tx.drum_tension_per_amp(p['torque_constant'], p['gear_ratio'], p['drum_radius'])
    tension = per_amp * current
    section = math.pi * p['cable_radius'] ** 2
    strength = float(p['cable_yield_strength'])
    return {'current': current, 'drum_tension': tension, 'section': section,
            'stress': tension / section, 'yield_strength': strength,
            'share': tension / section / strength,
            'min_cable_radius': math.sqrt(tension / (math.pi * strength)),
            'max_current_for_cable': strength * section / per_amp}


def physical_problems(params: Any) -> list[str]:
    """Every reason the instrument could not be built (empty: it could)."""
    p = params
    problems = []
    load = cable_load(p)
    if load['stress'] > load['yield_strength']:
        problems.append(
            f"cable stress {load['stress'] / 1e9:.2f} GPa at max_current {load['current']:g} A "
            f"(drum tension {load['drum_tension']:.0f} N on a {2e3 * p['cable_radius']:g} mm cable) "
            f"exceeds the cable's yield strength {load['yield_strength'] / 1e9:.2f} GPa "
            "('cable_yield_strength'): the cable would yield or break; use a cable radius >= "
            f"{load['min_cable_radius'] * 1e3:.3f} mm or max_current <= "
            f"{load['max_current_for_cable']:.3f} A")
    radii = tuple(p['guide_pulley_radii'])
    wraps = tuple(p['guide_pulley_wrap_angles'])
    fraction = p['drive_resistance_fraction']
    for label, tension in (('at rest', 0.0), (f"at max_current {load['current']:g} A",
                                              load['drum_tension'])):
        lam = float(_friction.chain_efficiency(p['pulley_friction_coefficient'], radii,
                                               p['cable_radius'], wraps, tension,
                                               p['tension_friction_gain']))
        if not (math.isfinite(lam) and 0.0 < lam <= 1.0):
            problems.append(f'chain efficiency lambda_n = {lam!r} {label}: it must lie in (0, 1] '
                            '(pulley friction, radii or wrap angles)')
        elif lam <= fraction:
            problems.append(
                f'jaw torque of the wrong sign {label}: chain efficiency lambda_n = {lam:.4f} is not '
                f"above 'drive_resistance_fraction' {fraction:g}, so M = r_n F0 (lambda_n - "
                f'{fraction:g}) <= 0 and no current closes the jaw')
    return problems


def check_physical(params: Any) -> None:
    """Raise :class:`ModelError` naming every reason the instrument could not be built.

    Parameters
    ----------
    params : ParamSet or mapping
        Instrument and limits values (SI).

    Raises
    ------
    ModelError
        One message listing the problems (see :func:`physical_problems`).
    """
    problems = physical_problems(params)
    if problems:
        name = params.get('instrument_name', 'instrument') if hasattr(params, 'get') else 'instrument'
        raise ModelError(f'{name} could not be built: ' + '; '.join(problems))
