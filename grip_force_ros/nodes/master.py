"""Master source node: publishes the master gripper opening (``master``).

Publishes ``master/gripper/measured_js`` (``interface`` crtk; dvrk: the dVRK master's
``<master>/gripper/measured_js``, e.g. ``MTML/gripper/measured_js``, 100 Hz by default)
(JointState, joint ``gripper``: position = opening (rad), velocity (rad/s)) at
``master_rate`` from a scripted trajectory or a replay (:mod:`grip_force_ros.trajectories`). The trajectory
clock starts when a subscriber is matched (``start_when_subscribed``). After a
non-repeating trajectory ends it keeps publishing the last angle (a silent
master would trip the controller's watchdog), or exits when
``exit_when_done`` is true.
"""
from __future__ import annotations

import time

from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.nodes.common import STATE_PUB_QOS
from grip_force_ros.nodes.lifetime import run_node
from grip_force_ros.nodes.realtime import loop_log
from grip_force_ros.nodes.ros_params import declare_node_parameters
from grip_force_ros.nodes.wire import JointStateWriter
from grip_force_ros.trajectories import MASTER_SPECS, Trajectory, make_trajectory

#: How long after the end of the trajectory an ``exit_when_done`` master keeps publishing (s).
EXIT_GRACE = 0.5


class MasterNode(Node):
    """Scripted or replayed master gripper angle, published at a fixed rate."""

    def __init__(self, **kwargs):
        super().__init__('master', **kwargs)
        self.finished = Future()
        self._param = declare_node_parameters(self, groups=('interface', 'realtime'),
                                              extra_specs=MASTER_SPECS,
                                              on_update=self._on_params, check=self._check)
        self.trajectory: Trajectory = self._build(self._values())
        params = self._param.params
        self.topic = topics.topic_set(params.interface, params.arm, params.master).master_js
        self._pub = self.create_publisher(JointState, self.topic, STATE_PUB_QOS)
        # serialized once; each tick writes its stamp and values in place (nodes/wire.py)
        self._msg = JointStateWriter([topics.MASTER_JOINT], ('position', 'velocity'))
        self._start = time.monotonic()
        self._started = False            # trajectory clock running (see start_when_subscribed)
        self._last_phase = None
        self._timer = self.create_timer(1.0 / self._param.value('master_rate'), self._tick)
        self.get_logger().info(
            f"publishing {self._param.value('trajectory')} ({self.trajectory.duration:.2f} s) "
            f"at {self._param.value('master_rate'):.0f} Hz on {self.topic}")

    def _values(self, values=None) -> dict:
        if values is None:
            values = {s.name: self._param.value(s.name) for s in MASTER_SPECS}
        return values

    @staticmethod
    def _build(values) -> Trajectory:
        return make_trajectory(values['trajectory'], values['trajectory_file'],
                               master_open_angle=values['master_open_angle'],
                               master_closed_angle=values['master_closed_angle'],
                               time_scale=values['time_scale'])

    def _check(self, values) -> None:
        """Cross-check: the trajectory must build (reads a replay file; no side effects)."""
        self._build(values)

    def _on_params(self, _params, changed) -> None:
        if changed & {'trajectory', 'trajectory_file', 'master_open_angle', 'master_closed_angle',
                      'time_scale'}:
            self.trajectory = self._build(self._values())
            self._start = time.monotonic()
            self._started = False
            self._last_phase = None
        if 'master_rate' in changed:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / self._param.value('master_rate'), self._tick)

    def elapsed(self) -> float:
        """Time since the trajectory started (s), wrapped when repeating; 0 until it starts."""
        if not self._started:
            if self._param.value('start_when_subscribed') and self._pub.get_subscription_count() == 0:
                return 0.0
            self._started = True
            self._start = time.monotonic()
        t = time.monotonic() - self._start
        if self._param.value('repeat') and self.trajectory.duration > 0:
            t %= self.trajectory.duration
        return t

    def _tick(self) -> None:
        t = self.elapsed()
        traj = self.trajectory
        angle = traj.angle(t)
        dt = 1e-3
        velocity = 0.0
        if 0.0 < t < traj.duration:
            velocity = (traj.angle(t + dt) - traj.angle(t - dt)) / (2 * dt)
        sec, nanosec = divmod(self.get_clock().now().nanoseconds, 1_000_000_000)
        self._pub.publish(self._msg.write(sec, nanosec, (angle,), (velocity,)))
        phase = traj.phase(t)
        if phase != self._last_phase:
            loop_log(self).put('info', f'phase {phase} at t={t:.2f} s, master angle {angle:.3f} rad')
            self._last_phase = phase
        if self._param.value('exit_when_done') and not self._param.value('repeat') \
                and t > traj.duration + EXIT_GRACE and not self.finished.done():
            self.finished.set_result(True)


def main(args=None) -> int:
    """Run the executable ``master``."""
    return run_node(MasterNode, 'master', args)


if __name__ == '__main__':
    import sys
    sys.exit(main())
