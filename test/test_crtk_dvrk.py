"""crtk_msgs built here, and the CRTK / dVRK Python clients.

``crtk_msgs.msg.OperatingState`` goes from one process to another over loopback DDS and
arrives field for field; ``import dvrk; dvrk.psm`` works with Debian's PyKDL. Both after
``source .venv/ros_setup.bash`` (it puts crtk_msgs' typesupport libraries and PyKDL on
the library path). Driving the simulated instrument through the dVRK client is a later test.
"""
from __future__ import annotations

import json
import signal

from _ros_tools import require_ros_tools, ros_env, run, start, stop

TOPIC = 'crtk_test/operating_state'

PUBLISHER = f'''
import rclpy
from crtk_msgs.msg import OperatingState
rclpy.init()
node = rclpy.create_node('crtk_test_publisher')
pub = node.create_publisher(OperatingState, '{TOPIC}', 10)
def tick():
    msg = OperatingState(state='ENABLED', is_homed=True, is_busy=False)
    msg.header.frame_id = 'PSM1'
    msg.header.stamp = node.get_clock().now().to_msg()
    pub.publish(msg)
node.create_timer(0.05, tick)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
'''

SUBSCRIBER = f'''
import json, rclpy
from crtk_msgs.msg import OperatingState
rclpy.init()
node = rclpy.create_node('crtk_test_subscriber')
got = []
node.create_subscription(OperatingState, '{TOPIC}', got.append, 10)
while not got:
    rclpy.spin_once(node, timeout_sec=0.5)
m = got[0]
print(json.dumps({{'type': type(m).__module__ + '.' + type(m).__name__, 'state': m.state,
                  'is_homed': m.is_homed, 'is_busy': m.is_busy, 'frame_id': m.header.frame_id,
                  'stamp_sec': m.header.stamp.sec}}))
node.destroy_node()
rclpy.shutdown()
'''


def test_operating_state_round_trip_between_processes(tmp_path):
    require_ros_tools()
    env = ros_env()
    pub = start('python', '-c', PUBLISHER, log=tmp_path / 'publisher.log', env=env)
    try:
        sub = run('python', '-c', SUBSCRIBER, timeout=90, env=env)
        assert pub.poll() is None, (tmp_path / 'publisher.log').read_text()
    finally:
        code = stop(pub, signal.SIGINT)
    assert sub.returncode == 0, sub.stderr
    received = json.loads(sub.stdout.strip().splitlines()[-1])
    assert received['type'] == 'crtk_msgs.msg._operating_state.OperatingState'
    assert (received['state'], received['is_homed'], received['is_busy'], received['frame_id']) == \
        ('ENABLED', True, False, 'PSM1')
    assert received['stamp_sec'] > 0
    assert code == 0, (tmp_path / 'publisher.log').read_text()


def test_dvrk_client_imports_with_pykdl():
    require_ros_tools()
    # dvrk/__init__.py exports the arm classes: dvrk.psm is the PSM class of dvrk/psm.py.
    probe = run('python', '-c', 'import sys, PyKDL, crtk, dvrk; '
                'print(dvrk.psm.__name__, sys.modules[dvrk.psm.__module__].__file__, '
                'PyKDL.__file__, PyKDL.Vector(1, 2, 3).Norm())')
    assert probe.returncode == 0, probe.stderr
    name, psm_file, kdl_file, norm = probe.stdout.split()
    assert name == 'psm'
    assert '/site-packages/dvrk/psm.py' in psm_file       # installed into the venv
    assert '/ros/pykdl/' in kdl_file                       # Debian's python3-pykdl, unpacked
    assert abs(float(norm) - 14 ** 0.5) < 1e-12
