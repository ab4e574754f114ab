"""The ROS 2 tools of the development environment (tools/ros_tools.sh).

After ``source .venv/ros_setup.bash``: the real ``ros2`` CLI finds grip_force_ros through
the ament index (colcon, symlink install), ``ros2 run`` starts its executables,
``ros2 param``/``node``/``topic``/``lifecycle`` talk to them; one copy of grip_force_ros
is imported. Plus the wheels' CMake path fix (tools/fix_wheel_cmake_paths.py).
"""
from __future__ import annotations

import importlib.util
import re
import shutil
import signal
import subprocess
import sys
import sysconfig
from pathlib import Path


from _ros_tools import (FASTDDS_LOG_LINE, ROOT, VENV, known_deadlock, log_errors, process_report,
                        require_ros_tools, retry, ros_env, run, start, stop, stop_daemon, vendor_dir)
from grip_force_ros.lab.processes import wait_until

EXECUTABLES = ('controller', 'master', 'sim_instrument')


def _load_fix_script():
    spec = importlib.util.spec_from_file_location('fix_wheel_cmake_paths',
                                                  ROOT / 'tools' / 'fix_wheel_cmake_paths.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_fix_wheel_cmake_paths_repoints_and_is_idempotent(tmp_path):
    import numpy
    fix = _load_fix_script()
    cmake = tmp_path / 'share' / 'pkg' / 'cmake' / 'export_pkg__rosidl_generator_pyExport.cmake'
    cmake.parent.mkdir(parents=True)
    cmake.write_text('INTERFACE_INCLUDE_DIRECTORIES "/opt/python/cp311-cp311/include/python3.11;'
                     '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"\n')
    other = tmp_path / 'share' / 'ament_index' / 'parent_prefix_path' / 'pkg'
    other.parent.mkdir(parents=True)
    other.write_text('/opt/python/cp311-cp311')   # not a .cmake file: left alone
    assert fix.fix(tmp_path) == [cmake]
    text = cmake.read_text()
    assert text == (f'INTERFACE_INCLUDE_DIRECTORIES "{sysconfig.get_paths()["include"]};'
                    f'{numpy.get_include()}"\n')
    assert fix.fix(tmp_path) == []            # idempotent
    assert cmake.read_text() == text
    assert other.read_text() == '/opt/python/cp311-cp311'


def test_venv_cmake_files_name_this_python():
    require_ros_tools()
    fix = _load_fix_script()
    assert fix.fix(VENV) == []    # the set-up ran it: nothing left to repoint
    stale = [p for p in (VENV / 'share').rglob('*.cmake')
             if '/opt/python/cp3' in p.read_text(errors='replace')]
    assert not stale, stale[:5]


def test_setup_file_ament_index_and_one_grip_force_ros(tmp_path):
    require_ros_tools()
    prefix = run('ros2', 'pkg', 'prefix', 'grip_force_ros')
    assert prefix.returncode == 0, prefix.stderr
    install = Path(prefix.stdout.strip())
    assert install == VENV / 'ros' / 'install' / 'grip_force_ros'
    exes = run('ros2', 'pkg', 'executables', 'grip_force_ros')
    assert exes.returncode == 0, exes.stderr
    listed = {line.split()[1] for line in exes.stdout.splitlines() if line.strip()}
    assert set(EXECUTABLES) <= listed, exes.stdout
    for name in EXECUTABLES:
        assert (install / 'lib' / 'grip_force_ros' / name).is_file()
    share = install / 'share' / 'grip_force_ros'
    for launch_file in ('grasp.launch.py', 'controller.launch.py'):
        assert (share / 'launch' / launch_file).resolve() == ROOT / 'launch' / launch_file
    assert (share / 'config' / 'paper_needle_driver.yaml').resolve() == \
        ROOT / 'config' / 'paper_needle_driver.yaml'
    # One grip_force_ros: outside the repository, the colcon (symlinked) package comes
    # first on PYTHONPATH; its files are the repository's, so edits are live.
    where = run('python', '-c', 'import grip_force_ros, crtk_msgs, launch_ros; '
                'print(grip_force_ros.__file__)', cwd=tmp_path)
    assert where.returncode == 0, where.stderr
    imported = Path(where.stdout.strip())
    assert imported.parent == VENV / 'ros' / 'build' / 'grip_force_ros' / 'grip_force_ros'
    assert imported.resolve() == ROOT / 'grip_force_ros' / '__init__.py'


def test_ros2_run_param_node_topic_lifecycle(tmp_path):
    require_ros_tools()
    env = ros_env()
    log = tmp_path / 'controller.log'
    proc = start('ros2', 'run', 'grip_force_ros', 'controller', '--ros-args', '--params-file',
                 'config/paper_needle_driver.yaml', log=log, env=env)
    try:
        got = retry(lambda: run('ros2', 'param', 'get', '/controller', 'instrument_name',
                                '--no-daemon', env=env),
                    lambda r: r.returncode == 0, timeout=60)
        assert got.stdout.strip() == 'String value is: paper_needle_driver', \
            (got.stdout, got.stderr, process_report(proc, log))
        nodes = retry(lambda: run('ros2', 'node', 'list', '--no-daemon', '--spin-time', '2', env=env),
                      lambda r: '/controller' in r.stdout.split(), timeout=30)
        assert '/controller' in nodes.stdout.split(), (nodes, process_report(proc, log))
        # CI of 2af15e3: 30 s of tries saw only the CLI's own two topics, just after the
        # node list had found /controller; whether the controller still ran was not asked
        topics = retry(lambda: run('ros2', 'topic', 'list', '--no-daemon', '--spin-time', '2', env=env),
                       lambda r: '/instrument/actuator/servo_jf' in r.stdout.split(), timeout=30)
        assert {'/instrument/actuator/servo_jf', '/grip/estimated_force', '/diagnostics'} <= \
            set(topics.stdout.split()), (topics.stdout, process_report(proc, log))
        # ros2lifecycle: imports, lists its verbs, and finds the controller, a lifecycle node
        helped = run('ros2', 'lifecycle', '--help', env=env)
        assert helped.returncode == 0, helped.stderr
        assert {'get', 'list', 'nodes', 'set'} <= set(re.findall(r'^\s+(\w+)\s', helped.stdout, re.M))
        # a new CLI process discovers the graph in its spin time: on a loaded machine 2 s can
        # pass before it has the controller's services (an empty list), as for node and
        # topic list above
        lifecycle = retry(lambda: run('ros2', 'lifecycle', 'nodes', '--no-daemon', '--spin-time',
                                      '2', env=env),
                          lambda r: '/controller' in r.stdout.split(), timeout=30)
        assert lifecycle.returncode == 0, lifecycle.stderr
        assert '/controller' in lifecycle.stdout.split(), \
            (lifecycle.stdout, _graph_seen(env), process_report(proc, log))
        assert proc.poll() is None
    finally:
        # ros2 run does not pass SIGINT on to its child: signal the process group.
        code = stop(proc, signal.SIGINT, group=True)
        stop_daemon(env)
    text = log.read_text()
    assert code == 0, text
    assert not log_errors(text), text


def _graph_seen(env: dict[str, str]) -> str:
    """What a new CLI process sees of the graph: its nodes, and its services with their types.

    For a ``ros2 lifecycle nodes`` that printed nothing: it
    lists the nodes that have a ``<node>/get_state`` service of type
    ``lifecycle_msgs/srv/GetState``, so an empty answer alone cannot say whether the node or
    its service was missing.
    """
    seen = []
    for verb in (('node', 'list'), ('service', 'list', '-t')):
        done = run('ros2', *verb, '--no-daemon', '--spin-time', '2', env=env)
        seen.append(f"ros2 {' '.join(verb)} (exit {done.returncode}):\n{done.stdout}{done.stderr}")
    return '\n'.join(seen)


def test_a_failed_discovery_reports_whether_the_node_runs_and_where_it_is(tmp_path):
    """:func:`process_report`, for a test that fails on what a CLI call did not find."""
    require_ros_tools()
    log = tmp_path / 'node.log'
    waiting = ('import faulthandler, signal, time; '
               'faulthandler.register(signal.SIGUSR1, all_threads=True); '
               'print("ready", flush=True); time.sleep(120)')
    proc = start(sys.executable, '-c', waiting, log=log)
    try:
        assert wait_until(lambda: 'ready' in log.read_text(), timeout=30), log.read_text()
        report = process_report(proc, log)
        assert report.startswith('the command runs'), report
        assert 'Python stacks asked into the log' in report, report
        assert 'File "<string>", line 1 in <module>' in report, report   # faulthandler's dump
        if shutil.which('gdb'):
            assert re.search(r'^#\d+ +(0x[0-9a-f]+ in )?\w', report, re.M), report   # gdb's frames
        else:
            assert 'no gdb on this machine' in report, report
    finally:
        stop(proc, signal.SIGKILL)
    assert process_report(proc, log).startswith('the command exited -9')


#: gdb's stacks of a participant caught deaf by a probe (participants with a 0.2 s lease
#: coming and going beside it, 237 s in), two of its 15 threads, frames cut to their names.
_DEADLOCKED = """\
Thread 8 (Thread 0x7f83fd1f96c0 (LWP 25208) "dds.udp.62660"):
#4  ___pthread_cond_wait (cond=0x55bc1eadad18, mutex=0x55bc1eacd040) at ./nptl/pthread_cond_wait.c:618
#6  0x00007f84036f93b9 in eprosima::fastrtps::rtps::ResourceEvent::unregister_timer(TimedEventImpl*) ()
#8  0x00007f840375cde5 in eprosima::fastrtps::rtps::WriterProxy::stop() ()
#11 0x00007f84039ef034 in eprosima::fastrtps::rtps::PDP::removeWriterProxyData(GUID_t const&) ()
Thread 7 (Thread 0x7f83fd9fa6c0 (LWP 25207) "dds.ev.0"):
#3  ___pthread_mutex_lock (mutex=0x55bc1ea81910) at ./nptl/pthread_mutex_lock.c:128
#4  0x00007f84039e8ee4 in eprosima::fastrtps::rtps::PDP::check_remote_participant_liveliness(...) ()
"""


#: gdb's stacks of a controller past 3 s in its teardown (eProsima/Fast-DDS#6513), two of its
#: 16 threads, frames cut to their names.
_SPINNING_SET_LISTENER = """\
Thread 10 (Thread 0x7fbc52f136c0 (LWP 31783) "dds.udp.13164"):
#3  ___pthread_mutex_lock (mutex=0x2c2312d0) at ./nptl/pthread_mutex_lock.c:93
#4  0x00007fbc71670c86 in eprosima::...::MyRTPSParticipantListener::onParticipantDiscovery(...) ()
#5  0x00007fbc717efbab in eprosima::fastrtps::rtps::PDP::actions_on_remote_participant_removed(...) ()
Thread 1 (Thread 0x7fbc72c44740 (LWP 31759) "controller"):
#0  0x00007fbc72f66b46 in clock_gettime ()
#3  0x00007fbc71688dfb in eprosima::fastdds::dds::DomainParticipant::set_listener(...) ()
#5  0x00007fbc71f57c84 in rmw_fastrtps_shared_cpp::destroy_participant(CustomParticipantInfo*) ()
"""


def test_fast_dds_s_spinning_set_listener_is_named_in_a_report():
    assert 'eProsima/Fast-DDS#6513' in known_deadlock(_SPINNING_SET_LISTENER)
    deleting_alone = _SPINNING_SET_LISTENER.split('Thread 1 ')[1]   # no callback waits: no hang
    assert known_deadlock(deleting_alone) is None


def test_fast_dds_s_open_deadlock_is_named_in_a_report():
    assert 'eProsima/Fast-DDS#6502' in known_deadlock(_DEADLOCKED)
    one_thread = _DEADLOCKED.split('Thread 7')[0]        # a receive thread waiting alone: no deadlock
    assert known_deadlock(one_thread) is None
    assert known_deadlock('') is None


def test_dev_ros2_runs_the_cli_from_the_callers_directory(tmp_path):
    require_ros_tools()
    # ./dev with the same vendored sources as this run: its set-up stamp matches, nothing rebuilds.
    env = ros_env(GRIP_FORCE_VENDOR=str(vendor_dir()))
    prefix = subprocess.run([str(ROOT / 'dev'), 'ros2', 'pkg', 'prefix', 'grip_force_ros'],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert prefix.returncode == 0, prefix.stderr
    assert prefix.stdout.strip() == str(VENV / 'ros' / 'install' / 'grip_force_ros')
    where = subprocess.run([str(ROOT / 'dev'), 'ros2', 'pkg', 'xml', 'grip_force_ros', '--tag', 'name'],
                           capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert where.returncode == 0 and where.stdout.strip() == 'grip_force_ros', where


def test_fast_dds_log_lines_are_told_from_a_commands_answer():
    """``ros2 lifecycle get`` can print a Fast DDS shared-memory error on stdout before
    ``unconfigured [1]``, not to be read as the answer. ``run`` moves such lines to stderr;
    the answer, and a command's own error text, stay."""
    logged = ('\x1b[37;1m2026-11-27 00:48:12.123 \x1b[31;1m[\x1b[37;1mRTPS_TRANSPORT_SHM\x1b[31;1m '
              'Error\x1b[37;1m] Failed init_port fastrtps_port7413: open_and_lock_file failed'
              '\x1b[34;1m -> Function \x1b[36mopen_port_internal\x1b[m')
    assert FASTDDS_LOG_LINE.match(logged)
    for answer in ('unconfigured [1]', 'Error: node not found', '2026-11-27 plain text Error'):
        assert not FASTDDS_LOG_LINE.match(answer)


#: A stand-in for ``ros2 launch``: starts one node that ignores SIGINT (its stderr into the
#: launch output, as launch does), names its pid as launch does, and on SIGINT waits 15 s
#: (as launch's SIGTERM and SIGKILL: past the helper's stack requests, gdb's too on a loaded
#: machine) before it kills the node and ends.
_STUCK_NODE = ('import faulthandler, signal, time; '
               'faulthandler.register(signal.SIGUSR1, all_threads=True); '
               'signal.signal(signal.SIGINT, signal.SIG_IGN); '
               'print("ready", flush=True); time.sleep(120)')
_FAKE_LAUNCH = f'''
import signal, subprocess, sys, time
node = subprocess.Popen([sys.executable, '-c', {_STUCK_NODE!r}], stdout=sys.stdout, stderr=sys.stdout)
print(f'[INFO] [stuck-1]: process started with pid [{{node.pid}}]', flush=True)
got = []
signal.signal(signal.SIGINT, lambda *args: got.append(time.monotonic()))
while not got:
    time.sleep(0.05)
time.sleep(15.0)
node.kill()
node.wait()
'''


def test_a_launched_node_still_running_before_launch_s_sigterm_leaves_its_stacks(tmp_path):
    """A node ``ros2 launch`` SIGKILLs (deaf to SIGINT/SIGTERM) leaves its stacks in the log."""
    from _ros_tools import stop_launch
    log = tmp_path / 'launch.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen([sys.executable, '-c', _FAKE_LAUNCH], stdout=out, stderr=subprocess.STDOUT)
    assert wait_until(lambda: 'ready' in log.read_text(), 60.0, 0.05)
    assert stop_launch(proc, log) == 0
    text = log.read_text()
    assert 'most recent call first' in text, text        # faulthandler's dump of the node
    assert 'line 1 in <module>' in text, text
    assert 'native stacks of pid' in text and 'no known deadlock' in text, text
    if shutil.which('gdb'):
        assert re.search(r'^#\d+ +(0x[0-9a-f]+ in )?\w', text, re.M), text   # gdb's frames


def test_log_errors_sees_a_callback_error_the_events_executor_caught():
    """A sim log with a KeyboardInterrupt caught in a timer callback."""
    caught = ("[sim_instrument-1] [FATAL] [1795825648.018376419] [sim_instrument]: Exception in "
              "'timers' callback: \n"
              "[sim_instrument-1] [WARN] [1795825648.022793734] [sim_instrument]: Error occurred at:\n"
              '[sim_instrument-1]   File "plant.py", line 437, in step\n')
    assert len(log_errors(caught)) == 2
    assert log_errors('Traceback (most recent call last):\n') == ['Traceback (most recent call last):']
    clean = ('[INFO] [controller-2]: process has finished cleanly [pid 4151]\n'
             '[sim_instrument-1] [INFO] [1795825648.0] [sim_instrument]: stepping at 1000 Hz\n')
    assert log_errors(clean) == []
