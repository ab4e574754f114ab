"""The procedures the controller's ~/calibrate and ~/tare run, without ROS (identify/procedures.py)."""
import math

import numpy as np
import pytest

from grip_force_ros.identify import fit_instrument
from grip_force_ros.identify.procedures import (CALIBRATION_FIRST_RAMP, CALIBRATION_HOLD,
                                                CALIBRATION_RAMP, CALIBRATION_SHARES,
                                                CurrentStaircase, GraspRecording, SensorZero,
                                                calibration_current)
from grip_force_ros.logs import read_log
from grip_force_ros.params import load_params_file
from grip_force_ros.params.files import instrument_path
from grip_force_ros.sim import simulate


def test_staircase_corners_levels_and_end():
    stairs = CurrentStaircase(0.4, start=-0.02)
    n = len(CALIBRATION_SHARES)
    assert stairs.levels == pytest.approx([s * 0.4 for s in CALIBRATION_SHARES])
    assert stairs.duration == pytest.approx(CALIBRATION_FIRST_RAMP + (n - 1) * CALIBRATION_RAMP
                                            + n * CALIBRATION_HOLD + CALIBRATION_RAMP)
    assert stairs.current(0.0) == -0.02 and stairs.current(-1.0) == -0.02
    assert stairs.current(stairs.duration) == 0.0 and stairs.current(stairs.duration + 5) == 0.0
    # each level is held for CALIBRATION_HOLD after its ramp
    t = CALIBRATION_FIRST_RAMP
    for level in stairs.levels:
        for dt in (0.0, CALIBRATION_HOLD / 2, CALIBRATION_HOLD - 1e-9):
            assert stairs.current(t + dt) == pytest.approx(level)
        t += CALIBRATION_HOLD + CALIBRATION_RAMP
    assert stairs.hold_end == pytest.approx(t - CALIBRATION_RAMP)


def test_staircase_is_continuous_and_slow():
    stairs = CurrentStaircase(0.5, start=0.1)
    t = np.arange(0.0, stairs.duration + 0.1, 1e-4)
    i = np.array([stairs.current(x) for x in t])
    rate = np.abs(np.diff(i)) / 1e-4
    # fastest ramp: 0.25 of 0.5 A in 0.3 s (0.42 A/s), and 0.5 A down in 0.3 s (1.7 A/s);
    # far below the instruments' max_current_slew (100 A/s), so the slew limit never acts
    assert rate.max() <= 0.5 / CALIBRATION_RAMP + 1e-9
    assert np.all(i[t >= stairs.duration] == 0.0)


@pytest.mark.parametrize('bad', [dict(top=0.0), dict(top=math.nan), dict(top=0.3, hold=0.0),
                                 dict(top=0.3, shares=(0.5, 0.25)), dict(top=0.3, shares=(0.5, 1.2)),
                                 dict(top=0.3, shares=())])
def test_staircase_refuses_bad_arguments(bad):
    with pytest.raises(ValueError):
        CurrentStaircase(**bad)


@pytest.mark.parametrize('config,friction_scale', [('paper_needle_driver', 0.8),
                                                   ('long_jaw_grasper', 1.2)])
def test_staircase_recording_calibrates_the_plant(tmp_path, config, friction_scale):
    """The grasp ~/calibrate drives, recorded as it writes it, fits the plant's friction."""
    shipped = load_params_file(instrument_path(config))
    plant = shipped.replace(friction_scale=friction_scale)
    top = calibration_current(shipped)
    assert top <= shipped.max_current
    stairs = CurrentStaircase(top)
    dt = 1e-3
    current = np.array([stairs.current(k * dt) for k in range(int(stairs.duration / dt))])
    log = simulate(plant, current, dt, obj='needle', seed=5)
    recording = GraspRecording(tmp_path / 'grasp.csv')
    for k in range(len(log['t'])):
        if log['t'][k] <= stairs.hold_end:
            recording.add(log['t'][k], log['current'][k], log['motor_angle'][k],
                          log['wrist_angle'][k], log['jaw_angle'][k], log['grip_force'][k])
    recording.close()
    read = read_log(recording.path)
    assert len(read['t']) == recording.rows > 3000
    result = fit_instrument(shipped, read)
    # as test_calibrate.py: the plateaus of a noisy 1 kHz sim fix mu to a few thousandths
    truth = shipped.pulley_friction_coefficient * friction_scale
    assert result.values['pulley_friction_coefficient'] == pytest.approx(truth, abs=0.004)
    assert len(result.force_levels) >= len(CALIBRATION_SHARES)


def test_recording_keeps_time_rising(tmp_path):
    recording = GraspRecording(tmp_path / 'r.csv')
    for t in (0.0, 0.001, 0.001, 0.0005, 0.002):
        recording.add(t, 0.1, 0.0, 0.0, 0.5, 1.0)
    recording.close()
    assert recording.rows == 3
    assert list(read_log(recording.path)['t']) == [0.0, 0.001, 0.002]


def test_sensor_zero_means():
    rng = np.random.default_rng(7)
    zero = SensorZero(0.2)
    sigma_i, sigma_f, n = 0.002, 0.02, 0
    for k in range(1000):
        t = k * 1e-3
        done = zero.add(t, 0.05 + 0.013 + rng.normal(0, sigma_i), 0.05, 0.3 + rng.normal(0, sigma_f))
        n += 1
        if done:
            break
    assert zero.samples == n == 201          # 0 .. 0.2 s at 1 kHz
    # within 4 standard errors of the mean (sigma / sqrt(n)) of the known offsets
    assert zero.current_offset == pytest.approx(0.013, abs=4 * sigma_i / math.sqrt(n))
    assert zero.force_offset == pytest.approx(0.3, abs=4 * sigma_f / math.sqrt(n))


def test_sensor_zero_without_load_cell():
    zero = SensorZero(0.01)
    assert not zero.add(0.0, 0.1, 0.1, None)
    assert zero.add(0.02, 0.12, 0.1, None)
    assert zero.current_offset == pytest.approx(0.01)
    assert math.isnan(zero.force_offset)
    with pytest.raises(ValueError):
        SensorZero(0.0)
