"""grip-force demo --arms: the arms' command lines, the held-grasp rule, two arms end to end."""
import json
import os
import subprocess
import sys

import pytest

from grip_force_ros.params.files import instrument_path


def _ros_args(argv):
    return argv[argv.index('--ros-args'):]


def test_each_arm_runs_its_nodes_in_its_namespace_with_its_own_diagnostics():
    from grip_force_ros.lab.demo.run import RunSpec, _node_argv
    config = instrument_path('paper_needle_driver')
    for ns in ('PSM1', 'PSM2'):
        spec = RunSpec(config=config, duration=4.0, namespace=ns)
        for name in ('sim_instrument', 'controller', 'master'):
            ros = _ros_args(_node_argv(name, spec))
            pairs = {ros[i + 1] for i, arg in enumerate(ros) if arg == '-r'}
            assert pairs == {f'__ns:=/{ns}', f'/diagnostics:=/{ns}/diagnostics'}, name
        naive = _ros_args(_node_argv('controller', RunSpec(config=config, controller='naive',
                                                           namespace=ns)))
        assert f'__ns:=/{ns}' in naive and '__node:=controller' in naive
    root = RunSpec(config=config, duration=4.0)
    for name in ('sim_instrument', 'controller', 'master'):
        assert '-r' not in _ros_args(_node_argv(name, root)), name
    assert root.remaps() == {}


def test_run_arms_refuses_arms_without_their_own_namespace(tmp_path):
    from grip_force_ros.lab.demo.run import RunSpec, run_arms
    config = instrument_path('paper_needle_driver')
    with pytest.raises(ValueError):
        run_arms([RunSpec(config=config, namespace='PSM1'), RunSpec(config=config, namespace='PSM1')],
                 tmp_path, 66)
    with pytest.raises(ValueError):
        run_arms([RunSpec(config=config)], tmp_path, 66)


def test_grasp_held_wants_an_unspoiled_run_near_its_target():
    from grip_force_ros.lab.demo.run import grasp_held
    good = {'target_force': 4.0, 'hold_error_mean': 0.02, 'hold_error_rms': 0.05}
    assert grasp_held(good, [])
    assert not grasp_held(good, ['a topic went silent for 120 ms during the hold phase'])
    assert not grasp_held({**good, 'hold_error_mean': -0.5}, [])      # 12.5 % off
    assert not grasp_held({**good, 'hold_error_rms': 0.7}, [])
    assert not grasp_held({}, []) and not grasp_held(None, [])
    assert not grasp_held({**good, 'hold_error_mean': float('nan')}, [])


def test_cli_refuses_arms_with_the_comparison_or_the_dvrk_profile(capsys):
    from grip_force_ros.lab.cli import main
    assert main(['demo', '--arms', '2', '--compare-instruments']) == 2
    assert main(['demo', '--arms', '2', '--interface', 'dvrk']) == 2
    assert 'crtk' in capsys.readouterr().err


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_two_arms_grasp_at_once_each_recorded_and_analysed(tmp_path):
    """PSM1 and PSM2 in one domain: both run, each bag holds its own topics, each is analysed."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    out = tmp_path / 'arms'
    proc = subprocess.run([sys.executable, '-m', 'grip_force_ros.lab.cli', 'demo', '--arms', '2',
                           '--duration', '3', '--json', '--quiet', '--out', str(out),
                           '--domain-id', env['ROS_DOMAIN_ID']],
                          capture_output=True, text=True, timeout=240, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout)
    assert list(report['arms']) == ['PSM1', 'PSM2']
    assert json.loads((out / 'results.json').read_text())['arms_held'] == report['arms_held']
    for name, arm in report['arms'].items():
        print(f"{name}: hold error {arm['metrics'].get('hold_error_mean')}, safe-state entries "
              f"{len(arm['safe_state_entries'])}, problems {arm['problems']} "
              f"(load {os.getloadavg()[0]:.1f})")
        assert arm['namespace'] == f'/{name}'
        assert arm['bag'].startswith(str(out / name))
        assert (out / name / 'summary.png').is_file() and (out / name / 'results.json').is_file()
        # the arm's own topics were recorded, and its controller answered its states
        assert arm['messages']['instrument/measured_js'] > 100, arm['messages']
        assert arm['messages']['instrument/actuator/servo_jf'] > 100, arm['messages']
        assert arm['messages']['/diagnostics'] > 0, arm['messages']
        assert isinstance(arm['grasp_held'], bool)
        assert 'hold_error_mean' in arm['metrics'] or arm['problems']
