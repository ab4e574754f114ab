"""The sensorless estimate's band (ControlOutput.band_low, band_high, estimate_held), no ROS.

With the jaw friction terms on (the Maryland forceps' rig fit) the estimate is held inside
the friction's band while the jaw sticks: the band has a positive width there and the
estimate lies strictly inside it. With the terms off (every paper instrument), with the load
cell and in the safe state there is no band: both edges are the estimate, width 0, never
held, and the other outputs are what they were (``test/test_jaw_friction.py`` compares the
closed loop with the code before the terms by ``==``).
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from grip_force_ros.control import GripController
from grip_force_ros.lab.closed_loop import ALL_SOURCES, NO_FORCE_SENSOR, closed_loop_step
from grip_force_ros.params import load_params_file
from grip_force_ros.sim.plant import InstrumentSim
from grip_force_ros.trajectories import needle_grasp

CONFIG = Path(__file__).resolve().parents[1] / 'config'
JAW_TERMS = ('jaw_coulomb_friction', 'jaw_coulomb_friction_slope', 'jaw_spring_torque',
             'jaw_spring_slope', 'jaw_spring_curvature', 'jaw_viscous_friction',
             'jaw_efficiency_load_gain')
STEPS = 2800          # 1 kHz: the default needle grasp's close and hold


def _params(name: str, sensor: bool = False, terms: bool = True):
    p = load_params_file(str(CONFIG / f'{name}.yaml'))
    if not terms:
        p = p.replace(**dict.fromkeys(JAW_TERMS, 0.0))
    return p.replace(force_sensor_enabled=sensor)


def _run(params, steps: int = STEPS, sources=None):
    """Closed loop on the sim of the same instrument: (t, ControlOutput, controller) rows."""
    sim = InstrumentSim(params, obj='needle', seed=3)
    ctrl = GripController(params)
    inputs, traj, rows = ctrl.new_inputs(), needle_grasp(), []
    sources = sources or (ALL_SOURCES if params.force_sensor_enabled else NO_FORCE_SENSOR)
    for k in range(steps):
        t = k * 1e-3
        _, out = closed_loop_step(sim, ctrl, inputs, t, traj.angle(t), 1e-3, sources=sources)
        rows.append((t, out))
    return rows, ctrl


def _no_band(out) -> bool:
    return (out.band_low == out.band_high == out.estimated_force and out.band_width == 0.0
            and out.estimate_held is False)


@pytest.fixture(scope='module')
def maryland():
    return _run(_params('maryland_forceps'))


def test_with_jaw_friction_the_hold_is_inside_a_band_of_positive_width(maryland):
    rows, ctrl = maryland
    assert ctrl.friction_state is not None
    grip = [out for _, out in rows if out.mode == 'grip']
    assert grip, 'the needle grasp grips'
    for out in grip:          # the estimate never leaves its band, the band never inverts
        assert out.band_low <= out.estimated_force <= out.band_high
        assert out.band_width == out.band_high - out.band_low >= 0.0
    held = [out for out in grip if out.estimate_held]
    assert len(held) > 100, 'the jaw sticks through much of the hold'
    for out in held:
        assert out.band_low < out.estimated_force < out.band_high and out.band_width > 0.0
    # the rig's 75 mN*m at the jaw: a band of several newtons at the 12 mm tip
    widths = sorted(out.band_width for out in held)
    assert widths[len(widths) // 2] > 1.0
    # while the chain pushes the estimate along an edge it sits on that edge
    edge = [out for out in grip if not out.estimate_held and out.band_width > 0.0]
    assert all(out.estimated_force in (out.band_low, out.band_high) for out in edge)


def test_the_band_reaches_diagnostics_while_held(maryland):
    rows, ctrl = maryland
    last = rows[-1][1]
    status = ctrl.status()
    assert status['estimate_band_N'] == f'{last.band_width:.3f}'
    assert status['estimate_band_low_N'] == f'{last.band_low:.3f}'
    assert status['estimate_band_high_N'] == f'{last.band_high:.3f}'
    if last.estimate_held:
        assert status['estimate'] == f'held in stick, band {last.band_width:.3f} N'
    else:
        assert status['estimate'].startswith("on the band's edge")
    # one step stated as held: the words the node's /diagnostics carries
    ctrl.band_low, ctrl.band_high, ctrl.estimate_held, ctrl.mode = 1.0, 3.5, True, 'grip'
    assert ctrl.band_status()['estimate'] == 'held in stick, band 2.500 N'


@pytest.mark.parametrize('name', ['maryland_forceps', 'paper_needle_driver'])
def test_without_jaw_friction_terms_there_is_no_band(name):
    rows, ctrl = _run(_params(name, terms=False), steps=1500)
    assert ctrl.friction_state is None
    assert all(_no_band(out) for _, out in rows)
    assert any(out.mode == 'grip' and out.estimated_force > 1.0 for _, out in rows)
    assert ctrl.status()['estimate'] == 'no jaw friction terms, no band'


def test_the_band_adds_fields_and_leaves_the_others_as_they_were():
    """Terms off: the first nine fields are a ControlOutput's of before, the band repeats one."""
    rows, _ = _run(_params('paper_needle_driver'), steps=600)
    for _, out in rows:
        assert out[-3:] == (out.estimated_force, out.estimated_force, False)
        assert out._fields[:9] == ('current_command', 'target_force', 'estimated_force',
                                   'pull_out_force', 'mode', 'limits_hit', 'reasons',
                                   'target_jaw_angle', 'feedforward_current')


def test_with_the_load_cell_there_is_no_band():
    params = _params('maryland_forceps', sensor=True)
    rows, ctrl = _run(params, steps=1500)
    assert ctrl.friction_state is not None          # the state still steps (the feedforward's)
    assert all(_no_band(out) for _, out in rows)
    assert ctrl.status()['estimate'] == 'load cell, no band'


def test_the_safe_state_has_no_band(maryland):
    params = _params('maryland_forceps')
    rows, ctrl = _run(params, steps=2000)
    inputs = ctrl.new_inputs()       # nothing received: the next step is safe
    out = ctrl.step(rows[-1][0] + 1e-3, inputs)
    assert out.mode == 'safe' and _no_band(out)
    assert math.isfinite(out.band_low)
    assert ctrl.status()['estimate'] == 'safe state: the last estimate kept, no band'
