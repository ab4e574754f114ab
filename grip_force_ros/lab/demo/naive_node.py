"""The naive baseline of the instrument comparison, as a tiny rclpy node.

What a system without a grip-force model does: motor current proportional to
how far the master gripper is closed past the contact angle, with ONE gain
for every instrument (``naive_current_closed``: the current at the fully
closed master). It publishes that command on
``instrument/actuator/servo_jf`` and, for the record, the target the real
controller's force map would set on ``grip/target_force``.

Run: ``python -m grip_force_ros.lab.demo.naive_node --ros-args --params-file X.yaml
-p naive_current_closed:=0.3``. Only the demo's ``--compare-instruments`` uses it.
"""
from __future__ import annotations

import sys

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.control import Mode
from grip_force_ros.nodes.lifetime import shutdown_once
from grip_force_ros.params import SPECS

_USED = ('master_angle_min', 'master_contact_angle', 'grip_force_max', 'force_map_exponent',
         'max_current')


def closing_share(master_angle: float, contact_angle: float, closed_angle: float) -> float:
    """Share (0..1) of the master travel from the contact angle to fully closed (rad in)."""
    span = contact_angle - closed_angle
    if span <= 0:
        return 1.0 if master_angle <= closed_angle else 0.0
    return min(1.0, max(0.0, (contact_angle - master_angle) / span))


class NaiveNode(Node):
    """Current = naive_current_closed * closing share; no model, no feedback."""

    def __init__(self):
        super().__init__('controller', allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True)
        self.values = {name: self._get(name, SPECS[name].default) for name in _USED}
        self.current_closed = float(self._get('naive_current_closed', 0.0))
        rate = float(self._get('naive_rate', 500.0))
        self.master_angle = None
        self.sub = self.create_subscription(JointState, topics.MASTER_JS, self._on_master, 10)
        self.pub_current = self.create_publisher(JointState, topics.SERVO_CURRENT, 10)
        self.pub_target = self.create_publisher(WrenchStamped, topics.TARGET_FORCE, 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self.timer = self.create_timer(1.0 / rate, self._tick)
        self.diag_timer = self.create_timer(0.2, self._diagnostics)

    def _diagnostics(self) -> None:
        """Report mode 'safe' until the master arrives, then 'free' or 'grip' (as the controller)."""
        share = 0.0 if self.master_angle is None else closing_share(
            self.master_angle, self.values['master_contact_angle'], self.values['master_angle_min'])
        mode = Mode.SAFE if self.master_angle is None else (Mode.GRIP if share > 0 else Mode.FREE)
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [DiagnosticStatus(
            level=DiagnosticStatus.OK if self.master_angle is not None else DiagnosticStatus.WARN,
            name='controller (naive map)', hardware_id='naive',
            message='no master yet' if self.master_angle is None else 'open loop',
            values=[KeyValue(key='mode', value=mode.value),
                    KeyValue(key='naive_current_closed', value=f'{self.current_closed:.4f}')])]
        self.pub_diag.publish(msg)

    def _get(self, name, default):
        if self.has_parameter(name):
            value = self.get_parameter(name).value
            return default if value is None else value
        return default

    def _on_master(self, msg: JointState) -> None:
        if len(msg.position):
            self.master_angle = float(msg.position[0])

    def _tick(self) -> None:
        stamp = self.get_clock().now().to_msg()
        share = 0.0 if self.master_angle is None else closing_share(
            self.master_angle, self.values['master_contact_angle'], self.values['master_angle_min'])
        current = min(self.current_closed * share, self.values['max_current'])  # A
        cmd = JointState()
        cmd.header.stamp = stamp
        cmd.name = [topics.DRUM_JOINT]
        cmd.effort = [current]
        self.pub_current.publish(cmd)
        target = WrenchStamped()
        target.header.stamp = stamp
        target.header.frame_id = topics.JAW_FRAME
        exponent = self.values['force_map_exponent']
        target.wrench.force.z = self.values['grip_force_max'] * share ** exponent   # N
        self.pub_target.publish(target)


def main(args=None) -> int:
    rclpy.init(args=args)
    node = NaiveNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        shutdown_once()    # a SIGINT may shut the context down under try_shutdown
    return 0


if __name__ == '__main__':
    sys.exit(main())
