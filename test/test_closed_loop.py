"""The offline closed loop's one period (grip_force_ros/lab/closed_loop.py)."""
import math

import pytest

from grip_force_ros.lab.closed_loop import ALL_SOURCES, NO_FORCE_SENSOR, NO_SOURCES, closed_loop_step
from grip_force_ros.control import SOURCES, GripController
from grip_force_ros.params import load_params_file
from grip_force_ros.params.files import instrument_path
from grip_force_ros.sim.plant import InstrumentSim

PERIOD = 1e-3


@pytest.fixture(scope='module')
def params():
    return load_params_file(instrument_path('paper_needle_driver'))


def pair(params, seed=3):
    sim = InstrumentSim(params, obj='needle', seed=seed)
    ctrl = GripController(params)
    return sim, ctrl, ctrl.new_inputs()


def master(t):
    """Close 0.8 -> 0 rad in 0.5 s, then hold (rad)."""
    return max(0.0, 0.8 - 1.6 * t)


@pytest.mark.parametrize('stamped', [False, True])
def test_one_period_is_the_nodes_sequence_written_out(params, stamped):
    """The step does what the nodes do, in their order: sample, the four inputs (with the
    source stamp when asked), one control step, the command for one period. The same sim
    seed and controller written out by hand give the same bits for 0.8 s of a grasp."""
    sim_a, ctrl_a, in_a = pair(params)
    sim_b, ctrl_b, in_b = pair(params)
    for k in range(800):
        t = k * PERIOD
        sample, out = closed_loop_step(sim_a, ctrl_a, in_a, t, master(t), PERIOD, stamped=stamped)
        stamp = t if stamped else math.nan
        m = sim_b.measure()
        in_b.set_master(t, master(t), stamp)
        in_b.set_instrument(t, m.wrist_angle, m.jaw_angle, m.jaw_velocity, stamp)
        in_b.set_actuator(t, m.current, m.motor_angle, m.motor_velocity, stamp)
        in_b.set_force(t, m.grip_force, stamp)
        ref = ctrl_b.step(t, in_b)
        sim_b.step(ref.current_command, PERIOD)
        assert sample.t == pytest.approx(t, abs=1e-12)      # the sample before the sim stepped
        assert sample == m and out == ref
    assert out.mode == 'grip' and out.target_force > 1.0    # the grasp got to the needle
    assert sim_a.truth() == sim_b.truth()
    if stamped:
        assert all(getattr(in_a, f'{s}_stamp') == pytest.approx(0.799) for s in SOURCES)
    else:
        assert all(math.isnan(getattr(in_a, f'{s}_stamp')) for s in SOURCES)


def test_a_source_left_out_keeps_its_last_value_and_time(params):
    """Without the force sensor the force input stays at its start (never received); a
    blackout leaves every input at the last period it arrived, and the controller's
    watchdog sees the age grow into the safe state."""
    sim, ctrl, inputs = pair(params)
    for k in range(300):
        closed_loop_step(sim, ctrl, inputs, k * PERIOD, master(k * PERIOD), PERIOD,
                         sources=NO_FORCE_SENSOR)
    assert math.isnan(inputs.force_time) and inputs.measured_force == 0.0
    assert inputs.instrument_time == pytest.approx(0.299)
    jaw, modes = inputs.jaw_angle, set()
    for k in range(300, 400):
        _, out = closed_loop_step(sim, ctrl, inputs, k * PERIOD, 0.0, PERIOD, sources=NO_SOURCES)
        modes.add(out.mode)
    assert {s: getattr(inputs, f'{s}_time') for s in ('master', 'instrument', 'actuator')} == \
        pytest.approx({'master': 0.299, 'instrument': 0.299, 'actuator': 0.299})
    assert inputs.jaw_angle == jaw and inputs.master_angle == pytest.approx(master(0.299))
    assert 'safe' in modes                                   # 100 ms without input is a loss


def test_an_unknown_source_is_refused(params):
    sim, ctrl, inputs = pair(params)
    with pytest.raises(ValueError, match="unknown input sources \\['forces'\\]"):
        closed_loop_step(sim, ctrl, inputs, 0.0, 0.8, PERIOD, sources=ALL_SOURCES | {'forces'})
    assert sim.measure().t == 0.0                            # refused before anything ran
