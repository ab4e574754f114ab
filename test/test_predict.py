"""`grip-force predict`: the forward model over a CSV log, round trip through the file."""
import numpy as np
import pytest

from grip_force_ros.cli import main as cli_main
from grip_force_ros.cli.predict import predict_log
from grip_force_ros.logs import read_log, write_csv
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import load_params_file

CONFIG = 'config/four_pulley_needle_driver.yaml'


def small_log(with_object=True):
    rng = np.random.default_rng(7)
    n = 40
    log = {'t': np.arange(n) * 1e-3, 'current': rng.uniform(-0.1, 0.5, n),
           'motor_angle': rng.uniform(-0.8, 0.1, n), 'wrist_angle': rng.uniform(-1, 1, n),
           'jaw_angle': rng.uniform(0, 1.2, n), 'grip_force': rng.uniform(0, 5, n)}
    if with_object:
        log['object'] = np.array(['needle', 'rigid', 'tissue', 'free'] * (n // 4))
    return log


def test_predict_round_trips_a_csv(tmp_path):
    log = small_log()
    src, dst = tmp_path / 'in.csv', tmp_path / 'out.csv'
    write_csv(src, log)
    assert cli_main(['predict', '--config', CONFIG, '--input', str(src), '--output', str(dst)]) == 0
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


def test_object_column_is_optional_default_needle():
    log = small_log(with_object=False)
    params = load_params_file(CONFIG)
    out = predict_log(log, params)
    want = GripForceModel(params).forward(log['current'], log['wrist_angle'], log['jaw_angle'], 'needle')
    np.testing.assert_allclose(out['grip_force_model'], want.grip_force, rtol=1e-12)
    np.testing.assert_allclose(out['pull_out_force_model'], want.pull_out_force, rtol=1e-12)
    rigid = predict_log(log, params, default_object='rigid')
    assert not np.allclose(rigid['grip_force_model'], out['grip_force_model'])


def test_velocity_columns_are_used():
    log = small_log(with_object=False)
    log['motor_velocity'] = np.full(len(log['t']), 30.0)
    params = load_params_file(CONFIG)
    moving = predict_log(log, params)['grip_force_model']
    still = predict_log(small_log(with_object=False), params)['grip_force_model']
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
    out = predict_log(log, params)
    want = GripForceModel(params).forward(log['current'], log['wrist_angle'], log['jaw_angle'], 'needle')
    np.testing.assert_allclose(out['jaw_torque_model'], want.jaw_torque, rtol=1e-12)
    assert 'jaw_torque_model' not in predict_log(small_log(), params)
