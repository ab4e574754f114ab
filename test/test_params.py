import math

import pytest

from grip_force_ros.params import (SCHEMA, ParameterError, load_params_file, make_params,
                                   read_params_yaml, to_yaml)


def test_defaults_validate():
    p = make_params()
    assert p.drum_radius == pytest.approx(0.004)
    assert p.guide_pulley_wrap_angles == pytest.approx((math.pi / 2, math.pi / 4, math.pi / 4))


def test_every_spec_default_is_in_its_own_range():
    for spec in SCHEMA:
        assert spec.check(spec.default) is not None or spec.type == 'bool'


@pytest.mark.parametrize('key,value,needle', [
    ('drum_radius', -0.004, 'drum_radius'),
    ('drum_radius', 'big', 'expected a number'),
    ('guide_pulley_radii', [0.003, 1.0], 'guide_pulley_radii[1]'),
    ('pulley_friction_coefficient', float('nan'), 'not finite'),
    ('drum_raduis', 0.004, 'unknown parameter'),
])
def test_bad_values_give_one_clear_error(key, value, needle):
    with pytest.raises(ParameterError, match=r'.*') as err:
        make_params({key: value})
    assert needle in str(err.value)
    assert isinstance(err.value, ValueError)


def test_out_of_range_message_names_key_value_and_range():
    with pytest.raises(ParameterError) as err:
        make_params({'max_current': 50.0})
    msg = str(err.value)
    assert 'max_current' in msg and '50.0' in msg and '[0.0, 20.0]' in msg


def test_yaml_round_trip(tmp_path):
    p = make_params({'drum_radius': 0.005})
    f = tmp_path / 'x.yaml'
    f.write_text(to_yaml(p))
    assert read_params_yaml(f)['drum_radius'] == 0.005
    assert load_params_file(f).drum_radius == 0.005


def test_bad_file_names_the_file(tmp_path):
    f = tmp_path / 'bad.yaml'
    f.write_text('/**:\n  ros__parameters:\n    drum_radius: 9.0\n')
    with pytest.raises(ParameterError, match='bad.yaml.*drum_radius'):
        load_params_file(f)


def test_replace_validates():
    p = make_params()
    assert p.replace(gear_ratio=2.0).gear_ratio == 2.0
    with pytest.raises(ParameterError):
        p.replace(gear_ratio=0.0)
