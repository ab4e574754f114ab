"""`colcon build` of the package, then its installed executables on a real graph.

Builds into a temporary directory (``--build-base``/``--install-base``, no
symlink install), checks the layout ``ros2 run`` relies on, and runs the three
executables at once with ``--ros-args --params-file
install/.../config/paper_needle_driver.yaml``: each must start, publish its
topics, and exit cleanly (code 0) on Ctrl-C.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from _ros_tools import log_errors
from grip_force_ros import topics
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.lab.processes import NodeProcess, ros_environment

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'grip_force_ros'
EXECUTABLES = ('controller', 'sim_instrument', 'master')


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    colcon = shutil.which('colcon') or str(Path(sys.executable).with_name('colcon'))
    if not Path(colcon).exists():
        pytest.skip('colcon is not installed (colcon-common-extensions)')
    base = tmp_path_factory.mktemp('colcon')
    proc = subprocess.run(
        [colcon, '--log-base', str(base / 'log'), 'build', '--base-paths', str(ROOT),
         '--packages-select', PACKAGE, '--build-base', str(base / 'build'),
         '--install-base', str(base / 'install')],
        cwd=base, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return base / 'install'


def test_install_layout(install):
    lib = install / PACKAGE / 'lib' / PACKAGE
    for name in EXECUTABLES:
        exe = lib / name
        assert exe.is_file() and os.access(exe, os.X_OK), exe
        assert not exe.is_symlink()
    share = install / PACKAGE / 'share' / PACKAGE
    shipped = sorted(p.name for p in (ROOT / 'config').glob('*.yaml'))
    assert shipped and sorted(p.name for p in (share / 'config').glob('*.yaml')) == shipped
    assert (share / 'package.xml').is_file()
    assert (install / PACKAGE / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / PACKAGE).is_file()
    site = list((install / PACKAGE / 'lib').glob('python3*/site-packages/grip_force_ros'))
    assert site and (site[0] / 'nodes' / 'controller.py').is_file()
    assert (site[0] / 'lab' / 'cli' / '__init__.py').is_file()      # the laboratory is installed too


def test_installed_executables_start_publish_and_stop(install, tmp_path):
    lib = install / PACKAGE / 'lib' / PACKAGE
    config = install / PACKAGE / 'share' / PACKAGE / 'config' / 'paper_needle_driver.yaml'
    site = next((install / PACKAGE / 'lib').glob('python3*/site-packages'))
    env = ros_environment(extra={'PYTHONPATH': os.pathsep.join(
        p for p in [str(site), os.environ.get('PYTHONPATH')] if p)})
    seen: dict[str, int] = {}

    def count(topic):
        def cb(_msg):
            seen[topic] = seen.get(topic, 0) + 1
        return cb

    # the sim's state: one combined instrument/measured_js a period (state_message)
    expected = {topics.MASTER_JS: JointState, topics.INSTRUMENT_JS: JointState,
                topics.SERVO_CURRENT: JointState,
                topics.ESTIMATED_FORCE: WrenchStamped, topics.MEASURED_FORCE: WrenchStamped,
                topics.DIAGNOSTICS: DiagnosticArray}
    with RosRunner() as ros:
        probe = ros.plain_node('colcon_probe')
        for topic, msg_type in expected.items():
            probe.create_subscription(msg_type, topic, count(topic), 10)
        ros.start()
        procs = {name: NodeProcess(name, log_path=str(tmp_path / f'{name}.log'), env=env,
                                   command=[str(lib / name), '--ros-args', '--params-file',
                                            str(config)])
                 for name in EXECUTABLES}
        try:
            ok = ros.wait_for(lambda: all(seen.get(t, 0) >= 20 for t in expected), 30.0)
            for name, proc in procs.items():
                assert proc.popen.poll() is None, (tmp_path / f'{name}.log').read_text()
        finally:
            codes = {name: proc.stop() for name, proc in procs.items()}
    logs = {name: (tmp_path / f'{name}.log').read_text() for name in EXECUTABLES}
    assert ok, (seen, logs)
    assert codes == {name: 0 for name in EXECUTABLES}, (codes, logs)
    # the installed copy ran, with the instrument file's values
    assert 'paper_needle_driver' in logs['controller']
    assert 'paper_needle_driver' in logs['sim_instrument']
    assert not log_errors(''.join(logs.values())), logs
