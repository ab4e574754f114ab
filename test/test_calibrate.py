"""grip-force calibrate: the fit recovers a known friction offset of a simulated plant (no ROS)."""
import json

import numpy as np
import pytest

from grip_force_ros.lab.cli import main as cli_main
from grip_force_ros.params.files import instrument_path
from grip_force_ros.identify.calibration import (CalibrationError, calibrated_yaml, fit_instrument,
                                                 steady_plateaus)
from grip_force_ros.logs import write_csv
from grip_force_ros.params import load_params_file, read_params_yaml
from grip_force_ros.sim import simulate


def staircase(levels=(0.1, 0.2, 0.3, 0.4), ramp=300, hold=500, rest=300):
    """Current profile (A, 1 ms samples): slow ramps up to each level, then held."""
    parts, last = [np.zeros(rest)], 0.0
    for level in levels:
        parts += [np.linspace(last, level, ramp), np.full(hold, level)]
        last = level
    parts.append(np.linspace(last, 0.0, ramp))   # release: must not spoil the fit
    return np.concatenate(parts)


def sim_log(config, friction_scale, stiffness_scale, seed=3):
    shipped = load_params_file(instrument_path(config))
    plant = shipped.replace(friction_scale=friction_scale, stiffness_scale=stiffness_scale)
    return shipped, simulate(plant, staircase(), 1e-3, obj='needle', seed=seed)


@pytest.mark.parametrize('config,friction_scale,stiffness_scale', [
    ('paper_needle_driver', 1.2, 0.8),
    ('long_jaw_grasper', 0.8, 1.2),
    ('four_pulley_needle_driver', 1.2, 0.8),
])
def test_fit_recovers_the_plant_friction(config, friction_scale, stiffness_scale):
    shipped, log = sim_log(config, friction_scale, stiffness_scale)
    truth = shipped.pulley_friction_coefficient * friction_scale
    result = fit_instrument(shipped, log)
    fitted = result.values['pulley_friction_coefficient']
    assert fitted == pytest.approx(truth, abs=0.004)
    assert result.before['pulley_friction_coefficient'] == shipped.pulley_friction_coefficient
    # the fit explains the load cell far better than the shipped YAML
    assert result.residual_rms < 0.03                      # N
    assert result.residual_rms_before > 5 * result.residual_rms
    assert 0 < result.std_errors['pulley_friction_coefficient'] < 0.01
    assert len(result.force_levels) >= 4       # distinct levels (ramps add some)


def test_plateaus_are_the_loading_branch_only():
    _, log = sim_log('paper_needle_driver', 1.0, 1.0)
    plateaus = steady_plateaus(log)
    peak_time = log['t'][np.argmax(log['grip_force'])]
    assert np.all(plateaus.t <= peak_time + 0.1)
    assert np.all(np.diff(plateaus.grip_force) > -0.1)      # a staircase up
    assert plateaus.grip_force.min() > 0.3


def test_one_force_level_or_no_contact_is_refused():
    shipped = load_params_file(instrument_path('paper_needle_driver'))
    log = simulate(shipped, np.concatenate([np.zeros(200), np.full(800, 0.2)]), 1e-3, seed=1)
    with pytest.raises(CalibrationError, match='one force level'):
        fit_instrument(shipped, log)
    free = simulate(shipped, staircase(), 1e-3, obj='free', seed=1)
    with pytest.raises(CalibrationError, match='no steady plateau'):
        fit_instrument(shipped, free)
    with pytest.raises(CalibrationError, match='cannot fit'):
        fit_instrument(shipped, log, fit=['drum_radius'])
    with pytest.raises(CalibrationError, match='lacks column'):
        fit_instrument(shipped, {'t': log['t'], 'current': log['current']})


def test_cli_writes_a_valid_calibrated_yaml(tmp_path, capsys):
    shipped, log = sim_log('paper_needle_driver', 1.2, 0.8)
    csv = write_csv(tmp_path / 'calib.csv', log)
    out = tmp_path / 'paper_calibrated.yaml'
    config = instrument_path('paper_needle_driver')
    assert cli_main(['calibrate', '--config', str(config), '--log', str(csv),
                     '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'pulley_friction_coefficient: 0.18' in printed and str(out) in printed
    text = out.read_text()
    header = [line for line in text.splitlines() if line.startswith('#')]
    assert any('calib.csv' in line for line in header)
    assert any('Fitted pulley_friction_coefficient: 0.18' in line for line in header)
    assert any('Residual rms' in line for line in header)
    calibrated = load_params_file(out)                       # valid against the schema
    assert calibrated.pulley_friction_coefficient == pytest.approx(0.18, abs=0.004)
    # every other key is kept as shipped
    before, after = read_params_yaml(config), read_params_yaml(out)
    assert set(before) == set(after)
    assert {k: v for k, v in before.items() if k != 'pulley_friction_coefficient'} == \
        {k: (tuple(v) if isinstance(v, list) and isinstance(before[k], tuple) else v)
         for k, v in after.items() if k != 'pulley_friction_coefficient'}


def test_cli_reports_a_bad_log(tmp_path, capsys):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,current\n0,0\n0.001,0\n')
    assert cli_main(['calibrate', '--config', 'paper_needle_driver', '--log', str(bad)]) == 1
    assert 'error:' in capsys.readouterr().err


def test_header_names_source_and_uncertainty():
    shipped, log = sim_log('long_jaw_grasper', 0.8, 1.2)
    result = fit_instrument(shipped, log)
    text = calibrated_yaml(instrument_path('long_jaw_grasper'), result, 'runs/calib.mcap')
    assert text.startswith('# Calibrated from long_jaw_grasper.yaml')
    assert '# Source log: runs/calib.mcap' in text and '+/-' in text


def test_cli_reads_a_rosbag2_mcap_log(tmp_path, capsys):
    from grip_force_ros.logs import write_bag
    _, log = sim_log('four_pulley_needle_driver', 0.8, 1.2)
    bag = write_bag(tmp_path / 'calib_bag', log)
    out = tmp_path / 'cal.yaml'
    assert cli_main(['calibrate', '--config', 'four_pulley_needle_driver', '--log', str(bag),
                     '--out', str(out), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['fitted']['pulley_friction_coefficient'] == pytest.approx(0.096, abs=0.004)
    assert load_params_file(out).pulley_friction_coefficient == pytest.approx(0.096, abs=0.004)
