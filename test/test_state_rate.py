"""Rate independence: the controller steps on the measured time between states.

ROS-free: the real GripController on the simulated instrument with states at 100 .. 1500 Hz
(lab/bench/state_rate.py, seeded sensor noise and +-10 % state-time jitter); the node refuses to
start outside the range the gains are shown stable for. The measured table: docs/control.md.
"""
import subprocess
import sys
from pathlib import Path

import pytest

from grip_force_ros.lab.bench.state_rate import offline_grasp
from grip_force_ros.control import GripController
from grip_force_ros.params import ParameterError, load_params_file, make_params
from grip_force_ros.params.controller import STATE_RATE_MAX, STATE_RATE_MIN

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'paper_needle_driver.yaml'


@pytest.mark.parametrize('rate', [STATE_RATE_MIN, 1000.0, STATE_RATE_MAX])
def test_needle_grasp_holds_at_the_ends_of_the_range(rate):
    run = offline_grasp(load_params_file(CONFIG), rate, seed=1)
    m = run['metrics']
    assert run['safe_steps'] == 0
    # measured (docs/control.md): |hold error| <= 1.3 % (worst of 3 seeds), overshoot <= 3.9 %
    # (100 Hz); 5 % / 6 % leave room for a seed; an unstable loop (the 1 kHz-only gains run
    # unscheduled at 100 Hz) gave -8 % and 91 %
    assert abs(m['hold_error_rel']) < 0.05, m
    assert m['overshoot'] < 0.06, m
    # settled to 5 % for good within 0.2 s of the hold; at 100 Hz the sensorless estimate can
    # switch stick-band branch once during the hold (the current jumps ~0.1 A to the other
    # edge, one ~40 ms dip to -6.6 %: seed 1 settles at 0.78 s; over seeds 0-9, 3 of 10 had
    # such a switch with the schedule, 1 of 10 with the slow 100 Hz-only gains,
    # docs/control.md): 1 s still fails a loop that hunts through the hold
    assert m['settling_time'] < (0.2 if rate >= 1000.0 else 1.0), m


def test_the_same_time_gives_the_same_integral_at_any_rate():
    """One second of a constant error integrates to ki * e * 1 s at 100 and at 1000 Hz steps."""
    from grip_force_ros.control import PID
    out = {}
    for rate in (100.0, 1000.0):
        pid = PID(kp=0.0, ki=2.0, kd=0.0, derivative_filter_time=1e-3, period=1e-3,
                  integral_limit=1e9)
        for _ in range(int(rate)):
            u = pid.update(0.5, 0.0, 1.0 / rate)
            pid.track(u, u, 1.0 / rate)
        out[rate] = pid.integral
    assert out[100.0] == pytest.approx(1.0, rel=1e-9) and out[1000.0] == pytest.approx(1.0, rel=1e-9)


def test_a_step_interval_beyond_the_watchdog_is_a_fault_not_an_integration():
    params = make_params({'expected_state_rate': 100.0})
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    t = 0.0
    for _ in range(100):                          # 1 s of grip at 100 Hz
        t += 0.01
        inputs.set_master(t, 0.0)
        inputs.set_instrument(t, 0.0, 0.04, 0.0)
        inputs.set_actuator(t, ctrl.command)
        out = ctrl.step(t, inputs)
    assert out.mode == 'grip'
    integral = ctrl.force_pid.integral
    t += 0.2                                      # the controller stalled 200 ms; fresh inputs
    inputs.set_master(t, 0.0)
    inputs.set_instrument(t, 0.0, 0.04, 0.0)
    inputs.set_actuator(t, ctrl.command)
    out = ctrl.step(t, inputs)
    assert out.mode == 'safe' and any('step interval 200.0 ms' in r for r in out.reasons)
    assert ctrl.force_pid.integral == integral    # nothing integrated over the stall
    assert ctrl.last_dt == pytest.approx(0.01)    # the safe ramp steps one nominal period
    out = ctrl.step(t + 0.01, inputs)
    assert out.mode == 'grip'                     # and the next step resumes
    backwards = ctrl.step(t, inputs)
    assert backwards.mode == 'safe' and any('backwards' in r for r in backwards.reasons)


@pytest.mark.parametrize('rate', [STATE_RATE_MIN / 2, STATE_RATE_MAX * 2])
def test_outside_the_range_the_parameters_are_refused(rate):
    with pytest.raises(ParameterError, match='expected_state_rate'):
        make_params({'expected_state_rate': rate})


def test_the_watchdog_must_cover_two_state_periods():
    with pytest.raises(ParameterError, match='2 state periods'):
        make_params({'expected_state_rate': 100.0, 'watchdog_timeout': 0.015})
    assert make_params({'expected_state_rate': 100.0}).watchdog_timeout == 0.03


def test_the_node_refuses_to_start_outside_the_range():
    done = subprocess.run([sys.executable, '-m', 'grip_force_ros.nodes.controller', '--ros-args',
                           '--params-file', str(CONFIG), '-p', 'expected_state_rate:=50.0'],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    line = [ln for ln in done.stderr.splitlines() if 'refusing to start' in ln]
    assert line and 'expected_state_rate' in line[0] and '[100.0, 1500.0]' in line[0], done.stderr


@pytest.mark.parametrize('drive', ['cut', 'held'])
def test_after_a_stall_the_command_restarts_from_the_measured_current(drive):
    """A drive with a command timeout cut the current during the stall (the sim), a dVRK held
    it: the controller continues from what the actuator measures, so the drive sees no step."""
    params = make_params({'expected_state_rate': 100.0})
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    t = 0.0
    for _ in range(100):
        t += 0.01
        inputs.set_master(t, 0.0)
        inputs.set_instrument(t, 0.0, 0.04, 0.0)
        inputs.set_actuator(t, ctrl.command)
        out = ctrl.step(t, inputs)
    held = ctrl.command
    # the grip current: the scheduled loop settles at 0.19 A inside the stick band (estimate
    # 4.01 N) within 0.4 s; the slow 100 Hz-only gains were still drifting through the band
    assert out.mode == 'grip' and held > 0.15
    t += 0.2
    measured = 0.0 if drive == 'cut' else held
    inputs.set_master(t, 0.0)
    inputs.set_instrument(t, 0.0, 0.04, 0.0)
    inputs.set_actuator(t, measured)
    out = ctrl.step(t, inputs)
    step = params.max_current_slew * 0.01            # the safe ramp's one nominal period
    assert out.mode == 'safe'
    assert out.current_command == pytest.approx(max(measured - step, 0.0))
