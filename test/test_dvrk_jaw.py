"""The dVRK's jaw effort <-> current conversion (model/dvrk_jaw.py): numbers and round trip."""
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from grip_force_ros.model.dvrk_jaw import JawEffortConversion, command_current_limit
from grip_force_ros.params import load_params_file, make_params

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT.parent / 'shared' / 'vendor' / 'dvrk-tools'


def test_the_psm_io_constant_is_one_over_torque_constant_times_gear():
    # sawRobotIO1394-PSM1-28007.xml, actuators 3..6: NmToAmps 1.949705 = 1/(0.0438 * 11.71)
    # (Maxon motors of 0.0438 N*m/A through 11.71:1 to the instrument's input disks)
    assert make_params({}).dvrk_actuator_nm_to_amps == pytest.approx(1.0 / (0.0438 * 11.71), abs=5e-7)


def test_maryland_numbers():
    """Maryland bipolar forceps 400172 on a Classic PSM: 1.78586 A of jaw motor current per N*m."""
    conv = JawEffortConversion(jaw_coupling=0.915964, nm_to_amps=1.949705)
    assert conv.amps_per_newton_metre == pytest.approx(0.915964 * 1.949705, rel=1e-12)
    assert conv.amps_per_newton_metre == pytest.approx(1.78586, abs=1e-5)
    # closing current -> a negative (closing) jaw effort; 0.3 A is -0.168 N*m
    assert conv.effort(0.3) == pytest.approx(-0.3 / 1.78586, rel=1e-5)
    # the two jaw actuators carry equal and opposite torques, c times the jaw effort
    assert conv.actuator_torques(-0.1) == pytest.approx((0.0915964, -0.0915964))
    # the tool's effort limit ftmax = 0.19 N*m is 0.339 A; the PSM's MaxCurrent (0.670 A) is
    # 0.375 N*m of jaw effort: the tool file's limit is the one that acts
    assert conv.current_limit(0.19) == pytest.approx(0.3393, abs=1e-4)
    assert 0.670 / conv.amps_per_newton_metre == pytest.approx(0.3752, abs=1e-4)


def test_round_trip_and_sign():
    conv = JawEffortConversion(jaw_coupling=1.2177, nm_to_amps=1.949705)
    currents = np.linspace(-0.7, 0.7, 141)
    for i in currents:
        e = conv.effort(float(i))
        assert conv.current(e) == pytest.approx(float(i), abs=1e-15)
        assert math.copysign(1.0, e) == -math.copysign(1.0, i) or i == 0.0
    # the dVRK's own conversion of an effort: C^T, then NmToAmps per actuator
    effort = -0.12
    tau6, tau7 = conv.actuator_torques(effort)
    motor_current_7 = 1.949705 * tau7                    # A, the dVRK's jaw actuator 7
    assert conv.current(effort) == pytest.approx(-motor_current_7)
    assert tau6 == pytest.approx(-tau7)


def test_refuses_nonpositive_constants():
    with pytest.raises(ValueError):
        JawEffortConversion(0.0, 1.9)
    with pytest.raises(ValueError):
        JawEffortConversion(0.9, -1.0)


def test_the_current_limit_of_the_dvrk_profile_is_the_effort_limit():
    crtk = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    dvrk = crtk.replace(interface='dvrk')
    assert command_current_limit(crtk) == crtk.max_current
    expected = crtk.dvrk_jaw_effort_max * crtk.dvrk_jaw_coupling * crtk.dvrk_actuator_nm_to_amps
    assert expected < crtk.max_current
    assert command_current_limit(dvrk) == pytest.approx(expected)


def test_the_tool_files_jaw_coupling_is_what_the_dvrk_multiplies_by():
    """The coupling read from the Maryland tool file: the jaw row is (0, 0, -c, c)."""
    if not TOOLS.is_dir():
        pytest.skip(f'no vendored dVRK tool files at {TOOLS} (a clone without ../shared)')
    text = (TOOLS / 'MARYLAND_BIPOLAR_FORCEPS_400172.json').read_text()
    text = re.sub(r'//[^\n]*', '', re.sub(r'/\*.*?\*/', '', text, flags=re.S))
    jaw_row = json.loads(text)['coupling']['ActuatorToJointPosition'][3]
    assert jaw_row == [0.0, 0.0, -0.915964, 0.915964]
