"""The dvrk interface profile with real node processes.

* PSM1 and PSM2 side by side in one ROS domain, each with its own sim, controller and master
  (MTML, MTMR): neither sees the other (PSM1's master closes, PSM2's stays open).
* Without crtk_msgs (plain venv Python, not sourced) a node asked for the dvrk profile
  refuses to start, saying how to get it; the crtk profile still runs.

The processes run in the sourced environment (test/_ros_tools.py): crtk_msgs' typesupport
libraries are on its library path.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _ros_tools import require_ros_tools, ros_env, run, start, stop
from grip_force_ros.params import load_params_file

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'paper_needle_driver.yaml'

pytestmark = pytest.mark.ros

#: Listens to both arms for ``seconds`` and prints what each one did (JSON).
WATCH = r'''
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
seconds = float(sys.argv[1])
rclpy.init()
node = rclpy.create_node('two_arm_watch')
got = {}
def keep(key):
    got[key] = []
    return lambda m: got[key].append(m)
for arm in ('PSM1', 'PSM2'):
    node.create_subscription(WrenchStamped, f'/{arm}/grip/measured_force', keep(f'{arm} force'), 50)
    node.create_subscription(WrenchStamped, f'/{arm}/grip/target_force', keep(f'{arm} target'), 50)
    node.create_subscription(JointState, f'/{arm}/jaw/measured_js', keep(f'{arm} jaw'), 50)
node.create_subscription(DiagnosticArray, '/diagnostics', keep('diagnostics'), 50)
end = time.time() + seconds
while time.time() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
out = {}
for arm in ('PSM1', 'PSM2'):
    out[arm] = {'max_force': max((m.wrench.force.z for m in got[f'{arm} force']), default=None),
                'max_target': max((m.wrench.force.z for m in got[f'{arm} target']), default=None),
                'min_jaw': min((m.position[0] for m in got[f'{arm} jaw']), default=None),
                'jaw_states': len(got[f'{arm} jaw'])}
arms = {}
for m in got['diagnostics']:
    for s in m.status:
        values = {kv.key: kv.value for kv in s.values}
        if s.name.endswith('controller') and 'arm' in values:
            arms.setdefault(values['arm'], set()).add(values.get('mode'))
out['controller_modes'] = {k: sorted(v) for k, v in arms.items()}
print(json.dumps(out))
'''


def _node(name, arm, master, log, env, *extra):
    args = ['python', '-m', f'grip_force_ros.nodes.{name}', '--ros-args',
            '-r', f'__node:={name}_{arm.lower()}', '--params-file', str(CONFIG),
            '-p', 'interface:=dvrk', '-p', f'arm:={arm}', '-p', f'master:={master}']
    for p in extra:
        args += ['-p', p]
    return start(*args, log=log, env=env)


def test_psm1_and_psm2_side_by_side_do_not_see_each_other(tmp_path):
    require_ros_tools()
    env = ros_env()
    params = load_params_file(CONFIG)
    procs = []
    try:
        for arm, master, trajectory in (('PSM1', 'MTML', ['repeat:=true']),
                                        ('PSM2', 'MTMR', ['master_closed_angle:=0.8'])):
            procs.append(_node('sim_instrument', arm, master, tmp_path / f'sim_{arm}.log', env))
            procs.append(_node('controller', arm, master, tmp_path / f'controller_{arm}.log', env,
                               'request_enable:=true'))
            procs.append(_node('master', arm, master, tmp_path / f'master_{arm}.log', env,
                               *trajectory))
        watch = run('python', '-c', WATCH, '14', timeout=120, env=env)
        assert watch.returncode == 0, watch.stderr
        for p in procs:
            assert p.poll() is None, [f.read_text()[-1500:] for f in tmp_path.glob('*.log')]
    finally:
        for p in reversed(procs):
            stop(p)
    got = json.loads(watch.stdout.strip().splitlines()[-1])
    psm1, psm2 = got['PSM1'], got['PSM2']
    assert psm1['jaw_states'] > 200 and psm2['jaw_states'] > 200, got
    # PSM1: MTML closes (needle grasp, repeated): it grips at the target force
    assert psm1['max_target'] == pytest.approx(params.grip_force_max)
    assert psm1['max_force'] > 0.9 * params.grip_force_max, got
    # PSM2: MTMR stays open: no grip, the jaw stays open (free motion at the master's 0.8 rad)
    assert psm2['max_target'] == 0.0, got
    assert psm2['max_force'] < 0.05 * params.grip_force_max, got
    assert psm2['min_jaw'] > 0.5, got
    # each controller reports its own arm
    assert set(got['controller_modes']) == {'PSM1', 'PSM2'}, got
    assert 'grip' in got['controller_modes']['PSM1'] and 'grip' not in got['controller_modes']['PSM2']


@pytest.mark.parametrize('executable', ['controller', 'sim_instrument'])
def test_dvrk_profile_without_crtk_msgs_refuses_to_start_and_says_why(executable):
    """The plain venv Python (not sourced) has no crtk_msgs' typesupport: exit 2, one clear line."""
    probe = subprocess.run([sys.executable, '-c', 'import crtk_msgs.msg'], capture_output=True)
    if probe.returncode == 0:
        pytest.skip('crtk_msgs is importable without sourcing here (a ROS machine with it installed)')
    env = ros_env()
    proc = subprocess.run([sys.executable, '-m', f'grip_force_ros.nodes.{executable}', '--ros-args',
                           '--params-file', str(CONFIG), '-p', 'interface:=dvrk'],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2, proc.stderr
    line = [ln for ln in proc.stderr.splitlines() if 'refusing to start' in ln]
    assert line and 'crtk_msgs' in line[0] and 'ros_setup.bash' in line[0], proc.stderr
    assert 'Traceback' not in proc.stderr


#: An arm's operating_state service that holds its first answer ``hold`` s (an answer lost
#: for the client, as Fast DDS loses one under load) and answers later requests at once.
#: Prints a JSON line per request: its number and when it came (monotonic s).
SLOW_ARM = r'''
import json, sys, threading, time
import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from crtk_msgs.srv import TriggerOperatingState
hold = float(sys.argv[1])
rclpy.init()
node = rclpy.create_node('slow_arm')
count = [0]
lock = threading.Lock()
def answer(request, response):
    with lock:
        count[0] += 1
        n = count[0]
    print(json.dumps({'request': n, 't': time.monotonic()}), flush=True)
    if n == 1:
        time.sleep(hold)
    response.operating_state.state = 'ENABLED'
    response.operating_state.is_homed = True
    response.operating_state.header.frame_id = 'PSM1'
    response.operating_state.header.stamp = node.get_clock().now().to_msg()
    return response
node.create_service(TriggerOperatingState, '/PSM1/operating_state', answer,
                    callback_group=ReentrantCallbackGroup())
executor = MultiThreadedExecutor(num_threads=3)
executor.add_node(node)
try:
    executor.spin()
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
'''


def test_a_lost_operating_state_answer_is_asked_again(tmp_path):
    """The controller learns an arm's state although the first answer of its service never comes.

    The arm is enabled from elsewhere (no request_enable) and sends no state change, so
    the service is the controller's only way to learn it. Before the re-ask
    (controller_io.STATE_REPLY_WAIT) the controller waited for the first answer alone:
    here 60 s, the test's limit 30 s.
    """
    require_ros_tools()
    env = ros_env()
    arm = start('python', '-c', SLOW_ARM, '60', log=tmp_path / 'arm.log', env=env)
    controller = _node('controller', 'PSM1', 'MTML', tmp_path / 'controller.log', env,
                       'request_enable:=false')
    try:
        deadline = time.monotonic() + 90.0      # both processes up and discovered (loaded)
        while time.monotonic() < deadline and not _requests(tmp_path / 'arm.log'):
            assert controller.poll() is None and arm.poll() is None
            time.sleep(0.2)
        first = _requests(tmp_path / 'arm.log')
        assert first, 'the controller never asked the arm for its operating state'
        known = None
        while time.monotonic() < first[0]['t'] + 30.0:
            if 'arm PSM1: ENABLED, homed' in (tmp_path / 'controller.log').read_text():
                known = time.monotonic()
                break
            time.sleep(0.2)
        requests = _requests(tmp_path / 'arm.log')
        assert known is not None, (f'the controller did not learn the state within 30 s of its '
                                   f'first request ({len(requests)} requests)')
        assert len(requests) >= 2
        assert requests[1]['t'] - requests[0]['t'] < 30.0
    finally:
        stop(controller)
        stop(arm, sig=signal.SIGKILL)   # a thread of it sleeps on the held answer


def _requests(log: Path) -> list[dict]:
    return [json.loads(line) for line in log.read_text().splitlines() if line.startswith('{"request"')]
