"""The dVRK's own Python client drives the simulated instrument as PSM1.

The unmodified ``dvrk.psm`` (../shared/vendor/dvrk_python, built into .venv by ./dev setup)
runs in the sourced environment (test/_ros_tools.py), as a dVRK user runs it, against
``sim_instrument`` with ``interface: dvrk``:

* it enables and homes the arm (crtk operating state, ``state_command``), reads
  ``jaw.measured_js`` and closes the jaw with ``jaw.servo_jf``;
* with our controller in the dvrk profile and a master on ``MTML/gripper/measured_js``,
  it watches the jaw while the needle grasp closes and holds.

``state_command`` is sent once by the client; one sent before the sim's subscription has
matched is lost (vendor README), so the client retries ``enable()``/``home()`` with a
timeout, as a careful user script does.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from _ros_tools import log_errors, require_ros_tools, ros_env, run, start, stop
from grip_force_ros.model import GripForceModel
from grip_force_ros.model.dvrk_jaw import JawEffortConversion
from grip_force_ros.params import load_params_file

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'paper_needle_driver.yaml'

pytestmark = pytest.mark.ros

#: The client: enable, home, read the jaw, stream a closing jaw effort, read it back.
CLIENT = r'''
import json, sys, time
import numpy
import crtk, dvrk

marker = sys.argv[1] if len(sys.argv) > 1 else ''
watch = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
effort = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
ral = crtk.ral('dvrk_client_test')
arm = dvrk.psm(ral, 'PSM1')
ral.spin()
out = {}
def retry(fn, what, tries=10, timeout=3.0):
    for k in range(tries):
        if fn(timeout):
            return k + 1
    raise SystemExit(f'{what} failed {tries} times')
jp, jv, jf, t0 = arm.jaw.measured_js(wait_timeout=20.0)
out['jaw_start'] = float(jp[0])
out['state_before'] = arm.operating_state()
out['enable_tries'] = retry(arm.enable, 'enable')
out['enabled'] = arm.is_enabled()
out['home_tries'] = retry(arm.home, 'home')
out['homed'] = bool(arm.is_homed())
out['state'] = arm.operating_state()
if effort:
    # stream the effort at the dVRK's 100 Hz for 1 s (a single servo_jf is cut by the drive's
    # 30 ms command timeout), then read the jaw back
    samples = []
    for k in range(100):
        arm.jaw.servo_jf(numpy.array([effort]))
        time.sleep(0.01)
        jp, jv, jf, t = arm.jaw.measured_js()
        samples.append((t, float(jp[0]), float(jf[0])))
    out['effort_samples'] = samples
if marker:
    open(marker, 'w').write('homed\n')
if watch:
    from geometry_msgs.msg import WrenchStamped
    forces = []
    ral.subscriber('/PSM1/grip/measured_force', WrenchStamped,
                   lambda m: forces.append((time.time(), m.wrench.force.z)))
    jaw = []
    end = time.time() + watch
    while time.time() < end:
        jp, jv, jf, t = arm.jaw.measured_js()
        jaw.append((time.time(), float(jp[0]), float(jf[0])))
        time.sleep(0.01)
    out['jaw'] = jaw
    out['forces'] = forces
    out['state_end'] = arm.operating_state()
print(json.dumps(out))
ral.shutdown()
'''


def _node(name: str, log: Path, env: dict, *params: str):
    args = ['python', '-m', f'grip_force_ros.nodes.{name}', '--ros-args', '--params-file', str(CONFIG),
            '-p', 'interface:=dvrk']
    for p in params:
        args += ['-p', p]
    return start(*args, log=log, env=env)


def _result(proc) -> dict:
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_dvrk_client_enables_homes_reads_and_closes_the_jaw(tmp_path):
    require_ros_tools()
    env = ros_env()
    params = load_params_file(CONFIG).replace(interface='dvrk')
    # the drive's 30 ms command timeout is not under test here: a client process starved for
    # 30 ms between two servo_jf would read the cut (0 A) back
    sim = _node('sim_instrument', tmp_path / 'sim.log', env, 'command_timeout:=1.0')
    effort = -0.05                                    # N*m, closing: 0.15 A through 2.374 A/(N*m)
    try:
        got = _result(run('python', '-c', CLIENT, '', '0', str(effort), timeout=120, env=env))
        assert sim.poll() is None, (tmp_path / 'sim.log').read_text()
    finally:
        code = stop(sim)
    log = (tmp_path / 'sim.log').read_text()
    assert code == 0, log
    # the arm comes up DISABLED and not homed; the client enables and homes it
    assert got['state_before'] in ('', 'DISABLED')
    assert got['enabled'] and got['homed'] and got['state'] == 'ENABLED'
    assert got['jaw_start'] == pytest.approx(params.initial_jaw_angle, abs=0.02)
    samples = got['effort_samples']
    late = [s for s in samples[50:]]                  # the last 0.5 s of the streamed effort
    # measured effort = the dVRK's conversion of the measured current: the command's, within the
    # current noise (2 mA std, 0.84 mN*m) and the current loop's lag (0.2 ms, settled)
    conv = JawEffortConversion.from_params(params)
    noise = 5 * params.current_noise_std / conv.amps_per_newton_metre
    assert all(abs(f - effort) < noise for _, _, f in late), late[:5]
    # the closing effort closes the jaw onto the needle (contact at 0.0417 rad)
    assert late[-1][1] < 0.1 < got['jaw_start']
    assert 'PSM1: enable -> ENABLED' in log and 'homed' in log


def test_our_controller_closes_a_needle_grasp_while_the_dvrk_client_watches(tmp_path):
    require_ros_tools()
    env = ros_env()
    params = load_params_file(CONFIG).replace(interface='dvrk')
    marker = tmp_path / 'homed'
    procs = {'sim': _node('sim_instrument', tmp_path / 'sim.log', env),
             'controller': _node('controller', tmp_path / 'controller.log', env)}
    client = None
    try:
        client = start('python', '-c', CLIENT, str(marker), '14', '0', log=tmp_path / 'client.log',
                       env=env)
        deadline = time.monotonic() + 90
        while not marker.exists():
            assert client.poll() is None, (tmp_path / 'client.log').read_text()
            assert time.monotonic() < deadline, 'the dVRK client never homed the arm'
            time.sleep(0.1)
        # the grasp starts once the arm is enabled and homed by the dVRK client
        procs['master'] = _node('master', tmp_path / 'master.log', env, 'exit_when_done:=true')
        client.wait(timeout=120)
    finally:
        for proc in [client, *reversed(list(procs.values()))]:
            if proc is not None:
                stop(proc)
    text = (tmp_path / 'client.log').read_text()
    got = json.loads(text.strip().splitlines()[-1])
    assert got['state_end'] == 'ENABLED'
    jaw = got['jaw']
    forces = got['forces']
    assert len(jaw) > 500 and len(forces) > 500, text[-2000:]
    conv = JawEffortConversion.from_params(params)
    # the hold: the load cell at the target (4 N) for the longest stretch
    target = params.grip_force_max
    held = [(t, f) for t, f in forces if abs(f - target) < 0.1 * target]
    assert len(held) > 50, ('no hold at the target', max(f for _, f in forces))
    t_hold = held[len(held) // 2][0]
    # what the dVRK client saw then: the jaw on the needle (closed past its 0.0417 rad contact
    # angle by the needle's compliance only) and a closing jaw effort, the current the hold
    # needs through the dVRK's own conversion
    near = [(p, f) for t, p, f in jaw if abs(t - t_hold) < 0.2]
    assert near, 'the client saw no jaw state during the hold'
    i_load = GripForceModel(params).current_for_force_scalar(target, 0.0, 0.04, 'needle')   # A
    # on the pulleys' stick band the hold current lies between lambda^2 (0.42 for this
    # instrument) and 1 times the loading current (docs/control.md), plus 10 % for the
    # controller's correction; the client reads it as the dVRK's effort, with the current
    # noise (5 std of 2 mA through the conversion) on top
    noise = 5 * params.current_noise_std / conv.amps_per_newton_metre
    lam2 = GripForceModel(params).forward(i_load, 0.0, 0.04, 'needle').efficiency ** 2
    lowest, highest = conv.effort(1.1 * i_load) - noise, conv.effort(0.9 * lam2 * i_load) + noise
    print(f'dVRK client during the hold: jaw {near[0][0]:.4f} rad, effort {near[0][1]:.4f} N*m '
          f'(loading-edge current {i_load:.3f} A = {conv.effort(i_load):.4f} N*m); load cell '
          f'{sum(f for _, f in held) / len(held):.3f} N over {len(held)} samples for {target} N')
    for position, effort in near:
        assert 0.0 < position < 0.06, position
        assert lowest <= effort <= highest, (effort, lowest, highest)
    for name in ('sim', 'controller'):
        text = (tmp_path / f'{name}.log').read_text()
        assert not log_errors(text), text
