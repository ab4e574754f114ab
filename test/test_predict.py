"""`grip-force predict`: the nominal model over a log, round trip through the file.

By default the prediction is the one `diagnose` compares against (the direction-aware
nominal); `--loading-branch` gives the paper's quasi-static form. Inputs alone suffice.
"""
import numpy as np
import pytest

from grip_force_ros.lab.cli import main as cli_main
from grip_force_ros.lab.cli.predict import predict_log
from grip_force_ros.lab.diagnosis import build_frame, load_decimated
from grip_force_ros.logs import read_log, write_csv
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import load_params_file

CONFIG = 'config/four_pulley_needle_driver.yaml'


def small_log(with_object=True, measured=True):
    """Random inputs at 200 Hz (the analysis rate: the nominal is computed on these rows)."""
    rng = np.random.default_rng(7)
    n = 40
    log = {'t': np.arange(n) * 5e-3, 'current': rng.uniform(-0.1, 0.5, n),
           'motor_angle': rng.uniform(-0.8, 0.1, n), 'wrist_angle': rng.uniform(-1, 1, n),
           'jaw_angle': rng.uniform(0, 1.2, n)}
    if measured:
        log['grip_force'] = rng.uniform(0, 5, n)
    if with_object:
        log['object'] = np.array(['needle', 'rigid', 'tissue', 'free'] * (n // 4))
    return log


def ramp_log(n=120, obj='needle'):
    """A slow current ramp up then down on one object, the wrist still (SI units, 5 ms samples)."""
    t = np.arange(n) * 5e-3
    current = np.interp(t, [0, t[n // 2], t[-1]], [0.0, 0.4, 0.1])
    return {'t': t, 'current': current, 'motor_angle': -0.3 * current, 'wrist_angle': np.zeros(n),
            'jaw_angle': np.full(n, 0.04), 'object': np.full(n, obj)}


def test_loading_branch_round_trips_a_csv(tmp_path):
    log = small_log()
    src, dst = tmp_path / 'in.csv', tmp_path / 'out.csv'
    write_csv(src, log)
    assert cli_main(['predict', '--config', CONFIG, '--input', str(src), '--output', str(dst),
                     '--loading-branch']) == 0
    out = read_log(dst)
    for name in log:                                     # the log's own columns are kept
        if name == 'object':
            assert list(out[name]) == list(log[name])
        else:
            np.testing.assert_allclose(out[name], log[name], rtol=1e-9)
    model = GripForceModel(load_params_file(CONFIG))
    # the model of the values in the file (10 significant digits, predict's input): with the
    # four-pulley driver's 0.6 mm cable the inputs' rounding (<= 5e-11 relative) moved one
    # sample's force by 1.5e-9 relative, more than the output's own rounding
    seen = read_log(src)
    for k in range(len(log['t'])):
        obj = log['object'][k]
        want = model.forward(seen['current'][k], seen['wrist_angle'][k], seen['jaw_angle'][k], obj)
        assert out['grip_force_model'][k] == pytest.approx(float(want.grip_force), rel=1e-9, abs=1e-12)
        if obj in ('needle', 'free'):
            assert out['pull_out_force_model'][k] == pytest.approx(float(want.pull_out_force), rel=1e-9,
                                                                   abs=1e-12)
        else:
            assert np.isnan(out['pull_out_force_model'][k])
    np.testing.assert_allclose(out['jaw_angle_model'],
                               model.jaw_angle(log['motor_angle'], log['wrist_angle'], log['current']),
                               rtol=1e-9, atol=1e-12)
    assert np.all(out['grip_force_model'][log['object'] == 'free'] == 0.0)


def test_default_is_the_nominal_diagnose_compares_against(tmp_path):
    """The same function of the inputs: the diagnosis frame's nominal, to the last digit."""
    params = load_params_file(CONFIG)
    log = small_log()
    out = predict_log(log, params)
    frame = build_frame(log, GripForceModel(params))
    np.testing.assert_array_equal(out['grip_force_model'], frame['nominal'])
    np.testing.assert_array_equal(out['jaw_angle_model'], frame['jaw_model'] + frame['stretch'])
    needle = log['object'] == 'needle'
    np.testing.assert_allclose(out['pull_out_force_model'][needle],
                               (np.sqrt(2) + 1) * params.needle_friction_coefficient
                               * out['grip_force_model'][needle], rtol=1e-12)
    assert np.isnan(out['pull_out_force_model'][log['object'] == 'rigid']).all()
    assert np.all(out['grip_force_model'][log['object'] == 'free'] == 0.0)


def test_direction_aware_equals_the_loading_branch_while_loading_and_sticks_after():
    """Rising current: the paper's forward map; falling: the cable sticks on the pulleys and the jaw
    keeps more force than the loading branch gives, until the unloading edge (1/lambda^2 band)."""
    params = load_params_file('config/paper_needle_driver.yaml')
    log = ramp_log()
    nominal = predict_log(log, params)['grip_force_model']
    loading = predict_log(log, params, loading_branch=True)['grip_force_model']
    rising = slice(5, 59)                # past the 20 ms smoothing of the velocities at the start
    np.testing.assert_allclose(nominal[rising], loading[rising], rtol=1e-3)
    falling = slice(62, 120)
    assert np.all(nominal[falling] > loading[falling])
    # 0.4 A -> 0.1 A is a fall by 75 %, beyond the 1 - lambda^2 = 58 % the band holds: on the
    # unloading edge the jaw keeps 1/lambda^2 of the loading force for the same current
    lam = float(GripForceModel(params).efficiency())
    f = params.drive_resistance_fraction
    unloading_ratio = (1 - f / lam) / (lam * (lam - f))
    assert nominal[-1] / loading[-1] == pytest.approx(unloading_ratio, rel=0.01)


def test_a_log_of_inputs_only_is_predicted(tmp_path):
    log = small_log(measured=False)
    src, dst = tmp_path / 'inputs.csv', tmp_path / 'out.csv'
    write_csv(src, log, measured=False)
    assert cli_main(['predict', '--config', CONFIG, '--input', str(src), '--output', str(dst)]) == 0
    out = read_log(dst, measured=False)
    assert 'grip_force' not in out and np.isfinite(out['grip_force_model']).all()
    with_measured = predict_log(small_log(), load_params_file(CONFIG))
    # the same prediction as with the measured column; the CSV keeps 10 significant digits
    np.testing.assert_allclose(out['grip_force_model'], with_measured['grip_force_model'], rtol=1e-7)


def test_object_column_is_optional_default_needle():
    log = small_log(with_object=False)
    params = load_params_file(CONFIG)
    out = predict_log(log, params, loading_branch=True)
    want = GripForceModel(params).forward(log['current'], log['wrist_angle'], log['jaw_angle'], 'needle')
    np.testing.assert_allclose(out['grip_force_model'], want.grip_force, rtol=1e-12)
    np.testing.assert_allclose(out['pull_out_force_model'], want.pull_out_force, rtol=1e-12)
    for branch in (True, False):
        rigid = predict_log(log, params, default_object='rigid', loading_branch=branch)
        assert not np.allclose(rigid['grip_force_model'],
                               predict_log(log, params, loading_branch=branch)['grip_force_model'])


def test_velocity_columns_are_used_by_the_loading_branch():
    log = small_log(with_object=False)
    log['motor_velocity'] = np.full(len(log['t']), 30.0)
    params = load_params_file(CONFIG)
    moving = predict_log(log, params, loading_branch=True)['grip_force_model']
    still = predict_log(small_log(with_object=False), params, loading_branch=True)['grip_force_model']
    assert np.all(moving <= still) and np.any(moving < still)


def test_predict_reports_a_bad_log(tmp_path, capsys):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,current\n0,0.1\n')
    assert cli_main(['predict', '--config', CONFIG, '--input', str(bad),
                     '--output', str(tmp_path / 'o.csv')]) == 1
    assert 'missing column' in capsys.readouterr().err


def test_torque_logs_get_a_model_torque_column():
    log = small_log(with_object=False)
    log['jaw_torque'] = log.pop('grip_force') * 0.01
    params = load_params_file(CONFIG)
    out = predict_log(log, params, loading_branch=True)
    want = GripForceModel(params).forward(log['current'], log['wrist_angle'], log['jaw_angle'], 'needle')
    np.testing.assert_allclose(out['jaw_torque_model'], want.jaw_torque, rtol=1e-12)
    nominal = predict_log(log, params)
    frame = build_frame(log, GripForceModel(params))
    np.testing.assert_array_equal(nominal['jaw_torque_model'], frame['nominal'])
    assert 'jaw_torque_model' not in predict_log(small_log(), params)


def test_a_full_rate_log_gets_the_analysis_rate_nominal_interpolated():
    """At 1 kHz the nominal is the 200 Hz one (as diagnose computes it), interpolated to the rows."""
    params = load_params_file('config/paper_needle_driver.yaml')
    fine = ramp_log(n=600)
    fine['t'] = np.arange(600) * 1e-3
    out = predict_log(fine, params)['grip_force_model']
    decimated = load_decimated({**fine, 'grip_force': np.zeros(600)}, 200.0)     # what diagnose analyses
    frame = build_frame(decimated, GripForceModel(params))
    np.testing.assert_allclose(np.interp(decimated['t'], fine['t'], out), frame['nominal'], rtol=1e-9,
                               atol=1e-12)


def test_a_bag_without_force_values_is_predicted(tmp_path):
    """A bag whose force topic carries no value (no load cell): not a diagnosis log, but predict reads it."""
    from grip_force_ros.logs import LogError, write_bag
    log = ramp_log()
    bag = write_bag(tmp_path / 'bag', {**log, 'grip_force': np.full(log['t'].size, np.nan)})
    with pytest.raises(LogError, match='no measured column'):
        read_log(bag)
    dst = tmp_path / 'out.csv'
    assert cli_main(['predict', '--config', CONFIG, '--input', str(bag), '--output', str(dst)]) == 0
    out = read_log(dst, measured=False)
    np.testing.assert_allclose(out['grip_force_model'],
                               predict_log(log, load_params_file(CONFIG))['grip_force_model'], rtol=1e-6)
