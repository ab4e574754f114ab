"""Names of the optional unmodelled effects of the simulated instrument.

The names are the DESIGN.md vocabulary; each is a parameter of the 'effects'
group (``params/sim.py``) whose value is the effect's strength, 0 = off.
"""
from __future__ import annotations

from typing import Any, Mapping

#: The effects the sim can switch on, DESIGN.md names (``none`` is not an effect).
EFFECT_NAMES: tuple[str, ...] = (
    'pivot_coulomb_friction',      # N*m, stick-slip torque at the jaw pivot
    'viscous_friction',            # N*m*s/rad, extra viscous torque at the jaw pivot
    'cable_hysteresis',            # -, Dahl loop half-width as a fraction of the tension
    'backlash',                    # rad, dead band at the jaw
    'tension_dependent_friction',  # 1/N, mu(T) = mu*(1 + g*|T|)
    'viscoelastic_creep',          # -, fraction of the jaw torque that relaxes under load
    'sensor_delay',                # s, load-cell transport delay
    'torque_constant_drift',       # -, K = K0*(1 - s*heat)
    'force_sensor_offset',         # N, load-cell offset
    'position_spring',             # N*m, jaw return spring: opening torque at the closed jaw
)


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
