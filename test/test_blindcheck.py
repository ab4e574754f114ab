"""Blind check: simulated logs with hidden effects, diagnosed without the answer (CI: --quick)."""
import numpy as np
import pytest

from grip_force_ros.lab.diagnosis.blind import (BLIND_EFFECTS, CI_SEEDS, DEVELOPMENT_SEEDS, HELD_OUT_SEEDS,
                                                NONE_PLANTS, BlindCase, cases, generate_log, is_right,
                                                plant_params, run_blindcheck)
from grip_force_ros.lab.diagnosis.effects import EFFECT_NAMES, EFFECTS
from grip_force_ros.effects import REGISTRY
from grip_force_ros.logs import normalise_log
from grip_force_ros.params import make_params

CONTRACT = {'t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force', 'object'}


def test_blind_logs_carry_only_the_contract_columns():
    """Nothing in a log names its effect: same columns, types and excitation with or without one."""
    plain = generate_log(BlindCase((), 3), duration=3.0)
    with_effect = generate_log(BlindCase((('sensor_delay', 0.05),), 3), duration=3.0)
    for log in (plain, with_effect):
        assert set(log) == CONTRACT
        normalise_log(log)                                   # passes the contract checks
    for k in CONTRACT - {'grip_force'}:                      # same inputs, only the physics differs
        if k == 'object':
            assert (plain[k] == with_effect[k]).all()
        else:
            np.testing.assert_allclose(plain[k], with_effect[k], atol=1e-9 if k == 't' else 1.0)
    assert not np.allclose(plain['grip_force'], with_effect['grip_force'])


def test_the_sets_cover_every_effect_pairs_and_effect_free_logs():
    from grip_force_ros.sim import EFFECT_NAMES as SIM_EFFECT_NAMES
    # every effect the sim can generate is in the set; since the sim has a position spring
    # that is the whole diagnosis vocabulary (an effect the sim lacked would still be a
    # candidate on every log, only ever a false positive)
    assert set(BLIND_EFFECTS) == set(EFFECT_NAMES) & set(SIM_EFFECT_NAMES)
    assert set(BLIND_EFFECTS) == set(EFFECT_NAMES)
    assert 'position_spring' in BLIND_EFFECTS
    full = cases(quick=False)
    quick = cases(quick=True)
    for s in (full, quick):
        truths = {c.truth for c in s}
        assert {(name,) for name in BLIND_EFFECTS} <= truths
        assert ('none',) in truths
        assert any(len(t) == 2 for t in truths)
    assert len({c.effects for c in full if len(c.truth) == 1 and c.truth != ('none',)}) \
        == 3 * len(BLIND_EFFECTS)


def test_the_seed_ranges_are_disjoint_and_share_no_log():
    """Development, held-out and CI seeds: separate ranges, and their blind sets no log seed."""
    ranges = (set(DEVELOPMENT_SEEDS), set(HELD_OUT_SEEDS), set(CI_SEEDS))
    assert not (ranges[0] & ranges[1]) and not (ranges[0] & ranges[2]) and not (ranges[1] & ranges[2])
    log_seeds = [{c.seed for s in r for c in cases(seed=s)} for r in ranges]
    assert not (log_seeds[0] & log_seeds[1]) and not (log_seeds[1] & log_seeds[2])
    assert len(HELD_OUT_SEEDS) >= 5


def test_no_plant_matches_its_yaml_and_strengths_sit_off_the_grid():
    yaml = make_params()
    full = cases(quick=False, seed=0)
    none_cases = [c for c in full if c.truth == ('none',)]
    assert [(dict(c.plant)['pulley_friction_coefficient'], dict(c.plant)['cable_modulus'])
            for c in none_cases] == list(NONE_PLANTS)
    for c in full:
        plant = dict(c.plant)
        assert set(plant) == {'pulley_friction_coefficient', 'cable_modulus', 'torque_constant',
                              'wrist_finger_coupling'}
        assert 0.92 <= plant['torque_constant'] <= 1.08 and plant['torque_constant'] != 1.0
        p = plant_params(c)
        assert p.friction_scale == plant['pulley_friction_coefficient']
        assert p.stiffness_scale == plant['cable_modulus']
        assert p.torque_constant == pytest.approx(yaml.torque_constant * plant['torque_constant'])
        assert c.plant_values(yaml)['pulley_friction_coefficient'] == pytest.approx(
            yaml.pulley_friction_coefficient * plant['pulley_friction_coefficient'])
        for name, strength in c.effects:     # around a registry level, never on it
            assert strength not in REGISTRY[name].strengths
            assert any(0.8 - 1e-9 <= strength / level <= 1.25 + 1e-9 for level in REGISTRY[name].strengths)
        grids = {v for e in EFFECTS.values() for v in e.grid}
        for name, value in c.extras:         # time constants and rest angles off the diagnosis' grids
            assert value not in grids
    # the mismatches of the blind set: friction 0.85 / 1.15 and stiffness 0.8 / 1.2 among effect logs too
    frictions = {dict(c.plant)['pulley_friction_coefficient'] for c in full if c.truth != ('none',)}
    assert {0.85, 1.0, 1.15} <= frictions


def test_a_pair_is_right_only_when_both_effects_are_named():
    both = {'effect': 'backlash', 'effects': ['backlash', 'sensor_delay']}
    assert is_right(('backlash', 'sensor_delay'), both)
    assert not is_right(('backlash', 'sensor_delay'), {'effect': 'backlash', 'effects': ['backlash']})
    assert is_right(('backlash',), {'effect': 'backlash', 'effects': ['backlash', 'sensor_delay']})
    assert not is_right(('backlash',), {'effect': 'sensor_delay', 'effects': ['sensor_delay', 'backlash']})
    assert is_right(('none',), {'effect': 'none', 'effects': ['none']})


def test_the_plant_mismatch_reaches_the_sim():
    """Same excitation: a plant with its friction 15 % above the YAML gives another grip force."""
    plain = generate_log(BlindCase((), 5, (), ()), duration=3.0)
    rough = generate_log(BlindCase((), 5, (), (('pulley_friction_coefficient', 1.15),)), duration=3.0)
    np.testing.assert_array_equal(plain['current'], rough['current'])
    assert not np.allclose(plain['grip_force'], rough['grip_force'])


def test_the_mismatch_figures_count_the_off_plants_only():
    """`mismatch`: effect-free logs with friction or stiffness >= 10 % off; an unidentified one is a miss."""
    from grip_force_ros.lab.diagnosis.blind import _mismatch

    def log(truth, plant, right, parameters):
        return {'truth': truth, 'plant': plant, 'right': right, 'parameters': parameters}

    def fitted(rel_err, named_off=True):
        return {'rel_err': rel_err, 'named_off': named_off}

    per_log = [
        log(['none'], {'pulley_friction_coefficient': 1.15, 'cable_modulus': 1.0}, True,
            {'pulley_friction_coefficient': fitted(0.02), 'cable_modulus': fitted(0.0, False)}),
        log(['none'], {'pulley_friction_coefficient': 0.85, 'cable_modulus': 0.8}, False,
            {'pulley_friction_coefficient': fitted(0.07)}),               # stiffness not identified
        log(['none'], {'pulley_friction_coefficient': 1.0, 'cable_modulus': 1.0}, False, {}),    # at the YAML
        log(['backlash'], {'pulley_friction_coefficient': 1.0, 'cable_modulus': 1.2}, True, {}),
        log(['backlash'], {'pulley_friction_coefficient': 1.0, 'cable_modulus': 1.05}, False, {}),  # not off
    ]
    assert _mismatch(per_log) == {'logs': 2, 'none': 0.5, 'within_5pct': 1 / 3, 'effect_logs': 1,
                                  'effect_named': 1.0}


@pytest.mark.slow
@pytest.mark.timeout(2400)   # 4 quick seeds (56 logs of 60 s): ~4 min on a quiet machine, ~15 at load 12
def test_quick_blindcheck_meets_the_goals_over_the_ci_seeds():
    """The CI blind check: the quick sets of the four CI seeds (never tuned on), mean and worst seed.

    The issue's goals (blindcheck.GOALS on the mean: >= 90 % named right, median held-out
    shrink >= 50 %, effect-free `none` >= 90 %; worst seed >= 85 % named right), and item 2
    on the effect-free logs whose plant has its friction or stiffness off: `none` and the off
    parameter named within 5 %. Several seeds, so a lucky one cannot pass it alone.
    """
    from grip_force_ros.lab.cli.blindcheck import GOALS, WORST_ACCURACY
    result = run_blindcheck(quick=True, seed=CI_SEEDS[0], seeds=len(CI_SEEDS), workers=2)
    assert [s['seed'] for s in result['per_seed']] == list(CI_SEEDS)
    assert result['logs'] == sum(len(cases(quick=True, seed=s)) for s in CI_SEEDS)
    rows = result['confusion']
    assert sum(sum(r.values()) for r in rows.values()) == result['logs']
    figures = {k: result[k] for k in GOALS} | {'worst_accuracy': result['worst']['accuracy']}
    for key, goal in GOALS.items():
        assert result[key] >= goal, figures
    assert result['worst']['accuracy'] >= WORST_ACCURACY, figures
    mismatch = result['mismatch']
    assert mismatch['logs'] == 2 * len(CI_SEEDS)      # QUICK_NONE_PLANTS: two of three off the YAML
    assert mismatch['none'] >= GOALS['none_accuracy'], mismatch
    assert mismatch['within_5pct'] >= GOALS['none_accuracy'], mismatch
    # the distinctive effects are always named (their shrink is judged by the median: one log's
    # depends on how much of its excitation the effect acts in; seed 50's pivot friction: 33 %)
    for r in result['per_log']:
        if r['truth'] in (['pivot_coulomb_friction'], ['tension_dependent_friction'], ['backlash']):
            assert r['right'], r
