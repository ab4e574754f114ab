"""The unmodelled effects: the one registry of their names, units and strengths.

The names are the docs/design.md vocabulary. Each entry says what the effect is, the unit
and range of its strength, the strengths the blind check and the benches use, and who
implements it: the simulated instrument (``sim/plant.py``, switched on by the
parameter of the same name in the 'effects' group) and the diagnosis (a regressor
builder in ``lab/diagnosis/effects.py``). Everything else reads this module:

- ``params/sim.py`` declares the 'effects' parameter group from it;
- ``sim/effects.py`` and ``lab/diagnosis/effects.py`` take their vocabularies from it
  (:data:`SIMULATED`, :data:`DIAGNOSED`);
- the blind check (``lab/diagnosis/blind.py``) takes its effects and strengths from it;
- the sim benchmark switches every simulated effect on at :func:`strengths_at`.

Adding an effect: an entry here, its physics in the sim and/or its builder in the
diagnosis. Plain data, no imports from the package (the parameter schema reads it).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ['EffectParam', 'EffectSpec', 'REGISTRY', 'EFFECT_NAMES', 'SIMULATED', 'DIAGNOSED', 'NONE',
           'LEVELS', 'strengths_at']

#: The verdict when no effect explains a meaningful part of the gap (not an effect).
NONE = 'none'
#: Names of the strength levels of :attr:`EffectSpec.strengths`.
LEVELS = ('weak', 'medium', 'strong')


@dataclass(frozen=True)
class EffectParam:
    """A further sim parameter of an effect (a time constant, a rest angle).

    Attributes
    ----------
    name : str
        Parameter name in the 'effects' group.
    default : float
        Default value, in ``unit``.
    unit : str
        SI unit ('' for dimensionless).
    description : str
        One or two sentences for the schema and the docs.
    min, max : float
        Allowed range, in ``unit``.
    """

    name: str
    default: float
    unit: str
    description: str
    min: float
    max: float


@dataclass(frozen=True)
class EffectSpec:
    """One unmodelled effect.

    Attributes
    ----------
    name : str
        docs/design.md name; also the sim parameter that holds its strength.
    unit : str
        Unit of the strength ('' for a fraction).
    description : str
        What the strength means (the parameter's description; 0 = off).
    min, max : float
        Range of the strength the sim accepts, in ``unit`` (default strength: 0 = off).
    strengths : tuple of float
        Weak, medium and strong strengths (:data:`LEVELS`), in ``unit``: the blind
        check's settings and the benchmarks' "effect on".
    simulated : bool
        The simulated instrument can generate it (it has a strength parameter).
    diagnosed : bool
        The diagnosis can fit it (it has a regressor builder).
    params : tuple of EffectParam
        Further sim parameters of the effect.
    blind_extras : tuple of (str, float)
        Sim parameters the blind check sets with this effect (name, value).
    """

    name: str
    unit: str
    description: str
    min: float
    max: float
    strengths: tuple[float, float, float]
    simulated: bool = True
    diagnosed: bool = True
    params: tuple[EffectParam, ...] = ()
    blind_extras: tuple[tuple[str, float], ...] = ()


_REGISTRY = (
    EffectSpec('pivot_coulomb_friction', 'N*m',
               'Coulomb (stick-slip) friction torque at the jaw pivot, opposing jaw motion. 0 = off.',
               0.0, 0.5, (0.005, 0.01, 0.02)),
    EffectSpec('viscous_friction', 'N*m*s/rad',
               'Extra viscous friction at the jaw pivot (torque = -c * jaw velocity). 0 = off.',
               0.0, 1.0, (0.01, 0.02, 0.04)),
    EffectSpec('cable_hysteresis', '',
               'Hysteresis of the cable bending over the drive pulley (Dahl model): a moment opposing '
               'changes of the cable tension, loop half-width as a fraction of the jaw drive moment. '
               '0 = off.',
               0.0, 0.5, (0.1, 0.2, 0.3)),
    EffectSpec('backlash', 'rad',
               'Dead band (full width, at the jaw) in the cable-jaw transmission. 0 = off.',
               0.0, 0.5, (0.03, 0.06, 0.12)),
    EffectSpec('tension_dependent_friction', '1/N',
               'Cable-pulley friction that grows with tension: mu(T) = mu*(1 + g*|T|), g unknown to the '
               'model. 0 = off.',
               0.0, 0.01, (0.002, 0.004, 0.008)),
    EffectSpec('viscoelastic_creep', '',
               'Slow relaxation of the jaw drive moment under load: this fraction of it relaxes '
               'with time constant viscoelastic_creep_time_constant and recovers when unloaded. 0 = off.',
               0.0, 0.9, (0.15, 0.3, 0.5),
               params=(EffectParam('viscoelastic_creep_time_constant', 2.0, 's',
                                   'Time constant of viscoelastic_creep.', 1e-3, 1e4),)),
    EffectSpec('sensor_delay', 's',
               'Transport delay of the load cell (grip force) relative to the other sensors. 0 = off.',
               0.0, 1.0, (0.03, 0.06, 0.1)),
    EffectSpec('torque_constant_drift', '',
               'Motor heating lowers the torque constant: K = K0*(1 - s*h), h = normalised heat (first '
               'order in I^2, 1 at a sustained max_current). 0 = off.',
               0.0, 0.9, (0.5, 0.8, 0.9),
               params=(EffectParam('torque_constant_drift_time_constant', 20.0, 's',
                                   'Thermal time constant of torque_constant_drift.', 1e-3, 1e5),),
               # a small motor's winding heats within seconds
               blind_extras=(('torque_constant_drift_time_constant', 10.0),)),
    EffectSpec('force_sensor_offset', 'N',
               'Constant offset added to the load-cell grip force. 0 = off.',
               -50.0, 50.0, (0.3, -0.5, 0.8)),
    # strengths: N*m opening at the closed jaw (rest angle 1 rad): 8-30 % of the jaw torque at
    # 0.3 A (49 mN*m), 0.3-1.2 N of grip force at the tip; the da Vinci rig's fitted spring: 13 mN*m
    EffectSpec('position_spring', 'N*m',
               'Return spring / cable pretension at the jaw: a torque opening the jaw that depends on '
               'where the jaw is, this much at the closed jaw (0 rad), falling linearly to 0 at '
               'position_spring_rest_angle (a preloaded torsion spring). It acts on the jaw dynamics '
               'like any jaw torque, so in contact it takes its share of the drive moment from the '
               'grip force. 0 = off.',
               0.0, 0.1, (0.004, 0.008, 0.015),
               params=(EffectParam('position_spring_rest_angle', 1.0, 'rad',
                                   'Jaw angle at which the position_spring torque is zero (beyond it the '
                                   'spring closes the jaw): spring rate = position_spring / this.',
                                   0.05, 100.0),)),
)

#: Effect name -> its entry, in the docs/design.md order (the order of every effect list).
REGISTRY: dict[str, EffectSpec] = {e.name: e for e in _REGISTRY}
#: Every effect name (the docs/design.md vocabulary; :data:`NONE` is not an effect).
EFFECT_NAMES: tuple[str, ...] = tuple(REGISTRY)
#: Effects the simulated instrument can generate.
SIMULATED: tuple[str, ...] = tuple(e.name for e in _REGISTRY if e.simulated)
#: Effects the diagnosis can fit.
DIAGNOSED: tuple[str, ...] = tuple(e.name for e in _REGISTRY if e.diagnosed)

if len(REGISTRY) != len(_REGISTRY) or NONE in REGISTRY:  # pragma: no cover - a programming error
    raise RuntimeError('duplicate effect name, or an effect named none, in the registry')


def strengths_at(level: str = 'medium', names=SIMULATED) -> dict[str, float]:
    """Effect name -> its strength at ``level`` (one of :data:`LEVELS`), for ``names``.

    Parameters
    ----------
    level : str
        'weak', 'medium' or 'strong'.
    names : iterable of str
        Effects to include (default: every simulated effect).

    Returns
    -------
    dict
        Name -> strength in the effect's unit (:attr:`EffectSpec.unit`).
    """
    k = LEVELS.index(level)
    return {name: REGISTRY[name].strengths[k] for name in names}
