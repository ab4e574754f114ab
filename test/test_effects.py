"""The effect registry (grip_force_ros/effects.py) is what the sim, the diagnosis, the
schema and the blind check read: each of them agrees with it."""
import pytest

from grip_force_ros import effects
from grip_force_ros.params import SPECS, specs_in


def test_registry_holds_the_design_vocabulary_in_order():
    assert effects.EFFECT_NAMES == tuple(effects.REGISTRY)
    assert effects.NONE not in effects.REGISTRY
    assert set(effects.SIMULATED) <= set(effects.EFFECT_NAMES)
    assert set(effects.DIAGNOSED) <= set(effects.EFFECT_NAMES)


@pytest.mark.parametrize('name', effects.EFFECT_NAMES)
def test_strengths_lie_in_the_range_and_extras_are_parameters_of_the_effect(name):
    e = effects.REGISTRY[name]
    assert len(e.strengths) == len(effects.LEVELS)
    assert all(e.min <= s <= e.max and s != 0.0 for s in e.strengths)
    assert e.description.endswith('0 = off.')
    declared = {x.name for x in e.params}
    assert all(extra in declared for extra, _ in e.blind_extras)
    assert all(x.min <= x.default <= x.max for x in e.params)


def test_schema_declares_each_simulated_effect_from_the_registry():
    group = [s.name for s in specs_in('effects')]
    expected = []
    for name in effects.SIMULATED:
        e = effects.REGISTRY[name]
        expected += [name] + [x.name for x in e.params]
        spec = SPECS[name]
        assert (spec.unit, spec.min, spec.max, spec.default, spec.description) == \
            (e.unit, e.min, e.max, 0.0, e.description)
    assert group == expected


def test_sim_diagnosis_and_blind_check_read_the_registry():
    from grip_force_ros.lab.diagnosis import effects as diagnosis_effects
    from grip_force_ros.lab.diagnosis.blind import BLIND_EFFECTS, STRENGTH_SPREAD, cases
    from grip_force_ros.sim import EFFECT_NAMES as SIM_NAMES
    assert SIM_NAMES == effects.SIMULATED
    assert diagnosis_effects.EFFECT_NAMES == effects.DIAGNOSED
    assert set(diagnosis_effects.EFFECTS) == set(effects.DIAGNOSED)
    # the blind set draws each single effect around one registry level (STRENGTH_SPREAD, so
    # that no strength sits on the diagnosis' grid), in level order, clipped to the range
    singles = [c.effects[0] for c in cases() if len(c.effects) == 1]
    assert {name for name, _ in singles} == set(BLIND_EFFECTS)
    low, high = STRENGTH_SPREAD
    for name in BLIND_EFFECTS:
        spec = effects.REGISTRY[name]
        drawn = [s for n, s in singles if n == name]
        assert len(drawn) == len(spec.strengths)
        for level, s in zip(spec.strengths, drawn):
            assert spec.min <= s <= spec.max
            assert s in (spec.min, spec.max) or low <= s / level <= high, (name, level, s)


def test_strengths_at_a_level():
    medium = effects.strengths_at('medium')
    assert list(medium) == list(effects.SIMULATED)
    assert medium['backlash'] == effects.REGISTRY['backlash'].strengths[1]
    assert effects.strengths_at('weak', ['sensor_delay']) == {
        'sensor_delay': effects.REGISTRY['sensor_delay'].strengths[0]}
    with pytest.raises(ValueError):
        effects.strengths_at('huge')
