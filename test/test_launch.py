"""The package's launch files (launch/*.launch.py) with the real ``ros2 launch``.

The grasp (master, sim_instrument, controller) is launched as a user would; the force is
read with ``ros2 topic echo --once``, a gain set and read back with ``ros2 param``; SIGINT
to the launch process (not its group: the nodes would get it twice) stops it, and every
node must exit 0, as the launch output reports. A second launch checks ``namespace:=``
(relative topics move, /diagnostics stays) and ``instrument:=NAME``. The argument
resolution (params.files.instrument_path) is tested directly.
"""
from __future__ import annotations

import re

import pytest

from _ros_tools import (ROOT, cli, known_deadlock, launch_exit_codes, lifecycle_transition, log_errors,
                        require_ros_tools, retry, ros_env, run, start, stop_daemon, stop_launch)
from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path
from grip_force_ros.params.interface import INTERFACES

NODES = ('sim_instrument', 'controller', 'master')
CONFIG = ROOT / 'config'


# --- instrument:= resolution (no ROS) ---------------------------------------------------------

def test_instrument_by_name_with_or_without_suffix():
    assert instrument_path('long_jaw_grasper', CONFIG) == CONFIG / 'long_jaw_grasper.yaml'
    assert instrument_path('long_jaw_grasper.yaml', CONFIG) == CONFIG / 'long_jaw_grasper.yaml'
    assert instrument_path(DEFAULT_INSTRUMENT, CONFIG) == CONFIG / 'paper_needle_driver.yaml'


def test_instrument_by_path(tmp_path, monkeypatch):
    own = tmp_path / 'my_tool.yaml'
    own.write_text('/**:\n  ros__parameters: {}\n')
    assert instrument_path(str(own), CONFIG) == own
    monkeypatch.chdir(tmp_path)
    assert instrument_path('./my_tool.yaml', CONFIG).resolve() == own   # relative to the cwd
    assert instrument_path('my_tool.yaml', CONFIG).resolve() == own     # an existing file wins


def test_unknown_instrument_lists_the_installed_ones(tmp_path):
    with pytest.raises(FileNotFoundError) as err:
        instrument_path('no_such_tool', CONFIG)
    message = str(err.value)
    assert 'no_such_tool' in message and 'paper_needle_driver' in message
    with pytest.raises(FileNotFoundError):
        instrument_path(str(tmp_path / 'missing.yaml'), CONFIG)
    with pytest.raises(FileNotFoundError):
        instrument_path('  ', CONFIG)


def test_interface_profiles():
    assert INTERFACES == ('crtk', 'dvrk')


# --- ros2 launch ------------------------------------------------------------------------------


def _param(env, *args, timeout=60.0):
    """``ros2 param ARGS --no-daemon``, again while the short-lived CLI node has not yet
    discovered the target ('Node not found': discovery takes a moment on a loaded machine)."""
    return cli(env, 'param', *args, '--no-daemon', '--spin-time', '2', timeout=timeout)


def _graph(env, *args, ok, window=90.0):
    """``ros2 ARGS --no-daemon --spin-time 2`` (a graph query), again until ``ok(result)``.

    Through ``cli``: each try has the limit of a CLI call (``_ros_tools.CLI_CALL_TIMEOUT``),
    inside ``window``: a call that hangs is one failed try, not the whole window (fresh-clone
    CI of 6f6d653: ``ros2 node list`` gave nothing for the whole 30 s of its retry, while the
    launch's nodes answered ``ros2 node info`` just before; a call under the old 60 s limit
    could eat the window).
    """
    return cli(env, *args, '--no-daemon', '--spin-time', '2', until=ok, timeout=window)


def _node_topics(node, env, needed, timeout=90.0):
    """Topics ``node`` publishes or subscribes to (``ros2 node info``), once ``needed`` shows.

    What a node's own entities are named, immune to other processes in the domain: the
    domain-wide topic list can hold the crtk names of an earlier test's stopped nodes beside
    a launch's namespaced ones.
    """
    info = _graph(env, 'node', 'info', node, ok=lambda r: needed in r.stdout, window=timeout)
    assert needed in info.stdout, (info.stdout, info.stderr)
    topics, section = set(), ''
    for line in info.stdout.splitlines():
        if line.strip().endswith(':') and not line.startswith('    '):
            section = line.strip()
        elif section in ('Subscribers:', 'Publishers:') and line.strip().startswith('/'):
            topics.add(line.split(':')[0].strip())
    return topics


def _wait_for_param(node, name, env, timeout=90.0):
    return retry(lambda: _param(env, 'get', node, name, timeout=5.0),
                 lambda r: r.returncode == 0, timeout=timeout)


def _named(text: str) -> str:
    """A launch log, after the name of a known deadlock its nodes' native stacks show.

    Only a node whose teardown the laboratory watches writes native stacks to its log
    (``lab.node_process``); under ``ros2 launch`` a teardown past its limit leaves its Python
    stacks (``lifetime.limit_teardown``), where no deadlock is named.
    """
    return f'{known_deadlock(text) or "no known deadlock in the log"}\n{text}'


#: A node's line as it stops after its peers (``lifetime.leave_after``), in a launch log.
_LEAVING = re.compile(r'\[(?:INFO|WARN)\] \[(?P<stamp>[\d.]+)\] \[(?:\w+\.)*(?P<node>\w+)\]: '
                      r'leaving (?P<how>after|with) (?P<rest>.*)')


def _leaving_order(text: str) -> list[tuple[str, str]]:
    """(node, how it left) of each node that waited for its peers, in the order of its line."""
    lines = sorted((float(m['stamp']), m['node'], m['how'] + ' ' + m['rest'])
                   for m in _LEAVING.finditer(text))
    return [(node, how) for _, node, how in lines]


def _assert_left_in_order(text: str) -> None:
    """Ctrl-C reached all three; the controller left after the master, the sim after both.

    The order the launch file sets (GRIP_FORCE_LEAVE_AFTER): no participant is torn down while
    another one's leaving reaches it (Fast DDS's spinning set_listener, eProsima/Fast-DDS#6513;
    a fresh-clone CI run had the controller hang there, killed with -9).
    """
    order = _leaving_order(text)
    assert [node for node, _ in order] == ['controller', 'sim_instrument'], (order, text)
    assert order[0][1].startswith('after master ('), (order, text)
    assert order[1][1].startswith('after controller, master ('), (order, text)


def _stop_launch(proc, log, env):
    try:
        code = stop_launch(proc, log)     # SIGINT to the launch process only
    finally:
        stop_daemon(env)
    text = log.read_text()
    return code, text


def test_grasp_launch_echo_param_and_clean_exit(tmp_path):
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'launch.log'
    proc = start('ros2', 'launch', 'grip_force_ros', 'grasp.launch.py', log=log, env=env)
    try:
        # With the type given, echo waits for the publisher instead of failing at once.
        echo = run('ros2', 'topic', 'echo', '--once', '--no-daemon', '/grip/estimated_force',
                   'geometry_msgs/msg/WrenchStamped', timeout=120, env=env)
        assert echo.returncode == 0, (echo.stderr, log.read_text())
        assert 'frame_id: jaw' in echo.stdout
        force = re.search(r'force:\s+x: (\S+)\s+y: (\S+)\s+z: (\S+)', echo.stdout)
        assert force, echo.stdout
        assert all(float(v) >= 0.0 for v in (force[1], force[3]))   # pull-out, grip (N)

        assert _wait_for_param('/controller', 'force_kp', env).returncode == 0
        value = '0.0234'
        set_ = _param(env, 'set', '/controller', 'force_kp', value)
        assert set_.returncode == 0 and 'Set parameter successful' in set_.stdout, set_
        got = _param(env, 'get', '/controller', 'force_kp')
        assert got.stdout.strip() == f'Double value is: {value}', got
        refused = _param(env, 'set', '/controller', 'max_current', '2.0')
        assert 'read-only' in refused.stdout + refused.stderr, refused
        assert proc.poll() is None, log.read_text()
    finally:
        code, text = _stop_launch(proc, log, env)
    assert code == 0, text
    assert launch_exit_codes(text) == {name: 0 for name in NODES}, _named(text)
    assert not log_errors(text), text
    _assert_left_in_order(text)


def test_grasp_launch_namespace_and_instrument(tmp_path):
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'launch.log'
    proc = start('ros2', 'launch', 'grip_force_ros', 'grasp.launch.py', 'namespace:=psm1',
                 'instrument:=long_jaw_grasper', log=log, env=env)
    try:
        got = _wait_for_param('/psm1/controller', 'instrument_name', env)
        assert got.stdout.strip() == 'String value is: long_jaw_grasper', (got, log.read_text())
        want = {'/psm1/grip/estimated_force', '/psm1/instrument/actuator/servo_jf',
                '/psm1/master/gripper/measured_js', '/diagnostics'}
        topics = _graph(env, 'topic', 'list', ok=lambda r: want <= set(r.stdout.split()))
        assert want <= set(topics.stdout.split()), topics.stdout
        # every topic of the controller under the namespace, but the root's /diagnostics
        own = _node_topics('/psm1/controller', env, '/psm1/grip/estimated_force')
        assert '/diagnostics' in own, own
        assert all(t.startswith('/psm1/') for t in own
                   - {'/diagnostics', '/rosout', '/parameter_events'}), own
        named = {f'/psm1/{n}' for n in NODES}
        nodes = _graph(env, 'node', 'list', ok=lambda r: named <= set(r.stdout.split()))
        assert named <= set(nodes.stdout.split()), (nodes.returncode, nodes.stdout, nodes.stderr)
        # ros2 topic hz on the namespaced force (the controller publishes it every step)
        # (15 s: the CLI's start-up and discovery alone can take seconds on a loaded machine)
        hz = run('bash', '-c', 'timeout -s INT 15 ros2 topic hz /psm1/grip/estimated_force; true',
                 timeout=60, env=env)
        rates = [float(r) for r in re.findall(r'average rate: ([\d.]+)', hz.stdout)]
        assert rates and max(rates) > 50.0, hz.stdout + hz.stderr
        assert proc.poll() is None, log.read_text()
    finally:
        code, text = _stop_launch(proc, log, env)
    assert code == 0, text
    assert launch_exit_codes(text) == {name: 0 for name in NODES}, _named(text)
    _assert_left_in_order(text)


def test_launch_rejects_unknown_interface_and_instrument(tmp_path):
    require_ros_tools()
    env = ros_env()
    bad = run('ros2', 'launch', 'grip_force_ros', 'grasp.launch.py', 'interface:=ros1', env=env,
              timeout=60)
    assert bad.returncode != 0
    assert 'crtk' in bad.stdout + bad.stderr and 'dvrk' in bad.stdout + bad.stderr
    missing = run('ros2', 'launch', 'grip_force_ros', 'controller.launch.py',
                  'instrument:=no_such_tool', env=env, timeout=60)
    assert missing.returncode != 0
    assert 'no_such_tool' in missing.stdout + missing.stderr


def test_grasp_launch_dvrk_profile_as_psm2_and_mtmr(tmp_path):
    """interface:=dvrk: the dVRK's names under the arm and master given (PSM2, MTMR), the
    controller asks the simulated arm to enable and home, then grips (force echoed)."""
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'launch.log'
    proc = start('ros2', 'launch', 'grip_force_ros', 'grasp.launch.py', 'interface:=dvrk',
                 'arm:=PSM2', 'master:=MTMR', log=log, env=env)
    try:
        want = {'/PSM2/jaw/measured_js', '/PSM2/measured_js', '/PSM2/jaw/servo_jf',
                '/PSM2/operating_state', '/PSM2/state_command', '/MTMR/gripper/measured_js',
                '/PSM2/grip/estimated_force'}
        topics = _graph(env, 'topic', 'list', ok=lambda r: want <= set(r.stdout.split()))
        assert want <= set(topics.stdout.split()), (topics.stdout, log.read_text())

        # the controller's own topics: none of the crtk or default dVRK names
        own = _node_topics('/controller', env, '/PSM2/jaw/servo_jf')
        assert not [t for t in own if t.startswith(('/PSM1', '/MTML', '/instrument'))], own
        state = retry(lambda: run('ros2', 'service', 'call', '/PSM2/operating_state',
                                  'crtk_msgs/srv/TriggerOperatingState', env=env, timeout=60),
                      lambda r: "is_homed=True" in r.stdout, timeout=60)
        assert "state='ENABLED'" in state.stdout and 'is_homed=True' in state.stdout, state.stdout
        echo = run('ros2', 'topic', 'echo', '--once', '--no-daemon', '/PSM2/jaw/servo_jf',
                   'sensor_msgs/msg/JointState', timeout=120, env=env)
        assert echo.returncode == 0 and '- jaw' in echo.stdout, (echo.stdout, echo.stderr)
        assert proc.poll() is None, log.read_text()
    finally:
        code, text = _stop_launch(proc, log, env)
    assert code == 0, text
    assert launch_exit_codes(text) == {name: 0 for name in NODES}, _named(text)
    assert 'asked arm PSM2 to enable' in text and not log_errors(text), text
    _assert_left_in_order(text)


def test_controller_launch_alone(tmp_path):
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'launch.log'
    config = CONFIG / 'maryland_forceps.yaml'
    proc = start('ros2', 'launch', 'grip_force_ros', 'controller.launch.py',
                 f'instrument:={config}', log=log, env=env)
    try:
        got = _wait_for_param('/controller', 'instrument_name', env)
        assert got.stdout.strip() == 'String value is: maryland_forceps', (got, log.read_text())
        nodes = _graph(env, 'node', 'list', ok=lambda r: '/controller' in r.stdout.split())
        assert '/controller' in nodes.stdout.split(), (nodes.returncode, nodes.stdout, nodes.stderr)
        assert '/sim_instrument' not in nodes.stdout.split()
    finally:
        code, text = _stop_launch(proc, log, env)
    assert code == 0, text
    assert launch_exit_codes(text) == {'controller': 0}, _named(text)


def test_grasp_launch_managed_controller_waits_for_lifecycle_set(tmp_path):
    """autostart:=false: the controller is a launch_ros LifecycleNode that waits
    unconfigured, the drive gets no command; ``ros2 lifecycle set`` configures and activates
    it, launch logs each transition, and the loop closes (the command echoed)."""
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'launch.log'
    proc = start('ros2', 'launch', 'grip_force_ros', 'grasp.launch.py', 'autostart:=false',
                 log=log, env=env)

    def lifecycle(*args):
        return cli(env, 'lifecycle', *args, '--no-daemon', '--spin-time', '2')

    servo = '/instrument/actuator/servo_jf'
    try:
        got = lifecycle('get', '/controller')
        assert got.stdout.split() == ['unconfigured', '[1]'], (got, log.read_text())
        info = _graph(env, 'topic', 'info', servo,
                      ok=lambda r: 'Subscription count: 1' in r.stdout)   # the sim's
        assert 'Publisher count: 0' in info.stdout, info
        for transition, state in (('configure', 'inactive'), ('activate', 'active')):
            # a call whose answer was lost (_ros_tools.CLI_CALL_TIMEOUT) is confirmed with get
            got, lost = lifecycle_transition(
                env, '/controller', transition,
                lambda: lifecycle('get', '/controller').stdout.split()[:1] == [state])
            assert lost or 'Transitioning successful' in got.stdout, (got, log.read_text())
            assert lifecycle('get', '/controller').stdout.split()[0] == state
        echo = run('ros2', 'topic', 'echo', '--once', '--no-daemon', servo,
                   'sensor_msgs/msg/JointState', timeout=120, env=env)
        assert echo.returncode == 0 and '- jaw_drum' in echo.stdout, (echo.stdout, echo.stderr)
        assert proc.poll() is None, log.read_text()
    finally:
        code, text = _stop_launch(proc, log, env)
    assert code == 0, text
    assert launch_exit_codes(text) == {name: 0 for name in NODES}, _named(text)
    # the launch_ros LifecycleNode's transition events, as launch logs them
    for seen in ('controller: unconfigured -> configuring', 'controller: inactive -> activating'):
        assert seen in text, text
    assert not log_errors(text), text
    _assert_left_in_order(text)
