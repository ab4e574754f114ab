"""Closed loop without ROS: GripController on the simulated instrument (sim/plant.py).

The plant is not the controller's model: the sim has stick-slip pulley friction, elastic
cables, a current loop, contact dynamics and sensor noise.
"""
import numpy as np
import pytest

from grip_force_ros.lab.closed_loop import ALL_SOURCES, closed_loop_step
from grip_force_ros.control import GripController
from grip_force_ros.params import load_params_file
from grip_force_ros.sim.plant import InstrumentSim
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PERIOD = 1e-3


def grasp(params, obj='needle', seconds=1.5, plant_changes=None, stale_from=None):
    """Master closes 0.8 -> 0 rad in 0.5 s, holds, opens from 1.0 s. Returns a log array."""
    sim = InstrumentSim(params.replace(**(plant_changes or {})), obj=obj, seed=3)
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    rows = []
    for k in range(int(seconds / PERIOD)):
        t = k * PERIOD
        master = max(0.0, 0.8 - 1.6 * t) if t < 1.0 else min(0.8, 2.0 * (t - 1.0))
        stale = stale_from is not None and t >= stale_from
        m, out = closed_loop_step(sim, ctrl, inputs, t, master, PERIOD,
                                  sources=ALL_SOURCES - {'instrument'} if stale else ALL_SOURCES)
        rows.append((t, master, m.jaw_angle, out.target_jaw_angle, out.target_force,
                     m.grip_force, out.current_command, {'free': 0, 'grip': 1, 'safe': 2}[out.mode]))
    return np.array(rows)


@pytest.fixture(scope='module')
def paper():
    return load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')


@pytest.mark.parametrize('sensor', [False, True], ids=['model estimate', 'load cell'])
def test_needle_grasp_holds_the_target_force(paper, sensor):
    log = grasp(paper.replace(force_sensor_enabled=sensor))
    hold = log[(log[:, 0] > 0.7) & (log[:, 0] < 1.0)]
    assert np.all(hold[:, 7] == 1)                                         # gripping
    target = hold[:, 4].mean()
    assert target == pytest.approx(min(paper.grip_force_max, paper.max_grip_force))
    assert hold[:, 5].mean() == pytest.approx(target, rel=0.03)           # load cell
    free = log[(log[:, 0] > 0.05) & (log[:, 0] < 0.3)]
    # jaw follows (rad): at 1 kHz states the jaw gains are the 1 kHz design (the schedule leaves
    # them as designed at gain_design_rate; crossover ~29 Hz). While the master closes at 1.6
    # rad/s the drum damping (6e-3 N*m*s/rad at ~1 rad/s, 3.4 mA through 1.77 N*m/A) needs an
    # error of 3.4 mA / jaw_kp 0.369 A/rad = 0.009 rad and the sim's stick-slip pulleys about as
    # much again (measured 0.015 rad rms, seed 3); 0.03 rad is the 1 kHz design's bound (gains
    # designed for 100 Hz only would need 0.07)
    assert np.sqrt(np.mean((free[:, 2] - free[:, 3]) ** 2)) < 0.03
    assert np.all(log[-50:, 7] == 0)                                       # released: free again
    assert np.max(np.abs(np.diff(log[:, 6]))) <= paper.max_current_slew * PERIOD + 1e-12


def test_load_cell_feedback_corrects_a_plant_that_differs_from_the_yaml(paper):
    """Friction 20% above and cable stiffness 20% below the YAML, the controller not told."""
    off = {'friction_scale': 1.2, 'stiffness_scale': 0.8}
    with_sensor = grasp(paper.replace(force_sensor_enabled=True), plant_changes=off)
    without = grasp(paper, plant_changes=off)
    window = (with_sensor[:, 0] > 0.7) & (with_sensor[:, 0] < 1.0)
    target = with_sensor[window, 4].mean()
    err_sensor = abs(with_sensor[window, 5].mean() - target) / target
    err_model = abs(without[window, 5].mean() - target) / target
    assert err_sensor < 0.03
    assert err_sensor < err_model


def test_stale_joint_states_ramp_the_current_down_in_the_loop(paper):
    log = grasp(paper, seconds=0.9, stale_from=0.7)
    after = log[log[:, 0] >= 0.7]
    first_safe = after[after[:, 7] == 2][0, 0]
    assert first_safe - (0.7 - PERIOD) <= paper.watchdog_timeout + 2 * PERIOD
    assert after[-1, 6] == 0.0
