"""Instrument YAMLs: they load, are complete and commented, and a bad file gives one clear error."""
import re
from pathlib import Path

import pytest
import yaml

from grip_force_ros.lab.cli import main as cli_main
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import ParameterError, load_params_file, specs_in

ROOT = Path(__file__).resolve().parents[1]
INSTRUMENTS = ['paper_needle_driver', 'long_jaw_grasper', 'four_pulley_needle_driver']


@pytest.mark.parametrize('name', INSTRUMENTS)
def test_config_loads_and_builds_a_model(name):
    path = ROOT / 'config' / f'{name}.yaml'
    params = load_params_file(path)
    assert params.instrument_name == name
    model = GripForceModel(params)
    # every instrument grips, and reaches its own force limit on a needle within its current limit
    assert model.grip_force_scalar(params.max_current, 0.0, 0.0, 'needle') > params.max_grip_force


@pytest.mark.parametrize('name', INSTRUMENTS)
def test_config_states_every_number_and_its_source(name):
    path = ROOT / 'config' / f'{name}.yaml'
    doc = yaml.safe_load(path.read_text())
    assert list(doc) == ['/**']
    body = doc['/**']['ros__parameters']
    declared = {s.name for s in specs_in('instrument', 'limits')}
    assert declared <= set(body), 'every instrument and limits parameter is written out'
    assert set(body) - declared <= {s.name for s in specs_in('controller')}, \
        'besides them only the designed controller gains (grip-force tune)'
    for line in path.read_text().splitlines():
        if re.match(r'^\s{4}\w+:', line) and 'instrument_name' not in line:
            assert '#' in line, f'no source comment: {line}'


def test_the_instruments_differ_in_geometry_and_friction():
    p = {n: load_params_file(ROOT / 'config' / f'{n}.yaml') for n in INSTRUMENTS}
    assert len({v.jaw_moment_arm_tip for v in p.values()}) == 3
    assert len({v.pulley_friction_coefficient for v in p.values()}) == 3
    assert len({len(v.guide_pulley_radii) for v in p.values()}) == 2


def test_paper_config_is_table_1():
    p = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    assert (p.drum_radius, p.guide_pulley_radii, p.drive_pulley_radius) == (0.004, (0.003,) * 3, 0.0025)
    assert (p.jaw_moment_arm_tip, p.jaw_moment_arm_inner, p.cable_modulus) == (0.012, 0.0095, 1.25e11)
    assert p.guide_pulley_wrap_angles == pytest.approx((3.14159265 / 2, 3.14159265 / 4, 3.14159265 / 4))
    assert (p.pulley_friction_coefficient, p.needle_friction_coefficient) == (0.15, 0.15)
    assert (p.torque_constant, p.gear_ratio, p.drum_mass, p.jaw_mass) == (1.44, 1.23, 0.0025, 0.001)


def _bad_copy(tmp_path, key, value, config='paper_needle_driver', **more):
    """A copy of ``config`` with ``key: value`` (and ``more`` keys) changed."""
    text = (ROOT / 'config' / f'{config}.yaml').read_text()
    for k, v in {key: value, **more}.items():
        text, n = re.subn(rf'(\s{k}:) [^#\n]*', rf'\1 {v} ', text)
        assert n == 1, k
    bad = tmp_path / 'bad.yaml'
    bad.write_text(text)
    return bad


def test_bad_value_gives_one_clear_error(tmp_path):
    bad = _bad_copy(tmp_path, 'drum_radius', '4.0')
    with pytest.raises(ParameterError) as err:
        load_params_file(bad)
    message = str(err.value)
    assert 'bad.yaml' in message and "'drum_radius'" in message and '4.0' in message
    assert '[0.0001, 0.05]' in message


def test_bad_file_is_refused_by_the_cli(tmp_path, capsys):
    bad = _bad_copy(tmp_path, 'pulley_friction_coefficient', '1.5')
    assert cli_main(['params', '--check', str(bad)]) == 1
    out = capsys.readouterr().out
    assert out.count('error') == 1 and 'pulley_friction_coefficient' in out and '1.5' in out


def test_inconsistent_file_is_refused_at_load(tmp_path):
    bad = _bad_copy(tmp_path, 'cable_radius', '0.0035')
    with pytest.raises(ParameterError, match="bad.*'cable_radius' 0.0035 m"):
        load_params_file(bad)


def test_instrument_files_are_found_by_name_or_path_from_anywhere(tmp_path, monkeypatch):
    from grip_force_ros.params import files
    shipped = ROOT / 'config' / 'long_jaw_grasper.yaml'
    monkeypatch.chdir(tmp_path)                                    # not the source tree
    assert files.instrument_path('long_jaw_grasper') == shipped
    assert files.instrument_path('long_jaw_grasper.yaml') == shipped
    assert files.instrument_path('config/long_jaw_grasper.yaml') == shipped
    assert files.instrument_path() == ROOT / 'config' / f'{files.DEFAULT_INSTRUMENT}.yaml'
    own = tmp_path / 'mine.yaml'
    own.write_text(shipped.read_text())
    assert files.instrument_path(own) == own                       # an existing file as given
    assert files.list_instruments() == sorted((ROOT / 'config').glob('*.yaml'))
    with pytest.raises(FileNotFoundError, match='no_such_instrument.*looked in'):
        files.instrument_path('no_such_instrument')


def test_config_directory_can_be_overridden(tmp_path, monkeypatch):
    from grip_force_ros.params import files
    (tmp_path / 'bench_rig.yaml').write_text((ROOT / 'config' / 'long_jaw_grasper.yaml').read_text())
    monkeypatch.setenv(files.CONFIG_DIR_ENV, str(tmp_path))
    assert files.config_dir() == tmp_path
    assert files.list_instruments() == [tmp_path / 'bench_rig.yaml']
    assert files.instrument_path('bench_rig') == tmp_path / 'bench_rig.yaml'
    with pytest.raises(FileNotFoundError, match=str(tmp_path)):
        files.instrument_path('long_jaw_grasper')                  # the override replaces config/


# ------------------------------------------------------------------ physical validation
ALL = INSTRUMENTS + ['maryland_forceps']


@pytest.mark.parametrize('name', ALL)
def test_every_shipped_instrument_could_be_built(name):
    """Cable stress at the current limit below the cable's strength, the chain efficiency in
    (0, 1], a jaw torque that closes: the shipped files pass the check that refuses others."""
    from grip_force_ros.model.physical import cable_load, physical_problems
    params = load_params_file(ROOT / 'config' / f'{name}.yaml')
    assert physical_problems(params) == []
    load = cable_load(params)
    assert load['stress'] <= params.cable_yield_strength
    assert load['drum_tension'] == pytest.approx(params.gear_ratio * params.torque_constant
                                                 * params.max_current / params.drum_radius)


def test_an_overstressed_cable_is_refused_by_params_check(tmp_path, capsys):
    """The four-pulley driver as it was first shipped: a 0.3 mm cable under 221 N at 0.5 A."""
    bad = _bad_copy(tmp_path, 'cable_radius', '0.00015', config='four_pulley_needle_driver')
    assert cli_main(['params', '--check', str(bad)]) == 1
    out = capsys.readouterr().out
    assert 'could not be built' in out and '3.13 GPa' in out and '1.08 GPa' in out
    assert 'cable radius >= 0.255 mm' in out and 'max_current <= 0.172 A' in out
    # the same file with a lower current limit passes
    fixed = _bad_copy(tmp_path, 'cable_radius', '0.00015', config='four_pulley_needle_driver',
                      max_current='0.17')
    assert cli_main(['params', '--check', str(fixed)]) == 0


def test_a_jaw_torque_of_the_wrong_sign_and_a_bad_efficiency_are_refused(monkeypatch):
    from grip_force_ros.model import ModelError
    from grip_force_ros.model import physical
    params = load_params_file(ROOT / 'config' / 'paper_needle_driver.yaml')
    # mu 0.3 on the paper's pulleys: lambda_n 0.43 < the static resistance fraction 0.5
    lossy = params.replace(pulley_friction_coefficient=0.3)
    with pytest.raises(ModelError, match='jaw torque of the wrong sign at rest.*lambda_n = 0.4'):
        physical.check_physical(lossy)
    monkeypatch.setattr(physical._friction, 'chain_efficiency', lambda *a, **k: 0.0)
    with pytest.raises(ModelError, match=r'chain efficiency lambda_n = 0.0 at rest: .*\(0, 1\]'):
        physical.check_physical(params)


def test_a_node_refuses_to_start_on_an_instrument_that_could_not_be_built(tmp_path):
    import subprocess
    import sys
    bad = _bad_copy(tmp_path, 'cable_radius', '0.00015', config='four_pulley_needle_driver')
    done = subprocess.run([sys.executable, '-m', 'grip_force_ros.nodes.sim_instrument',
                           '--ros-args', '--params-file', str(bad)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr[-2000:]
    assert 'refusing to start' in done.stderr and 'could not be built' in done.stderr
    assert 'Traceback' not in done.stderr
