"""The fault catalogue and its check against the real controller node (issue 5).

ROS-free tests check the catalogue itself (kinds, outcomes, mutators). The ``ros`` tests run
cases against a real in-process controller node over loopback DDS (and the controller
executable for parameter files): a representative subset, one or more per category and
outcome, in CI; the whole catalogue with ``GRIP_FORCE_FAULTCHECK_FULL=1``
(``grip-force faultcheck`` runs it too).
"""
import math
import os

import pytest

from grip_force_ros.faults.catalogue import (OUTCOMES, SOURCES, bad_params_text, burst, catalogue,
                                             duplicate_each, frozen_stamp, rename, resize, select,
                                             set_field, shift_stamp, silence)
from grip_force_ros.params import SPECS

SAMPLE = {'stamp': 100.0, 'name': ['wrist_pitch', 'jaw'], 'position': [0.1, 0.2],
          'velocity': [0.0, 0.3], 'effort': []}

#: One or more cases of every category and outcome; runs in CI (~20 s).
SUBSET = [
    'nan_master_gripper_angle', 'inf_master_gripper_velocity', 'neg_inf_instrument_jaw_angle',
    'nan_actuator_measured_current', 'short_instrument_position', 'missing_joint_jaw',
    'unknown_joint_master', 'jaw_angle_above_range', 'measured_current_out_of_range',
    'master_slightly_below_range', 'master_slightly_above_range', 'master_far_above_range',
    'stamp_backwards_instrument', 'stamp_future_actuator', 'duplicate_instrument',
    'frozen_stamp_actuator', 'burst_10x_all', 'silence_master', 'silence_instrument',
    'silence_actuator', 'sim_restart', 'sim_restart_clock_reset', 'silence_force_sensor',
    'nan_force_sensor', 'set_max_current_read_only', 'set_negative_force_kp', 'set_wrong_type',
    'set_atomic_mixed', 'set_grip_force_max_above_hardware', 'file_missing_parameters_section',
    'file_not_yaml', 'file_missing_hardware_limit', 'file_wrong_type', 'file_out_of_range',
    'file_unknown_key', 'file_inconsistent', 'file_nan_value',
]


# ---------------------------------------------------------------------------- catalogue
def test_catalogue_has_25_kinds_with_defined_outcomes():
    cases = catalogue()
    assert len(cases) >= 25
    assert len({c.name for c in cases}) == len(cases)
    assert {c.outcome for c in cases} == set(OUTCOMES)
    categories = {c.category for c in cases}
    for needed in ('non-finite', 'array length', 'joint names', 'range', 'master range',
                   'timestamps', 'duplicates', 'burst', 'silence', 'sim restart',
                   'runtime parameters', 'parameter file'):
        assert needed in categories, needed
    for c in cases:
        assert c.description
        if c.kind in ('message', 'restart'):
            assert c.source in SOURCES + ('all', 'restart'), c.name
            assert c.ticks > 0
        if c.outcome in ('reject_safe', 'stale_safe', 'clamp', 'refuse_set', 'refuse_start'):
            assert c.reason, f'{c.name}: an outcome with a reason needs the expected reason'
    # silence on every input topic, NaN and inf in every field the controller reads
    silenced = {c.source for c in cases if c.category == 'silence'}
    assert silenced == set(SOURCES)
    values = {c.name.split('_')[0] for c in cases if c.category == 'non-finite'}
    assert {'nan', 'inf', 'neg'} <= values


def test_subset_names_exist():
    names = {c.name for c in catalogue()}
    assert set(SUBSET) <= names
    subset = [c for c in catalogue() if c.name in SUBSET]
    assert {c.category for c in subset} == {c.category for c in catalogue()}
    assert {c.outcome for c in subset} == set(OUTCOMES)


def test_mutators():
    assert set_field('position', 1, math.nan)(SAMPLE, 0)[0]['position'][1] != SAMPLE['position'][1]
    assert SAMPLE['position'] == [0.1, 0.2]          # the good sample is not modified
    assert resize('position', 1)(SAMPLE, 0)[0]['position'] == [0.1]
    assert resize('effort', 2)(SAMPLE, 0)[0]['effort'] == [0.0, 0.0]
    renamed = rename(['wrist_pitch', 'jaw', 'elbow'])(SAMPLE, 0)[0]
    assert renamed['name'][-1] == 'elbow' and len(renamed['position']) == 3
    assert shift_stamp(-1.0)(SAMPLE, 3)[0]['stamp'] == 99.0
    assert len(duplicate_each(3)(SAMPLE, 0)) == 3
    assert silence()(SAMPLE, 0) == []
    stamps = [s['stamp'] for s in burst(10)(SAMPLE, 0)]
    assert len(stamps) == 10 and stamps == sorted(stamps) and len(set(stamps)) == 10
    assert max(stamps) == pytest.approx(100.0) and min(stamps) > 99.999
    frozen = frozen_stamp()
    assert [frozen(dict(SAMPLE, stamp=t), k)[0]['stamp'] for k, t in enumerate((1.0, 2.0, 3.0))] \
        == [1.0, 1.0, 1.0]


def test_select():
    assert [c.name for c in select(catalogue(), ['silence_master'])] == ['silence_master']
    assert len(select(catalogue(), ['parameter file'])) == len(
        [c for c in catalogue() if c.kind == 'param_file'])
    assert [c.name for c in select(catalogue(), None)] == [c.name for c in catalogue()]


def test_bad_params_text():
    import yaml
    base = {'max_current': 0.5, 'guide_pulley_radii': (0.003, 0.003)}
    doc = yaml.safe_load(bad_params_text(base, {'max_current': None, 'force_kp': -1.0}))
    values = doc['/**']['ros__parameters']
    assert 'max_current' not in values and values['force_kp'] == -1.0
    assert values['guide_pulley_radii'] == [0.003, 0.003]
    assert bad_params_text(base, {'__text__': 'x'}) == 'x'


def test_runtime_parameter_cases_name_schema_parameters():
    for c in catalogue():
        if c.kind == 'param_set':
            for name in c.params:
                assert name in SPECS, name
            if 'read_only' in c.name:
                assert all(SPECS[n].read_only for n in c.params)


# ---------------------------------------------------------------------------- real nodes
def _assert_report(report, n_cases):
    failures = '\n'.join(f"{f['name']}: {f['why']}" for f in report['failures'])
    assert report['cases'] == n_cases
    assert report['crashes'] == 0, failures
    assert report['limit_violations'] == 0, failures
    assert report['passed'] == report['cases'], failures


@pytest.mark.ros
def test_faultcheck_subset_on_real_nodes():
    from grip_force_ros.faults.runner import run_faultcheck
    cases = [c for c in catalogue() if c.name in SUBSET]
    report = run_faultcheck(cases)
    _assert_report(report, len(cases))
    by_name = {d['name']: d for d in report['details']}
    # the watchdog cases trip within two control periods after the timeout
    for name in ('silence_master', 'silence_instrument', 'silence_actuator'):
        assert 1 <= by_name[name]['controller_steps_after_timeout'] <= 2, by_name[name]
    # rejected samples were counted and resumed bumplessly
    assert by_name['nan_master_gripper_angle']['rejected_samples'] > 0
    assert by_name['burst_10x_all']['rejected_samples'] == 0


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.skipif(os.environ.get('GRIP_FORCE_FAULTCHECK_FULL') != '1',
                    reason='the whole catalogue (~1 min): GRIP_FORCE_FAULTCHECK_FULL=1')
def test_faultcheck_full_catalogue():
    from grip_force_ros.faults.runner import run_faultcheck
    report = run_faultcheck()
    _assert_report(report, len(catalogue()))
