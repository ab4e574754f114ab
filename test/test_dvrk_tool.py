"""``grip-force import-dvrk-tool``: instrument facts from a dVRK tool file (params/dvrk_tool.py)."""
import json
import math
from pathlib import Path

import pytest

from grip_force_ros.lab.cli import main as cli_main
from grip_force_ros.params import ParameterError, load_params_file, read_params_yaml
from grip_force_ros.params.dvrk_tool import import_tool, read_tool_file, strip_comments, tool_facts

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT.parent / 'shared' / 'vendor' / 'dvrk-tools'
MARYLAND = TOOLS / 'MARYLAND_BIPOLAR_FORCEPS_400172.json'
KEPT = ('torque_constant', 'gear_ratio', 'drum_radius', 'guide_pulley_radii', 'cable_radius',
        'pulley_friction_coefficient', 'tension_friction_gain', 'cable_modulus', 'max_current',
        'force_ki', 'jaw_kp')


@pytest.fixture
def tools():
    if not TOOLS.is_dir():
        pytest.skip(f'no vendored dVRK tool files at {TOOLS} (a clone without ../shared)')
    return TOOLS


def test_comments_are_stripped_outside_strings():
    text = '/* head */ {"a": "x // y", // note\n "b": [1, /* two */ 2]}'
    assert json.loads(strip_comments(text)) == {'a': 'x // y', 'b': [1, 2]}


def test_maryland_facts(tools):
    facts = tool_facts(read_tool_file(MARYLAND), MARYLAND.name)
    values = {k: v for k, (v, _) in facts.items()}
    assert values == {'jaw_angle_min': -0.349066, 'jaw_angle_max': 1.39626,
                      'dvrk_jaw_effort_max': 0.19, 'dvrk_jaw_coupling': 0.915964,
                      'wrist_finger_coupling': pytest.approx(0.630273)}
    assert all(MARYLAND.name in source for _, source in facts.values())
    assert '-20 deg' in facts['jaw_angle_min'][1] and '80 deg' in facts['jaw_angle_max'][1]


def test_pitch_coupling_is_relative_to_the_pitch_row(tools):
    """The large needle driver's pitch row is 1.0186 (not 1): 0.8306 / 1.0186."""
    path = tools / 'LARGE_NEEDLE_DRIVER_400006.json'
    facts = tool_facts(read_tool_file(path), path.name)
    assert facts['wrist_finger_coupling'][0] == pytest.approx(0.8306 / 1.0186)
    assert facts['dvrk_jaw_coupling'][0] == 1.2177
    # the sign is the base file's (the model has one blade)
    assert tool_facts(read_tool_file(path), path.name, -0.6)['wrist_finger_coupling'][0] < 0


def test_every_tool_file_with_two_opposed_jaw_disks_imports(tools):
    ok, refused = [], []
    for path in sorted(tools.glob('*.json')):
        if path.name == 'index.json':
            continue
        try:
            facts = tool_facts(read_tool_file(path), path.name)
        except ParameterError as exc:
            refused.append((path.name, str(exc)))
            continue
        assert facts['dvrk_jaw_effort_max'][0] > 0 and facts['dvrk_jaw_coupling'][0] > 0
        ok.append(path.name)
    assert len(ok) > 40, refused
    # a tool without a jaw of two opposed disks is refused with the reason, not guessed
    assert all('jaw' in why or 'coupling' in why for _, why in refused), refused


def test_import_keeps_the_base_and_says_where_each_number_came_from(tools, tmp_path):
    base = ROOT / 'config' / 'paper_needle_driver.yaml'
    out = tmp_path / 'paper_as_maryland.yaml'
    assert cli_main(['import-dvrk-tool', str(MARYLAND), '--base', str(base), '--out', str(out)]) == 0
    new, old = load_params_file(out), load_params_file(base)
    assert (new.jaw_angle_min, new.jaw_angle_max, new.dvrk_jaw_effort_max) == \
        (-0.349066, 1.39626, 0.19)
    assert new.dvrk_jaw_coupling == 0.915964
    assert new.wrist_finger_coupling == pytest.approx(0.630273)
    for key in KEPT:
        assert new[key] == old[key], key
    text = out.read_text()
    for key in ('jaw_angle_min', 'jaw_angle_max', 'dvrk_jaw_effort_max', 'dvrk_jaw_coupling',
                'wrist_finger_coupling'):
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(f'{key}:'))
        assert f'dVRK tool file {MARYLAND.name}' in line, line
    # importing again into the result changes nothing but the base named in the header
    again = tmp_path / 'again.yaml'
    import_tool(MARYLAND, out, again)
    assert again.read_text().splitlines()[1:] == text.splitlines()[1:]


def test_a_fact_the_base_lacks_is_added_among_the_parameters(tools, tmp_path):
    """It went beside ``ros__parameters`` before (the first indent found), where ROS ignores it."""
    base = tmp_path / 'base.yaml'
    base.write_text('\n'.join(ln for ln in (ROOT / 'config' / 'paper_needle_driver.yaml')
                              .read_text().splitlines()
                              if not ln.strip().startswith('dvrk_jaw_effort_max:')) + '\n')
    out = tmp_path / 'out.yaml'
    import_tool(MARYLAND, base, out)
    line = next(ln for ln in out.read_text().splitlines() if 'dvrk_jaw_effort_max:' in ln)
    assert line.startswith('    dvrk_jaw_effort_max: 0.19'), line
    assert load_params_file(out).dvrk_jaw_effort_max == 0.19


def test_a_bad_tool_file_writes_nothing(tools, tmp_path):
    bad = tmp_path / 'BAD.json'
    bad.write_text('{"jaw": {"qmin": -0.3, "qmax": 1.4, "ftmax": 0.2}, "coupling": '
                   '{"ActuatorToJointPosition": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}')
    out = tmp_path / 'out.yaml'
    base = str(ROOT / 'config' / 'paper_needle_driver.yaml')
    assert cli_main(['import-dvrk-tool', str(bad), '--base', base, '--out', str(out)]) == 1
    assert not out.exists()
    # a jaw range the schema refuses (qmin above qmax) is refused before writing
    bad.write_text(MARYLAND.read_text().replace('"qmin": -0.349066', '"qmin": 2.0'))
    assert cli_main(['import-dvrk-tool', str(bad), '--base', base, '--out', str(out)]) == 1
    assert not out.exists()


def test_the_shipped_maryland_file_is_the_import_of_its_tool_file(tools, tmp_path):
    """config/maryland_forceps.yaml takes its dVRK facts from MARYLAND_BIPOLAR_FORCEPS_400172."""
    config = ROOT / 'config' / 'maryland_forceps.yaml'
    again = tmp_path / 'maryland.yaml'
    facts = import_tool(MARYLAND, config, again)
    shipped = read_params_yaml(config)
    for key, (value, _) in facts.items():
        assert math.isclose(shipped[key], value, rel_tol=0, abs_tol=0), key
    assert again.read_text() == config.read_text()
