"""Diagnosis engine: the direction-aware nominal, the effect fits, the JSON contract, the CLI."""
import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grip_force_ros.lab.diagnosis import (EFFECT_NAMES, DiagnosisError, build_frame, capstan_tension,
                                          diagnose, load_decimated, run_diagnosis, write_report)
from grip_force_ros.lab.diagnosis.frame import decimate, hold_where_stuck, play, play_sliding
from grip_force_ros.logs import read_log, write_csv
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import make_params


# --- pieces -----------------------------------------------------------------------------------

def test_capstan_tension_loading_unloading_and_stick():
    lam = 0.6
    f0 = np.r_[np.linspace(0, 100, 50), np.linspace(100, 20, 80), np.linspace(20, 60, 40)]
    tn, _ = capstan_tension(f0, lam)
    np.testing.assert_allclose(tn[:50], lam * f0[:50])                  # loading: Tn = lambda T0
    k = 50 + np.argmax(f0[50:130] < lam * 100 * lam)                      # stuck until T0 = lambda Tn
    assert np.allclose(tn[50:k], lam * 100)                              # stuck: Tn held
    np.testing.assert_allclose(tn[k + 1:130], f0[k + 1:130] / lam)      # unloading: Tn = T0 / lambda
    assert tn[130] == pytest.approx(tn[129])                            # reversal: stuck again


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.0, 200.0), min_size=2, max_size=60), st.floats(0.3, 0.95))
def test_capstan_tension_stays_in_the_friction_band(f0, lam):
    f0 = np.array(f0)
    tn, _ = capstan_tension(f0, lam, np.sin(np.arange(f0.size)) * 30.0)
    assert np.all(tn >= lam * f0 - 1e-9) and np.all(tn <= f0 / lam + 1e-9)


def test_capstan_flags_the_unknown_stuck_tension_after_contact():
    f0 = np.r_[np.zeros(5), np.full(20, 50.0), np.linspace(50, 200, 20)]
    _, uncertain = capstan_tension(f0, 0.7)
    assert uncertain[5:25].all()          # held: could be anywhere in the band
    assert not uncertain[-5:].any()       # rising slipped both extremes onto the loading branch


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=2, max_size=80), st.floats(0.01, 2.0))
def test_play_is_a_direction_with_memory(x, width):
    d = play(np.array(x), width)
    assert np.all(np.abs(d) <= 1 + 1e-9)
    up = play(np.r_[0.0, np.linspace(0, 3 * width, 30)], width)
    assert up[-1] == pytest.approx(1.0)


def test_play_sliding_sticks_for_the_width_after_each_reversal():
    width = 0.1
    x = np.r_[np.linspace(0, 1, 101), np.linspace(1, 0, 101)[1:]]            # 0.01 per sample
    direction, sliding = play_sliding(x, width)
    assert direction[100] == pytest.approx(1.0) and direction[-1] == pytest.approx(-1.0)
    # after the reversal at sample 100 the input must travel the full width (10 samples)
    # before the state moves again: stuck there, sliding on both sides of it
    assert not sliding[101:110].any()
    assert sliding[60:100].all() and sliding[112:].all()
    held = hold_where_stuck(x, sliding)
    assert np.all(held[101:110] == held[100])                              # the value of the last slide
    np.testing.assert_array_equal(held[sliding], x[sliding])


def test_load_decimated_streams_the_same_as_whole(tmp_path):
    rng = np.random.default_rng(1)
    n = 5003
    log = {'t': np.arange(n) * 1e-3, 'current': rng.normal(size=n), 'motor_angle': rng.normal(size=n),
           'wrist_angle': np.zeros(n), 'jaw_angle': np.zeros(n), 'grip_force': rng.normal(size=n)}
    path = write_csv(tmp_path / 'a.csv', log)
    streamed = load_decimated(path, 200.0, chunk_rows=777)
    whole = decimate(read_log(path), 5)
    for k in log:
        np.testing.assert_allclose(streamed[k], whole[k], rtol=1e-9, atol=1e-12)


# --- synthetic logs: the model's own nominal plus one known augmentation -----------------------

PARAMS = make_params()
MODEL = GripForceModel(PARAMS)


def _inputs(seed=0, seconds=60.0, dt=5e-3):
    """Varied inputs at the analysis rate: ramps, holds and steps of current; a slow wrist."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds / dt)) * dt
    knots = np.arange(0, seconds + 2, 1.5)
    levels = rng.uniform(0.05, 0.45, knots.size)
    current = np.interp(t, knots, levels)
    current[(t % 10.0) > 8.5] = -0.05          # the jaw opens now and then: nothing to grip
    wrist = 0.3 * np.sin(2 * np.pi * t / 17.0)
    jaw = np.full(t.size, PARAMS.needle_contact_angle if 'needle_contact_angle' in PARAMS else 0.04)
    log = {'t': t, 'current': current, 'motor_angle': MODEL.motor_angle(jaw, wrist, current),
           'wrist_angle': wrist, 'jaw_angle': jaw, 'object': np.full(t.size, 'needle')}
    # the cable stretches under its tensions: the drum turns that much further for this jaw angle
    stretch = build_frame(_with(log, np.zeros(t.size)), MODEL)['stretch']
    log['motor_angle'] = MODEL.motor_angle(jaw - stretch, wrist, current)
    return log


def _with(log, y, column='grip_force'):
    out = dict(log)
    out[column] = y
    return out


def _nominal(log, measured='grip_force', model=MODEL):
    return build_frame(_with(log, np.zeros(log['t'].size), measured), model)['nominal']


#: The sliding rig's instrument: pulley friction 0.02 (a stick band of a few percent). Its
#: current is the drive torque over the torque per ampere of the loading branch; with the
#: paper's 0.15 the pulleys would hold the cable through every reversal of that current (a band
#: of x2.4), which the generator leaves out.
RIG_PARAMS = make_params({'pulley_friction_coefficient': 0.02})
RIG_MODEL = GripForceModel(RIG_PARAMS)


def test_offset_is_named_with_its_value_and_the_gap_shrinks():
    log = _inputs(1)
    rng = np.random.default_rng(2)
    y = 0.97 * _nominal(log) + 0.4 + rng.normal(0, 0.02, log['t'].size)
    result = diagnose([_with(log, y)], params=PARAMS)
    v = result['verdict']
    assert v['effect'] == 'force_sensor_offset'
    entry = next(r for r in result['ranking'] if r['effect'] == 'force_sensor_offset')
    offset = entry['params']['offset']
    assert offset['value'] == pytest.approx(0.4, abs=0.03)
    assert offset['std'] < 0.05
    # the friction and torque constant refitted beside the offset: their loading gain against the
    # YAML's is the 0.97 of the log
    beside = PARAMS.replace(**entry['reidentified_beside'])
    loading = GripForceModel(beside).torque_coefficients()[0] / MODEL.torque_coefficients()[0]
    assert loading == pytest.approx(0.97, abs=0.01)
    assert v['gap_after'] < 0.2 * v['gap_before']


def test_delay_is_named_and_located_in_time():
    log = _inputs(3)
    nominal = _nominal(log)
    y = np.interp(log['t'] - 0.05, log['t'], nominal) + np.random.default_rng(4).normal(0, 0.02, nominal.size)
    result = diagnose([_with(log, y)], params=PARAMS)
    assert result['verdict']['effect'] == 'sensor_delay'
    delay = next(r for r in result['ranking'] if r['effect'] == 'sensor_delay')['params']['delay']['value']
    assert delay == pytest.approx(0.05, abs=0.016)


def test_tension_dependent_efficiency_is_named():
    log = _inputs(5)
    y = _nominal(log) * (1.0 - 0.5 * log['current']) + np.random.default_rng(6).normal(0, 0.02, log['t'].size)
    result = diagnose([_with(log, y)], params=PARAMS)
    assert result['verdict']['effect'] == 'tension_dependent_friction'
    loss = next(r for r in result['ranking'] if r['effect'] == 'tension_dependent_friction')
    assert loss['params']['efficiency_loss_per_amp']['value'] == pytest.approx(0.5, rel=0.15)


def test_a_gain_and_noise_alone_is_none_and_the_torque_constant_is_refitted():
    log = _inputs(7)
    y = 1.15 * _nominal(log) + np.random.default_rng(8).normal(0, 0.05, log['t'].size)
    result = diagnose([_with(log, y)], params=PARAMS)
    assert result['verdict']['effect'] == 'none'
    assert result['verdict']['gap_after'] == result['verdict']['gap_before']
    # the gain is re-identified (the torque constant, with a little friction: the cable's stretch in
    # the jaw angle stays the YAML's, which pulls the stiffness along), so the force gain left is 1
    calibration = result['calibration']
    assert calibration['force_gain']['value'] == pytest.approx(1.0, abs=0.02)
    assert calibration['parameters_off'][0] == 'torque_constant'
    torque = calibration['parameters']['torque_constant']
    assert 1.08 < torque['fitted'] / torque['yaml'] < 1.2 and torque['unit'] == 'N*m/A'
    assert result['verdict']['gap_before'] < 0.1 * calibration['gap_uncalibrated']


def test_jaw_torque_logs_are_compared_in_newton_metres():
    log = _inputs(9)
    y = _nominal(log, 'jaw_torque') - 0.004 + np.random.default_rng(10).normal(0, 2e-4, log['t'].size)
    result = diagnose([_with(log, y, 'jaw_torque')], params=PARAMS)
    assert result['unit'] == 'N*m' and result['verdict']['unit'] == 'N*m'
    assert result['verdict']['effect'] == 'force_sensor_offset'
    assert result['verdict']['gap_before'] > 0.001
    assert result['verdict']['gap_after'] < 0.3 * result['verdict']['gap_before']


def _sliding_rig(seed, seconds=40.0, dt=5e-3, friction=0.06, load_levels=(0.01, 0.03, 0.05), spring=None):
    """A jaw driven along a sine against a constant load per log, through Coulomb friction
    larger than the load: the current flips sign at every stroke and sticks at reversals.
    ``spring(motor_angle)``: an extra jaw torque (N*m) the drive must supply at each angle."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds / dt)) * dt
    motor = 0.5 - 0.5 * np.cos(2 * np.pi * t / 5.0)
    slide, sliding = play_sliding(motor, 0.01)
    load = float(rng.choice(load_levels))                                  # N*m at the jaw
    per_amp = float(_nominal({**_inputs(0, 1.0), 'current': np.full(200, 1.0)}, 'jaw_torque', RIG_MODEL)[0])
    # the drive torque while sliding: the load plus the friction against the motion; while stuck the
    # current moves across the friction band (here: a ramp between the branches)
    drive = load + friction * slide + (0.0 if spring is None else spring(motor))
    current = drive / per_amp + rng.normal(0, 0.002, t.size)
    # the jaw follows the drum through the model's kinematics (encoder zero 1.7 rad: the stroke
    # opens it from 1.7 to 0.1 rad), the cable rigid: its stretch is left to the calibration
    jaw = 1.7 + RIG_MODEL.jaw_angle(motor, 0.0, current) + rng.normal(0, 1e-3, t.size)
    return {'t': t, 'current': current, 'motor_angle': motor, 'wrist_angle': np.zeros(t.size),
            'jaw_angle': jaw, 'object': np.full(t.size, 'rigid'),
            'jaw_torque': load + rng.normal(0, 5e-4, t.size)}


def test_jaw_torque_rig_is_loaded_through_the_stroke_and_names_pivot_friction():
    """A torque rig whose current changes sign every stroke under a constant load: no sample is a
    load transient, and the friction is named with a direction that follows the motor angle."""
    train = [_sliding_rig(s) for s in (21, 22, 23, 24)]
    test = [_sliding_rig(s) for s in (25, 26)]
    assert (train[0]['current'] < 0).any() and (train[0]['current'] > 0).any()
    frame = build_frame(load_decimated(train[0]), RIG_MODEL)
    assert frame['contact'].all()                                          # loaded although current < 0
    result = diagnose(train, test, params=RIG_PARAMS)
    v = result['verdict']
    assert v['effect'] == 'pivot_coulomb_friction'
    coulomb = next(r for r in result['ranking'] if r['effect'] == 'pivot_coulomb_friction')
    assert coulomb['params']['friction_torque_grid']['direction_state_of'] == 'motor_angle'
    assert coulomb['params']['force_step']['value'] == pytest.approx(-0.06, rel=0.2)
    assert v['gap_after_first'] < 0.4 * v['gap_before']                   # measured 35 -> 11 mN*m


def _spring(motor):
    """A spring over the stroke (N*m at the jaw, motor angle in rad): cable pretension and jaw."""
    return 0.01 - 0.02 * (motor - 0.5) ** 2 / 0.25 + 0.005 * (motor - 0.5) / 0.5


def _stroke_log(seed, spring=None):
    """The sliding rig's motion with the model's own torque, plus ``spring(motor)`` and noise."""
    log = _sliding_rig(seed)
    rng = np.random.default_rng(seed + 100)
    y = _nominal(log, 'jaw_torque', RIG_MODEL) + (0.0 if spring is None else spring(log['motor_angle']))
    return _with(log, y + rng.normal(0, 1e-3, y.size), 'jaw_torque')


def test_position_spring_over_the_stroke_is_named_with_its_shape():
    """A jaw torque that depends on the angle only (cable pretension, jaw spring): named, its
    Legendre coefficients over the training stroke and peak-to-peak recovered; gone -> none."""
    train = [_stroke_log(s, _spring) for s in (21, 22, 23, 24)]
    test = [_stroke_log(s, _spring) for s in (25, 26)]
    result = diagnose(train, test, params=RIG_PARAMS)
    v = result['verdict']
    assert v['effects'] == ['position_spring']
    params = next(r for r in result['ranking'] if r['effect'] == 'position_spring')['params']
    assert params['spring_angle']['value'] == 'motor_angle'
    # the stroke 0..1 rad maps to x = 2 m - 1: spring = 0.01 - 0.02 x^2 + 0.005 x
    # = (0.01 - 0.02/3) P0 + 0.005 P1 - (0.04/3) P2 (N*m)
    for k, want in enumerate((0.01 - 0.02 / 3, 0.005, -0.04 / 3)):
        coef = params[f'spring_legendre_{k}']
        assert coef['value'] == pytest.approx(want, abs=1e-3)
        assert coef['std'] < 1e-3
    x = np.linspace(0.0, 1.0, 101)
    assert params['spring_peak_to_peak']['value'] == pytest.approx(np.ptp(_spring(x)), rel=0.05)
    assert v['gap_after'] < 0.2 * v['gap_before']
    plain = diagnose([_stroke_log(s) for s in (21, 22, 23, 24)], [_stroke_log(s) for s in (25, 26)],
                     params=RIG_PARAMS)
    assert plain['verdict']['effects'] == ['none']


def test_position_spring_is_not_named_without_a_spring():
    """The spring's three columns do not explain friction alone, an offset or noise: on the plain
    sliding rig (friction, no spring) and on grip logs with an offset or only noise it is not named."""
    result = diagnose([_sliding_rig(s) for s in (21, 22, 23, 24)], [_sliding_rig(s) for s in (25, 26)],
                      params=RIG_PARAMS)
    assert 'position_spring' not in result['verdict']['effects']
    log = _inputs(7)
    rng = np.random.default_rng(8)
    noise = diagnose([_with(log, 1.15 * _nominal(log) + rng.normal(0, 0.05, log['t'].size))], params=PARAMS)
    assert noise['verdict']['effects'] == ['none']
    offset = diagnose([_with(log, _nominal(log) + 0.4 + rng.normal(0, 0.02, log['t'].size))], params=PARAMS)
    assert offset['verdict']['effect'] == 'force_sensor_offset'
    assert 'position_spring' not in offset['verdict']['effects']


def test_position_spring_columns_are_legendre_over_the_training_stroke():
    from grip_force_ros.lab.diagnosis.effects import EFFECTS, stroke_coordinate, stroke_range
    motor = np.linspace(0.2, 1.2, 1001)
    assert stroke_range(motor) == pytest.approx((0.205, 1.195), abs=1e-3)
    assert stroke_range(np.full(10, 0.3)) == pytest.approx((0.2995, 0.3005))     # a still angle: no 1/0
    x = stroke_coordinate(motor, (0.2, 1.2))
    assert x[0] == pytest.approx(-1.0) and x[-1] == pytest.approx(1.0)
    n = motor.size
    frame = {'motor': motor, 'jaw': 0.9 * motor, 'nominal': np.ones(n),
             'contact': np.r_[np.zeros(1), np.ones(n - 1)],
             'gain': np.full(n, 3.0), 'stroke': {'motor': (0.2, 1.2), 'jaw': (0.18, 1.08)}}
    design = EFFECTS['position_spring'].build(frame, 'motor_angle')
    assert len(design.force_cols) == 3 and not design.angle_cols
    np.testing.assert_allclose(design.force_cols[0][1:], 3.0)                     # G * P0
    np.testing.assert_allclose(design.force_cols[1][1:], 3.0 * x[1:])             # G * P1
    np.testing.assert_allclose(design.force_cols[2][1:], 3.0 * 0.5 * (3 * x[1:] ** 2 - 1))
    assert all(c[0] == 0.0 for c in design.force_cols)                           # no load, no spring torque
    jaw = EFFECTS['position_spring'].build(frame, 'jaw_angle')
    np.testing.assert_allclose(jaw.force_cols[1][1:], 3.0 * x[1:], atol=1e-12)   # same stroke, mapped alike


def test_json_contract_and_split_by_files():
    a, b = _inputs(11), _inputs(12)
    rng = np.random.default_rng(13)
    logs = [_with(x, _nominal(x) + 0.3 + rng.normal(0, 0.02, x['t'].size)) for x in (a, b)]
    result = diagnose([logs[0]], [logs[1]], params=PARAMS)
    json.dumps(result)                                    # plain JSON
    assert {'effect', 'gap_before', 'gap_after'} <= set(result['verdict'])
    assert result['split']['method'] == 'files'
    names = [r['effect'] for r in result['ranking']]
    assert sorted(names) == sorted(list(EFFECT_NAMES) + ['none'])
    assert all('holdout_rmse' in r for r in result['ranking'])
    assert result['regions'] and all(0.0 <= r['share_of_gap'] <= 1.0 for r in result['regions'])
    # every region dimension partitions the held-out samples: shares add up to one
    by_dim = {}
    for r in result['regions']:
        by_dim.setdefault(r['dimension'], []).append(r['share_of_gap'])
    for dim, shares in by_dim.items():
        if dim != 'direction of motion':
            assert sum(shares) == pytest.approx(1.0, abs=1e-9), dim


def test_time_block_split_is_described():
    log = _inputs(14)
    result = diagnose([_with(log, _nominal(log))], params=PARAMS)
    assert result['split']['method'] == 'time_blocks'
    assert 'held' in result['split']['description']


def test_errors_are_domain_errors():
    log = _inputs(15, seconds=2.0)
    with pytest.raises(DiagnosisError):
        diagnose([], params=PARAMS)
    free = _with({**log, 'object': np.full(log['t'].size, 'free')}, np.zeros(log['t'].size))
    with pytest.raises(DiagnosisError, match='no load'):
        diagnose([free], params=PARAMS)


def test_report_writes_markdown_and_figures(tmp_path):
    log = _inputs(16, seconds=30.0)
    y = _nominal(log) + 0.3 + np.random.default_rng(17).normal(0, 0.02, log['t'].size)
    d = run_diagnosis([_with(log, y)], params=PARAMS)
    path = write_report(d, tmp_path / 'rep')
    text = path.read_text()
    assert 'force_sensor_offset' in text
    for png in ('regions.png', 'residuals.png', 'timeseries.png', 'ranking.png'):
        assert (tmp_path / 'rep' / png).stat().st_size > 10_000
        assert png in text


def test_cli_diagnose_json_and_report(tmp_path, capsys):
    from grip_force_ros.lab.cli import main
    from grip_force_ros.params import load_params_file
    log = _inputs(18, seconds=30.0)
    model = GripForceModel(load_params_file('config/paper_needle_driver.yaml'))
    nominal = build_frame(_with(log, np.zeros(log['t'].size)), model)['nominal']
    y = nominal - 0.25 + np.random.default_rng(19).normal(0, 0.02, log['t'].size)
    path = write_csv(tmp_path / 'run.csv', _with(log, y))
    code = main(['diagnose', str(path), '--config', 'config/paper_needle_driver.yaml', '--json',
                 '--report', str(tmp_path / 'rep'), '--quiet'])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result['verdict']['effect'] == 'force_sensor_offset'
    assert (tmp_path / 'rep' / 'report.md').exists()
    assert main(['diagnose', str(tmp_path / 'missing.csv'), '--config',
                 'config/paper_needle_driver.yaml', '--quiet']) == 1


def test_missing_values_are_left_out_not_propagated():
    log = _inputs(20)
    y = _nominal(log) + 0.3 + np.random.default_rng(21).normal(0, 0.02, log['t'].size)
    y[100:140] = np.nan
    log = {**log, 'current': log['current'].copy()}
    log['current'][500] = np.inf
    result = diagnose([_with(log, y)], params=PARAMS)
    assert np.isfinite(result['verdict']['gap_before'])
    assert result['verdict']['effect'] == 'force_sensor_offset'
