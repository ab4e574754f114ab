"""Simulated instrument node (``sim_instrument``): a thin shell around ``InstrumentSim``.

Subscribes (KEEP_LAST 1):
    instrument/actuator/servo_jf      jaw_drum: effort = motor current command (A)
Steps the plant in real time: a timer at ``publish_rate`` (1 kHz) advances the
simulation by the time actually elapsed since the last step (capped at
:data:`MAX_STEP`, so a stalled process slows the simulation instead of
integrating one huge step), with the last accepted current command held.
Publishes each step's measurements, all with the same stamp (the time of the
measurement), in this order:
    instrument/actuator/measured_js   jaw_drum: position (rad), velocity (rad/s),
                                      effort = measured current (A)
        at once: the controller steps on it;
    instrument/measured_js            wrist_pitch, jaw: position (rad), velocity (rad/s)
    grip/measured_force               force.z = load-cell grip force (N)
        when the current command answering that state has come in (or at the next
        step, if none came), so that they do not compete with the loop for the CPU
        while it is closing (2 cores on the bench machine: in an interleaved A/B
        this took ~40 us off the median round trip, BENCHMARKS.md).
and its status on ``/diagnostics`` at 1 Hz, with the loop's round trip over the
last second: a command that carries the stamp of an actuator state it answers
(the controller's convention) took arrival minus stamp, both on this node's clock
(:class:`~grip_force_ros.sim.loop_latency.LoopLatency`).

The plant's parameters are the 'instrument', 'sim' and 'effects' groups of the
schema (``friction_scale`` and ``stiffness_scale`` make the plant differ from
the instrument file; the controller is not told). A malformed command
(unknown joint, wrong length, NaN) is rejected and the last good one is held.
"""
from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.nodes.common import (DIAGNOSTICS_QOS, STATE_PUB_QOS, STATE_SUB_QOS,
                                         InputRejected, read_joints, run_node, stamp_nanoseconds)
from grip_force_ros.nodes.ros_params import declare_node_parameters
from grip_force_ros.sim import InstrumentSim
from grip_force_ros.sim.loop_latency import LoopLatency

GROUPS = ('instrument', 'sim', 'effects')
#: Largest simulated step per timer period (s); longer stalls slow the simulation down.
MAX_STEP = 0.01
DIAGNOSTICS_PERIOD = 1.0  # s

_COMMAND_JOINTS = (topics.DRUM_JOINT,)


class SimInstrumentNode(Node):
    """Integrates :class:`InstrumentSim` in real time and publishes its sensors."""

    def __init__(self, **kwargs):
        super().__init__('sim_instrument', **kwargs)
        self.finished = Future()
        self._param = declare_node_parameters(self, GROUPS, on_update=self._on_params)
        params = self._param.params
        self.sim = InstrumentSim(params, obj=None, seed=params.sim_seed)
        self.current_command = 0.0       # A, last accepted command
        self.rejected = 0                # malformed commands
        self.last_rejection = ''
        self.commands = 0                # accepted commands
        self.capped_steps = 0            # periods whose elapsed time exceeded MAX_STEP
        self.loop = LoopLatency(capacity=int(2 * params.publish_rate * DIAGNOSTICS_PERIOD) + 16)

        self.create_subscription(JointState, topics.SERVO_CURRENT, self._on_command,
                                 STATE_SUB_QOS)
        self._joint_pub = self.create_publisher(JointState, topics.INSTRUMENT_JS, STATE_PUB_QOS)
        self._actuator_pub = self.create_publisher(JointState, topics.ACTUATOR_JS, STATE_PUB_QOS)
        self._force_pub = self.create_publisher(WrenchStamped, topics.MEASURED_FORCE,
                                                STATE_PUB_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                               DIAGNOSTICS_QOS)
        self._joint_msg = JointState(name=[topics.WRIST_JOINT, topics.JAW_JOINT],
                                     position=[0.0, 0.0], velocity=[0.0, 0.0])
        self._actuator_msg = JointState(name=[topics.DRUM_JOINT], position=[0.0],
                                        velocity=[0.0], effort=[0.0])
        self._force_msg = WrenchStamped()
        self._force_msg.header.frame_id = topics.JAW_FRAME
        self._sensors_pending = False    # joint state and force of the last step not yet sent

        self._last = time.monotonic()
        self._started = self._last
        self._timer = self.create_timer(1.0 / params.publish_rate, self._tick)
        self._diag_timer = self.create_timer(DIAGNOSTICS_PERIOD, self._publish_diagnostics)
        self.get_logger().info(
            f'{params.instrument_name}: object {self.sim.obj}, '
            f'friction x{params.friction_scale:g}, '
            f'stiffness x{params.stiffness_scale:g}, stepping at {params.publish_rate:.0f} Hz')

    # ------------------------------------------------------------------ input
    def _on_command(self, msg: JointState) -> None:
        arrival = self.get_clock().now().nanoseconds
        self.loop.command_received(stamp_nanoseconds(msg.header.stamp), arrival)
        try:
            (current,), = read_joints(msg, _COMMAND_JOINTS, ('effort',)).values()
        except InputRejected as exc:
            self.rejected += 1
            self.last_rejection = str(exc)
            self.get_logger().warning(f'rejected current command: {exc}',
                                      throttle_duration_sec=1.0)
            return
        self.current_command = current
        self.commands += 1
        if self._sensors_pending:
            self._publish_sensors()

    # ------------------------------------------------------------------ parameters
    def _on_params(self, params, changed) -> None:
        self.sim.set_params(params)
        if 'sim_object' in changed:
            self.sim.set_object(params.sim_object)
        if 'publish_rate' in changed:
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / params.publish_rate, self._tick)
        self.get_logger().info(f'parameters changed: {sorted(changed)}')

    # ------------------------------------------------------------------ loop
    def _tick(self) -> None:
        now = time.monotonic()
        dt = now - self._last
        self._last = now
        if dt <= 0.0:
            return
        if dt > MAX_STEP:
            dt = MAX_STEP
            self.capped_steps += 1
        if self._sensors_pending:      # no answer to the previous state came: publish them now
            self._publish_sensors()
        self.sim.step(self.current_command, dt)
        m = self.sim.measure()
        now = self.get_clock().now()
        stamp = now.to_msg()

        act = self._actuator_msg
        act.header.stamp = stamp
        act.position[0], act.velocity[0], act.effort[0] = m.motor_angle, m.motor_velocity, m.current
        self._actuator_pub.publish(act)
        self.loop.state_published(now.nanoseconds)

        js = self._joint_msg
        js.header.stamp = stamp
        js.position[0], js.position[1] = m.wrist_angle, m.jaw_angle
        js.velocity[1] = m.jaw_velocity
        force = self._force_msg
        force.header.stamp = stamp
        force.wrench.force.z = m.grip_force
        self._sensors_pending = True   # sent once the command answering this state is in

    def _publish_sensors(self) -> None:
        """Joint state and load cell of the last step (stamped with the actuator state's time)."""
        self._sensors_pending = False
        self._joint_pub.publish(self._joint_msg)
        self._force_pub.publish(self._force_msg)

    def _publish_diagnostics(self) -> None:
        params = self._param.params
        wall = time.monotonic() - self._started
        warn = self.rejected or self.capped_steps
        loop = self.loop.summary()
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if warn else DiagnosticStatus.OK,
            name='grip_force_ros: sim_instrument',
            message=f'simulating {self.sim.obj}' + (f'; rejected {self.rejected} commands'
                                                    if self.rejected else ''),
            hardware_id=params.instrument_name,
            values=[KeyValue(key=k, value=v) for k, v in {
                'object': self.sim.obj,
                'sim_time_s': f'{self.sim.t:.3f}',
                'real_time_factor': f'{self.sim.t / wall:.3f}' if wall > 0 else 'n/a',
                'current_command_A': f'{self.current_command:.4f}',
                'commands_accepted': str(self.commands),
                'commands_rejected': str(self.rejected),
                'last_rejection': self.last_rejection or 'none',
                'capped_steps': str(self.capped_steps),
                # the last second: actuator state -> command answering it, this node's clock
                'loop_round_trip_p50_ms': f"{loop['p50_ms']:.3f}",
                'loop_round_trip_p99_ms': f"{loop['p99_ms']:.3f}",
                'loop_round_trip_max_ms': f"{loop['max_ms']:.3f}",
                'loop_states_unanswered': str(loop['unanswered']),
                'friction_scale': f'{params.friction_scale:g}',
                'stiffness_scale': f'{params.stiffness_scale:g}',
            }.items()])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)


def main(args=None) -> int:
    """Run the executable ``sim_instrument``."""
    return run_node(SimInstrumentNode, 'sim_instrument', args)


if __name__ == '__main__':
    import sys
    sys.exit(main())
