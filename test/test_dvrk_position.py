"""The dVRK's jaw position loop (model/dvrk_jaw.py JawPositionLoop) and the simulated PSM's
control modes (sim/psm.py PsmControl), without ROS."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from grip_force_ros.model.dvrk_jaw import JawEffortConversion, JawPositionLoop, SetpointOrigin
from grip_force_ros.params import load_params_file
from grip_force_ros.params.dvrk_tool import strip_comments
from grip_force_ros.sim import InstrumentSim
from grip_force_ros.sim import psm as psm_mod
from grip_force_ros.sim.psm import PsmControl

ROOT = Path(__file__).resolve().parents[1]
VENDOR = ROOT.parent / 'shared' / 'vendor'
MARYLAND = ROOT / 'config' / 'maryland_forceps.yaml'


def _json(path: Path):
    return json.loads(strip_comments(path.read_text()))


@pytest.fixture(scope='module')
def params():
    return load_params_file(MARYLAND).replace(interface='dvrk')


def test_the_jaw_stiffness_is_the_disc_gain_through_the_coupling():
    """K = p / (2 c^2): the jaw entry of C^-T diag(p) C^-1 of the vendored tool and PID files."""
    pid = _json(VENDOR / 'dvrk-psm-source' / 'share' / 'pid' / 'sawControllersPID-PSM.json')
    discs = [j for j in pid['pid'] if j['name'].startswith('disc_')]
    assert {j['p_gain'] for j in discs} == {6.0} and {j['d_gain'] for j in discs} == {0.09}
    assert {j['pid_max_output'] for j in discs} == {-1.0}          # no output limit
    tool = _json(VENDOR / 'dvrk-tools' / 'MARYLAND_BIPOLAR_FORCEPS_400172.json')
    coupling = np.array(tool['coupling']['ActuatorToJointPosition'])
    inv = np.linalg.inv(coupling)
    stiffness = inv.T @ np.diag([6.0] * 4) @ inv                    # N*m/rad, joint space
    loop = JawPositionLoop(JawEffortConversion(coupling[3, 3], 1.949705), 6.0, 0.09, 0.670)
    assert loop.stiffness == pytest.approx(stiffness[3, 3], rel=1e-9)
    assert loop.stiffness == pytest.approx(3.5757, abs=1e-4)
    assert np.abs(stiffness[3, :3]).max() < 1e-9                    # no cross term at the jaw
    assert loop.damping == pytest.approx(0.09 / (2 * 0.915964 ** 2), rel=1e-12)
    # the drive's 0.670 A per disc motor is 0.375 N*m at the jaw
    assert loop.effort_limit == pytest.approx(0.3752, abs=1e-4)


def test_the_loop_current_is_the_conversion_of_its_effort_and_is_drive_limited(params):
    loop = JawPositionLoop.from_params(params)
    # a setpoint 0.02 rad below the jaw closes it: -0.0715 N*m, +0.128 A
    effort = loop.effort(0.0, 0.02, 0.0)
    assert effort == pytest.approx(-0.02 * loop.stiffness)
    assert loop.current(0.0, 0.02, 0.0) == pytest.approx(loop.conversion.current(effort))
    assert loop.current(-0.3, 0.3, 0.0) == pytest.approx(params.dvrk_actuator_max_current)
    assert loop.current(0.6, 0.0, 0.0) == pytest.approx(-params.dvrk_actuator_max_current)
    # damping resists the motion
    assert loop.effort(0.1, 0.1, 1.0) == pytest.approx(-loop.damping)


def test_the_setpoint_gives_the_effort_and_is_bounded(params):
    loop = JawPositionLoop.from_params(params)
    for effort in (-0.19, -0.05, 0.0, 0.03):
        q = loop.setpoint(effort, 0.04, params.jaw_angle_min, params.jaw_angle_max)
        assert loop.effort(q, 0.04, 0.0) == pytest.approx(effort)
    assert loop.setpoint(0.0, 0.3, -1.0, 1.0) == 0.3                 # no effort: where it is
    assert loop.setpoint(-5.0, 0.0, params.jaw_angle_min, 1.0) == params.jaw_angle_min


def _psm(params):
    loop = JawPositionLoop.from_params(params)
    psm = PsmControl(loop, params.jaw_angle_min, params.jaw_angle_max, goal=(0.1, 0.2, 0.1, 0.0))
    sim = InstrumentSim(params, obj='needle', seed=3)
    return psm, sim


def _run(psm, sim, seconds, current=0.0, dt=0.01):
    for _ in range(int(round(seconds / dt))):
        psm.advance(sim, current, dt)


def test_servo_jf_puts_the_whole_arm_in_effort_mode_and_the_arm_drifts(params):
    psm, sim = _psm(params)
    psm.homed()
    assert (psm.space, psm.mode) == (psm_mod.JOINT_SPACE, psm_mod.POSITION_MODE)
    _run(psm, sim, 0.5)
    assert psm.drift() < 1e-12
    psm.jaw_effort()
    assert (psm.space, psm.mode) == (psm_mod.CARTESIAN_SPACE, psm_mod.EFFORT_MODE)
    assert 'whole arm' in psm.take_notice() and psm.take_notice() is None   # said once
    _run(psm, sim, 0.5, current=0.2)
    assert psm.drift() > 0.1                       # the outer pitch sags: the arm is not held
    assert sim.truth()['current_command'] == 0.2   # the jaw takes the effort
    psm.arm_cartesian_position()                   # a teleop servo_cp: held again
    assert psm.mode == psm_mod.POSITION_MODE and psm.mode_changes == 3
    _run(psm, sim, 0.3)
    assert psm.drift() < 1e-4


def test_leaving_effort_mode_resets_the_jaw_effort(params):
    psm, sim = _psm(params)
    psm.homed()
    psm.jaw_effort()
    _run(psm, sim, 1.0, current=0.3)               # squeezing the needle by effort
    squeezed = sim.truth()['grip_force']
    assert squeezed > 5.0
    psm.arm_cartesian_position()                   # servo_cp: position mode, jaw effort 0
    _run(psm, sim, 0.5, current=0.3)               # the held effort is not used any more
    # the drive's current falls to the little the PID needs to hold the jaw where it was; the
    # grip falls with it (the cable's friction holds a part of it: the stick band)
    assert sim.truth()['current'] < 0.05 and sim.truth()['grip_force'] < 0.7 * squeezed


def test_jaw_servo_jp_keeps_the_cartesian_position_mode(params):
    psm, sim = _psm(params)
    psm.homed()
    psm.arm_cartesian_position()
    changes = psm.mode_changes
    for _ in range(100):                           # teleop servo_cp beside our jaw setpoints
        psm.arm_cartesian_position()
        psm.jaw_position(-0.02)
        psm.advance(sim, 0.0, 0.01)
    assert psm.mode_changes == changes and psm.space == psm_mod.CARTESIAN_SPACE
    assert psm.drift() < 1e-12
    # the PID squeezes the needle: its effort at the jaw's angle
    angle = sim.jaw_angle_now()
    truth = sim.truth()
    assert truth['grip_force'] > 5.0
    want = psm.loop.current(-0.02, angle, 0.0)
    assert truth['current'] == pytest.approx(want, rel=0.05)
    # the dVRK clips the setpoint at jaw.qmin
    psm.jaw_position(-5.0)
    assert psm.jaw_setpoint == params.jaw_angle_min


def test_the_pid_runs_at_1_5_khz_inside_a_step(params, monkeypatch):
    psm, sim = _psm(params)
    psm.homed()
    psm.jaw_position(0.3)
    calls = []
    real = sim.jaw_angle_now
    monkeypatch.setattr(sim, 'jaw_angle_now', lambda: calls.append(1) or real())
    _run(psm, sim, 1.0)
    assert len(calls) == pytest.approx(1500, abs=2)
    # it tracks the setpoint, within the static error the friction leaves a P loop
    assert sim.truth()['jaw_angle'] == pytest.approx(0.3, abs=0.03)


def test_position_mode_holds_the_jaw_where_it_is_and_a_cut_stops_the_loop(params):
    psm, sim = _psm(params)
    sim.set_object('free')
    psm.homed()
    start = sim.jaw_angle_now()
    _run(psm, sim, 0.3)
    assert psm.jaw_setpoint == pytest.approx(start)
    assert sim.jaw_angle_now() == pytest.approx(start, abs=1e-3)
    psm.jaw_position(start - 0.2)
    _run(psm, sim, 0.01)
    assert psm.pid_current > 0.0
    psm.cut()
    assert psm.pid_current == 0.0 and math.isnan(psm.jaw_setpoint)
    _run(psm, sim, 0.1)
    assert abs(sim.truth()['current']) < 1e-6


# ---------------------------------------------------------------------- the controller's path
def test_the_controller_setpoint_tracks_in_free_motion_and_squeezes_in_grip(params):
    loop = JawPositionLoop.from_params(params)
    lo, hi = params.jaw_angle_min, params.jaw_angle_max
    # free motion: the jaw target itself (the PSM's loop tracks it), bounded
    assert loop.command_setpoint('free', 0.01, 0.5, 0.3, lo, hi) == 0.3
    assert loop.command_setpoint('free', 0.0, 0.5, 9.0, lo, hi) == hi
    # grip: the setpoint below the jaw whose loop effort at rest is the step's effort
    q = loop.command_setpoint('grip', -0.1, 0.04, 0.04, lo, hi)
    assert q < 0.04 and loop.effort(q, 0.04, 0.0) == pytest.approx(-0.1)
    # safe: an effort ramping to 0 ends at the measured angle, with no jump on the way
    ramp = [loop.command_setpoint('safe', e, 0.04, math.nan, lo, hi)
            for e in np.linspace(-0.1, 0.0, 11)]
    assert ramp[-1] == 0.04 and max(np.abs(np.diff(ramp))) < 0.0031
    # the tool's qmin bounds the squeeze
    assert loop.command_setpoint('grip', -10.0, 0.04, 0.04, lo, hi) == lo


def test_dvrk_command_is_effort_by_default_and_checked(params):
    from grip_force_ros.params import ParameterError, make_params
    assert make_params({}).dvrk_command == 'effort'
    assert params.replace(dvrk_command='effort').dvrk_command == 'effort'
    with pytest.raises(ParameterError):
        params.replace(dvrk_command='torque')


def _offline_grasp(params, command: str, teleop: bool, seconds: float = 4.0):
    """The controller's dvrk path offline at 100 Hz (the node's conversions, no ROS)."""
    from grip_force_ros.control import GripController
    from grip_force_ros.trajectories import needle_grasp
    loop = JawPositionLoop.from_params(params)
    psm, sim = _psm(params)
    psm.homed()
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    traj, period, limit = needle_grasp(), 0.01, params.dvrk_jaw_effort_max
    held, origin = [], SetpointOrigin()
    for k in range(int(round(seconds / period))):
        t = k * period
        m = sim.measure()
        start = origin.update(m.jaw_angle, t)
        inputs.set_master(t, traj.angle(t), t)
        inputs.set_instrument(t, m.wrist_angle, m.jaw_angle, m.jaw_velocity, t)
        inputs.set_actuator(t, m.current, stamp=t)
        inputs.set_force(t, m.grip_force, t)
        out = ctrl.step(t, inputs)
        effort = max(-limit, min(limit, loop.conversion.effort(out.current_command)))
        if command == 'position':
            psm.jaw_position(loop.command_setpoint(str(out.mode), effort, start,
                                                   out.target_jaw_angle, params.jaw_angle_min,
                                                   params.jaw_angle_max))
        else:
            psm.jaw_effort()
        if teleop:
            psm.arm_cartesian_position()     # servo_cp after our command, every period
        psm.advance(sim, out.current_command, period)
        if 2.0 <= t < 2.8:                    # the needle grasp's hold
            held.append((out.target_force, sim.truth()['grip_force']))
    return held, psm


def test_offline_the_position_path_holds_the_needle_with_the_load_cell(params):
    p = params.replace(force_sensor_enabled=True)
    held, psm = _offline_grasp(p, 'position', teleop=True)
    target = held[0][0]
    assert target > 1.0
    assert max(abs(f - target) for _, f in held) < 0.02 * target
    assert psm.effort_entries == 0 and psm.largest_drift < 1e-9


def test_the_setpoint_origin_low_passes_the_jaw_angle():
    origin = SetpointOrigin(0.02)
    assert origin.update(0.04, 0.0) == 0.04                          # the first sample
    assert origin.update(0.05, 0.02) == pytest.approx(0.04 + 0.01 * (1 - math.exp(-1)))
    assert origin.update(1.0, 0.02) == pytest.approx(0.04 + 0.01 * (1 - math.exp(-1)))   # no time


def test_offline_the_effort_path_is_undone_by_teleoperation(params):
    p = params.replace(force_sensor_enabled=True)
    held, psm = _offline_grasp(p, 'effort', teleop=True)
    target = held[0][0]
    assert max(abs(f - target) for _, f in held) > 0.2 * target    # the grip is not held
    assert psm.effort_entries > 300                                 # twice every period
