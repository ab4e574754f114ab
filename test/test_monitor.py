"""grip-force monitor against a real publisher on loopback DDS."""
import io
import os
import threading
import time

import pytest

from _interrupts import raise_as_pybind11_does
from grip_force_ros import topics
from grip_force_ros.lab.demo.monitor import Snapshot, controller_mode, plain_line, render

pytestmark = pytest.mark.ros


def test_render_shows_values_units_and_silence():
    snap = Snapshot(elapsed=1.0, values={'target_force': 4.0, 'measured_force': 3.95},
                    ages={topics.TARGET_FORCE: 0.01, topics.MEASURED_FORCE: 5.0},
                    rates={topics.TARGET_FORCE: 1000.0},
                    diagnostics=[{'name': 'grip_force: controller', 'level': 1,
                                  'message': 'current limit', 'values': {'mode': 'grip'}}])
    text = '\n'.join(render(snap, 'domain 7'))
    assert '4.000 N' in text and '3.950 N' in text
    assert '1000 Hz' in text and 'silent 5.0 s' in text
    assert 'mode             grip' in text
    assert '[WARN ] grip_force: controller: current limit' in text
    line = plain_line(snap)
    assert 'target=4.000' in line and 'measured=3.950' in line and 'diag=WARN' in line
    assert controller_mode([]) == '?'
    snap.values.update(estimate_band_low=0.0, estimate_band_high=7.269)
    snap.ages[topics.ESTIMATE_BAND] = 0.01
    assert 'estimate band      0.000 .. 7.269 N' in '\n'.join(render(snap))


def _publish(domain_id: int, stop: threading.Event) -> None:
    import rclpy
    from rclpy.context import Context
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    node = rclpy.create_node('fake_controller', context=ctx)
    target = node.create_publisher(WrenchStamped, topics.TARGET_FORCE, 10)
    estimate = node.create_publisher(WrenchStamped, topics.ESTIMATED_FORCE, 10)
    command = node.create_publisher(JointState, topics.SERVO_CURRENT, 10)
    diag = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
    try:
        while not stop.is_set():
            w = WrenchStamped()
            w.wrench.force.z = 2.5
            target.publish(w)
            w.wrench.force.z, w.wrench.force.x = 2.4, 0.36
            estimate.publish(w)
            js = JointState(name=[topics.DRUM_JOINT], effort=[0.125])
            command.publish(js)
            d = DiagnosticArray()
            d.status = [DiagnosticStatus(level=DiagnosticStatus.OK, name='controller',
                                         message='gripping',
                                         values=[KeyValue(key='state', value='grip')])]
            diag.publish(d)
            time.sleep(0.01)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_monitor_shows_a_live_publisher_headless():
    from grip_force_ros.lab.demo.monitor import monitor

    domain = int(os.environ['ROS_DOMAIN_ID'])
    stop = threading.Event()
    pub = threading.Thread(target=_publish, args=(domain, stop), daemon=True)
    pub.start()
    out = io.StringIO()   # not a TTY: plain lines
    try:
        refreshes = monitor(duration=3.0, period=0.25, stream=out, domain_id=domain)
    finally:
        stop.set()
        pub.join(5)
    lines = out.getvalue().splitlines()
    assert refreshes == len(lines) >= 10
    assert not any('\033' in line for line in lines)
    last = lines[-1]
    assert 'target=2.500' in last and 'estimated=2.400' in last
    assert 'current_cmd=0.125' in last and 'mode=grip' in last and 'diag=OK' in last
    assert 'measured=-' in last.replace(' ', '')   # no load cell publishing: shown as missing


def test_monitor_redraws_in_place_on_a_tty():
    from grip_force_ros.lab.demo.monitor import monitor

    out = io.StringIO()
    monitor(duration=0.5, period=0.1, stream=out, domain_id=int(os.environ['ROS_DOMAIN_ID']),
            tty=True)
    text = out.getvalue()
    assert '\033[2K' in text and '\033[' in text and 'F' in text   # cursor moved back up
    assert text.count('grip-force monitor') >= 4
    assert 'no data' in text


def test_a_ctrl_c_inside_a_deserialization_ends_the_monitor_as_a_ctrl_c(monkeypatch):
    """A Ctrl-C inside rclpy's deserialize_message (in the monitor's main thread) is a Ctrl-C."""
    from grip_force_ros.lab.demo import monitor as monitor_module

    domain = int(os.environ['ROS_DOMAIN_ID'])
    monkeypatch.setattr(monitor_module._Collector, 'snapshot', raise_as_pybind11_does)
    assert monitor_module.monitor(duration=5.0, period=0.05, stream=io.StringIO(), domain_id=domain) == 0
    monkeypatch.setattr(monitor_module._Collector, 'snapshot', lambda self: int('not a number'))
    with pytest.raises(ValueError):                                  # a real error still raises
        monitor_module.monitor(duration=5.0, period=0.05, stream=io.StringIO(), domain_id=domain)
