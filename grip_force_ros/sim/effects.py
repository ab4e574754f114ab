"""The effects the simulated instrument can switch on, and the check of an ``effects`` dict.

The names, units and ranges are the effect registry's (:mod:`grip_force_ros.effects`);
each is a parameter of the 'effects' group (``params/sim.py``) whose value is the
effect's strength, 0 = off.
"""
from __future__ import annotations

from typing import Any, Mapping

from grip_force_ros.effects import SIMULATED

#: The effects the sim can switch on, docs/design.md names (``none`` is not an effect).
EFFECT_NAMES: tuple[str, ...] = SIMULATED


class SimError(ValueError):
    """Invalid input to the simulated instrument (unknown object or effect, bad command)."""


def effect_overrides(effects: Mapping[str, Any] | None) -> dict[str, float]:
    """Check an ``effects`` dict (effect name -> strength) and return it as floats.

    Extra parameters of an effect (e.g. ``viscoelastic_creep_time_constant``)
    are accepted too. Validation of ranges happens in the parameter schema.

    Raises
    ------
    SimError
        For a name that is neither an effect nor an effects-group parameter.
    """
    from grip_force_ros.params import specs_in
    if not effects:
        return {}
    allowed = {s.name for s in specs_in('effects')}
    out = {}
    for name, value in effects.items():
        if name not in allowed:
            raise SimError(f'unknown effect {name!r}; known: {list(EFFECT_NAMES)}')
        out[name] = float(value)
    return out
