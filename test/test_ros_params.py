"""Node parameters from the schema: descriptors, start-up validation, runtime sets.

Runtime sets go through the real parameter services (``AsyncParameterClient``
from another node), the path ``ros2 param set`` takes.
"""
from __future__ import annotations

import math
import subprocess
from pathlib import Path

import pytest
import yaml
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from grip_force_ros.nodes.controller import ControllerNode
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.lab.processes import node_command
from grip_force_ros.nodes.master import MasterNode
from grip_force_ros.nodes.ros_params import NodeParameters, descriptor_for
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode
from grip_force_ros.params import SPECS, ParameterError, ParamSpec, read_params_yaml, specs_in

pytestmark = pytest.mark.ros

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'paper_needle_driver.yaml'


@pytest.fixture(scope='module')
def ros():
    runner = RosRunner()
    runner.start()
    yield runner
    runner.stop()


@pytest.fixture(scope='module')
def controller(ros):
    return ros.add(ControllerNode, **{k: v for k, v in read_params_yaml(CONFIG).items()
                                      if k in SPECS and SPECS[k].group in
                                      ('instrument', 'limits', 'controller')})


@pytest.fixture(scope='module')
def client(ros, controller):
    node = ros.plain_node('param_client')
    cli = AsyncParameterClient(node, 'controller')
    assert cli.wait_for_services(timeout_sec=10.0)
    return cli


def remote_set(client, ros, **values):
    future = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
    assert ros.wait_for(future.done, 10.0), 'parameter service did not answer'
    return future.result().results


# ---------------------------------------------------------------- descriptors
def test_descriptors_carry_type_unit_range_and_read_only():
    spec = SPECS['max_current']
    d = descriptor_for(spec)
    assert d.type == ParameterType.PARAMETER_DOUBLE
    assert d.read_only and '[A]' in d.description
    assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == \
        (spec.min, spec.max)
    seed = descriptor_for(SPECS['sim_seed'])
    assert seed.type == ParameterType.PARAMETER_INTEGER and seed.integer_range
    arr = descriptor_for(SPECS['guide_pulley_radii'])
    assert arr.type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert 'each element' in arr.additional_constraints and not arr.floating_point_range


def test_controller_declares_every_parameter_of_its_groups(controller):
    names = set(controller._parameters)
    expected = {s.name for s in specs_in('instrument', 'limits', 'controller')}
    assert expected <= names
    assert not {s.name for s in specs_in('sim', 'effects')} & names
    # the values come from the instrument file
    for key, value in read_params_yaml(CONFIG).items():
        if key in expected:
            got = controller.get_parameter(key).value
            if isinstance(value, list):
                assert list(got) == pytest.approx(value)
            else:
                assert got == pytest.approx(value) if isinstance(value, float) else got == value


# ---------------------------------------------------------------- runtime sets
def test_out_of_range_runtime_set_is_refused_with_a_reason(ros, controller, client):
    before = controller.get_parameter('force_kp').value
    (res,) = remote_set(client, ros, force_kp=-1.0)
    assert not res.successful and 'force_kp' in res.reason
    assert controller.get_parameter('force_kp').value == before
    assert controller.controller.params.force_kp == before


def test_nan_runtime_set_is_refused(ros, controller, client):
    (res,) = remote_set(client, ros, watchdog_timeout=math.nan)
    assert not res.successful and 'watchdog_timeout' in res.reason


def test_read_only_parameter_is_refused(ros, controller, client):
    before = controller.controller.params.max_current
    (res,) = remote_set(client, ros, max_current=5.0)
    assert not res.successful and 'read-only' in res.reason
    assert controller.controller.params.max_current == before


def test_cross_parameter_rule_refuses_a_set(ros, controller, client):
    hi = controller.get_parameter('master_angle_max').value
    (res,) = remote_set(client, ros, master_angle_min=hi + 0.1)
    assert not res.successful
    assert 'master_angle_min' in res.reason and 'master_angle_max' in res.reason


def test_choice_is_checked(ros, controller, client):
    (res,) = remote_set(client, ros, object_kind='banana')
    assert not res.successful and 'banana' in res.reason and 'needle' in res.reason


def test_type_is_checked(ros, controller, client):
    (res,) = remote_set(client, ros, force_ki='fast')
    assert not res.successful


def test_valid_runtime_set_reaches_the_controller_core(ros, controller, client):
    new_ki = controller.get_parameter('force_ki').value * 0.9
    results = remote_set(client, ros, force_ki=new_ki, watchdog_timeout=0.05)
    assert all(r.successful for r in results), [r.reason for r in results]
    assert controller.controller.params.force_ki == pytest.approx(new_ki)
    assert controller.controller.watchdog_timeout == pytest.approx(0.05)


def test_force_sensor_switch_subscribes_at_runtime(ros, controller, client):
    (res,) = remote_set(client, ros, force_sensor_enabled=True)
    assert res.successful
    assert controller._force_sub is not None and controller.controller.use_sensor
    (res,) = remote_set(client, ros, force_sensor_enabled=False)
    assert res.successful and controller._force_sub is None


def test_double_array_elements_are_checked_at_runtime(ros):
    """rclpy ranges do not cover arrays: the on-set callback checks each element."""
    node = ros.plain_node('array_params')
    spec = ParamSpec('gains', 'double_array', (1.0, 2.0), 'A/N', 'test gains', min=0.0, max=5.0,
                     group='test')
    params = NodeParameters(node, groups=(), extra_specs=[spec])
    bad = node.set_parameters([Parameter('gains', value=[1.0, 7.5])])[0]
    assert not bad.successful and 'gains[1]' in bad.reason and '7.5' in bad.reason
    ok = node.set_parameters([Parameter('gains', value=[0.5, 4.0])])[0]
    assert ok.successful and params.value('gains') == (0.5, 4.0)


# ---------------------------------------------------------------- start-up
@pytest.mark.parametrize('overrides,needles', [
    ({'drum_radius': 0.5}, ['drum_radius', '0.5', '[0.0001, 0.05]']),
    ({'drum_raduis': 0.004}, ['unknown', 'drum_raduis']),
    ({'guide_pulley_radii': [0.003, 0.003, 0.9]}, ['guide_pulley_radii[2]', '0.9']),
    ({'max_current': 'lots'}, ['max_current', 'lots']),
    ({'friction_scale': 9.0}, ['friction_scale', '9.0']),   # a sim key: refused by every node
    ({'jaw_angle_min': 1.0, 'jaw_angle_max': 0.5}, ['jaw_angle_min', 'jaw_angle_max']),
])
@pytest.mark.parametrize('node_cls', [ControllerNode, SimInstrumentNode, MasterNode])
def test_invalid_instrument_values_refuse_to_start(ros, node_cls, overrides, needles):
    with pytest.raises(ParameterError) as err:
        ros.add(node_cls, **overrides)
    for needle in needles:
        assert needle in str(err.value)


def test_integer_in_file_is_accepted_for_a_double(ros):
    node = ros.add(SimInstrumentNode, sim_rate=20000)     # YAML '20000' is an integer
    assert node.get_parameter('sim_rate').value == 20000.0
    assert node.sim.params.sim_rate == 20000.0


@pytest.mark.parametrize('executable', ['controller', 'sim_instrument', 'master'])
def test_executable_exits_non_zero_on_a_bad_file(tmp_path, executable):
    values = read_params_yaml(CONFIG)
    values['max_current'] = 50.0
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'/**': {'ros__parameters': values}}))
    proc = subprocess.run(node_command(executable, params_file=str(bad)), capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode != 0
    err = proc.stderr + proc.stdout
    assert "'max_current'" in err and '50.0' in err and '[0.0, 20.0]' in err, err
    assert 'Traceback' not in err


def test_instrument_file_must_state_every_hardware_limit(ros):
    values = {k: v for k, v in read_params_yaml(CONFIG).items() if k != 'max_current_slew'}
    with pytest.raises(ParameterError, match='max_current_slew'):
        ros.add(ControllerNode, **values)


def test_unparsable_parameter_file_exits_non_zero(tmp_path):
    bad = tmp_path / 'broken.yaml'
    bad.write_text('/**:\n  ros__parameters: [\n')
    proc = subprocess.run(node_command('sim_instrument', params_file=str(bad)),
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert 'broken.yaml' in proc.stderr and 'Traceback' not in proc.stderr
