"""Grip-force controller node (``controller``): a thin shell around ``GripController``.

Subscribes (KEEP_LAST 1; only the newest sample matters):
    master/gripper/measured_js        gripper: position (rad)
    instrument/measured_js            wrist_pitch, jaw: position (rad), velocity (rad/s, optional)
    instrument/actuator/measured_js   jaw_drum: position (rad), velocity (rad/s),
                                      effort = measured current (A)
    grip/measured_force               force.z = grip force (N), only when force_sensor_enabled
Publishes, every control step (one per control period, ``control_rate``, 1 kHz):
    instrument/actuator/servo_jf      jaw_drum: effort = current command (A)
        at once;
    grip/estimated_force              force.z = grip force (N), force.x = needle pull-out force (N)
    grip/target_force                 force.z = target grip force (N)
        when the instrument's next joint state comes in (the sim sends it once the
        command reached it), at the latest before the next step's command, so that
        they do not compete with the loop for the CPU while it closes (measured:
        BENCHMARKS.md, "The controller sends the estimated and target force after
        the loop has closed").
and ``/diagnostics`` at 10 Hz and on a change of mode, limits or input faults.

Loop timing, as hardware interfaces do it: the control step runs when a fresh
actuator state arrives (in its subscription callback), so each command answers
the newest state without waiting for a free-running timer (two unsynchronised
1 kHz timers, the sim's and the controller's, would add a 0-1 ms wait whose
phase is fixed for a whole run). The ``control_rate`` timer stays as the
watchdog and fallback: it steps when no state came for
:data:`FALLBACK_AFTER_PERIODS` periods (a lost state, or silence: then it steps
every period, and the safe state still comes within two periods of
``watchdog_timeout``), never within half a period of the previous step. A state
that is merely late (jitter under half a period) gets no extra step: an extra
step would repeat the same measurement and cost both processes a callback.
Every actuator state is stepped on: the PID assumes one step per period, so
the actuator state is expected at ``control_rate`` (the sim publishes at
``publish_rate`` = 1 kHz). Cancelling the timer stops the loop altogether (no
step on states either).

Stamps: the current command of a step on a fresh actuator state (accepted,
with a non-zero stamp) carries that state's header stamp, a reply stamp in the
instrument's own clock: the instrument can tell the age of each command (the sim
measures the loop's round trip this way, arrival minus stamp). Commands of the
timer fallback, and of a step on a state that was rejected, duplicated or
unstamped, carry the controller's clock. The force outputs and /diagnostics
always carry the controller's clock at the step (an instrument with a wrong
clock does not put wrong times on them).

A malformed message (unknown or missing joint names, wrong array lengths, NaN)
is rejected with its reason; the last good input is kept. All the control
logic, the plausibility checks and the watchdog live in
:mod:`grip_force_ros.control`.
"""
from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.control import SOURCES, ControlInputs, GripController, Mode
from grip_force_ros.nodes.common import (DIAGNOSTICS_QOS, STATE_PUB_QOS, STATE_SUB_QOS,
                                         InputRejected, read_joints, run_node, stamp_seconds)
from grip_force_ros.nodes.ros_params import declare_node_parameters

GROUPS = ('instrument', 'limits', 'controller')
#: Periodic /diagnostics rate (Hz); changes are published sooner, at most this often:
DIAGNOSTICS_RATE = 10.0
DIAGNOSTICS_MIN_INTERVAL = 0.01  # s
#: The timer does not step sooner than this many periods after the previous step:
MIN_STEP_SPACING_PERIODS = 0.5
#: The timer steps only when no actuator state came for this many periods:
FALLBACK_AFTER_PERIODS = 1.5
#: A timer tick this many periods after the previous one follows a stall of this process:
#: it does not step (once), so that the states that came in meanwhile are taken first.
STALL_PERIODS = 5.0

_MASTER_JOINTS = (topics.MASTER_JOINT,)
_INSTRUMENT_JOINTS = (topics.WRIST_JOINT, topics.JAW_JOINT)
_ACTUATOR_JOINTS = (topics.DRUM_JOINT,)
#: The plausibility ranges of ControlInputs (copied on a runtime parameter change).
_INPUT_RANGES = ('master_angle_min', 'master_angle_max', 'master_angle_tolerance',
                 'jaw_angle_min', 'jaw_angle_max', 'wrist_angle_limit', 'current_limit',
                 'force_limit', 'stamp_future_tolerance')


class ControllerNode(Node):
    """Runs :class:`GripController` once per actuator state, the timer as watchdog fallback."""

    def __init__(self, **kwargs):
        super().__init__('controller', **kwargs)
        self.finished = Future()
        self._param = declare_node_parameters(self, GROUPS, on_update=self._on_params)
        params = self._param.params
        self.controller = GripController(params)
        self.inputs: ControlInputs = self.controller.new_inputs()
        self.last_output = None
        self._now_ns = self.get_clock().now
        self._sub_qos = STATE_SUB_QOS

        self.create_subscription(JointState, topics.MASTER_JS, self._on_master, STATE_SUB_QOS)
        self.create_subscription(JointState, topics.INSTRUMENT_JS, self._on_instrument,
                                 STATE_SUB_QOS)
        self.create_subscription(JointState, topics.ACTUATOR_JS, self._on_actuator,
                                 STATE_SUB_QOS)
        self._force_sub = None
        self._update_force_subscription(params.force_sensor_enabled)

        self._servo_pub = self.create_publisher(JointState, topics.SERVO_CURRENT, STATE_PUB_QOS)
        self._estimate_pub = self.create_publisher(WrenchStamped, topics.ESTIMATED_FORCE,
                                                   STATE_PUB_QOS)
        self._target_pub = self.create_publisher(WrenchStamped, topics.TARGET_FORCE,
                                                 STATE_PUB_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                               DIAGNOSTICS_QOS)
        # Messages reused every period (1 kHz): fill, do not rebuild.
        self._servo_msg = JointState(name=[topics.DRUM_JOINT], effort=[0.0])
        self._estimate_msg = WrenchStamped()
        self._estimate_msg.header.frame_id = topics.JAW_FRAME
        self._target_msg = WrenchStamped()
        self._target_msg.header.frame_id = topics.JAW_FRAME

        self._forces_pending = False   # estimated/target force of the last step not sent yet
        self._diag_key = None          # (mode, limits_hit, reasons, rejected count) last published
        self._diag_time = -math.inf    # s, when /diagnostics was last published
        self._limits_seen: set = set()  # limits hit since the last /diagnostics
        self._new_rejections: list = []  # rejection reasons since the last /diagnostics
        # Loop timing (perf_counter s): for /diagnostics and the loop benchmark.
        self._period = 1.0 / params.control_rate
        self.timing = {'ticks': 0, 'late': 0, 'period_sum': 0.0, 'period_max': 0.0,
                       'busy_sum': 0.0, 'busy_max': 0.0}
        self._last_tick = None
        # Step scheduling (perf_counter s): see the module docstring.
        self._min_spacing = MIN_STEP_SPACING_PERIODS * self._period
        self._fallback_after = FALLBACK_AFTER_PERIODS * self._period
        self._last_step = -math.inf        # when the last control step started
        self._last_timer = -math.inf       # when the timer last fired
        self._late_reported = 0            # late inputs counted at the last /diagnostics
        self._last_state_step = -math.inf  # when the last step on an actuator state started
        self.steps = {'on_state': 0, 'on_timer': 0, 'deferred_after_stall': 0}   # by trigger
        self._timer = self.create_timer(1.0 / params.control_rate, self._tick)
        self.get_logger().info(
            f'{params.instrument_name}: control at {params.control_rate:.0f} Hz, '
            f"feedback {'force sensor' if params.force_sensor_enabled else 'model estimate'}, "
            f'object {params.object_kind}')

    # ------------------------------------------------------------------ time
    def _now(self) -> float:
        """Return the controller clock (s), the clock of receive times and of the watchdog."""
        return self._now_ns().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs
    def _reject(self, source: str, now: float, exc: InputRejected) -> None:
        reason = self.inputs.reject(source, now, f'malformed message: {exc}')
        self._note_rejection(reason)
        self.get_logger().warning(f'rejected {reason}', throttle_duration_sec=1.0)

    def _note_rejection(self, reason: str) -> None:
        """Keep a rejection for the next /diagnostics, even if it is over by then."""
        if reason not in self._new_rejections and len(self._new_rejections) < 5:
            self._new_rejections.append(reason)

    def _report(self, reason) -> None:
        if reason is not None:
            self._note_rejection(reason)
            self.get_logger().warning(f'rejected {reason}', throttle_duration_sec=1.0)

    def _on_master(self, msg: JointState) -> None:
        now = self._now()
        try:
            (angle,), = read_joints(msg, _MASTER_JOINTS, ('position',)).values()
        except InputRejected as exc:
            return self._reject('master', now, exc)
        self._report(self.inputs.set_master(now, angle, stamp_seconds(msg.header.stamp)))

    def _on_instrument(self, msg: JointState) -> None:
        now = self._now()
        fields = ('position', 'velocity') if len(msg.velocity) else ('position',)
        try:
            joints = read_joints(msg, _INSTRUMENT_JOINTS, fields)
        except InputRejected as exc:
            return self._reject('instrument', now, exc)
        if self._forces_pending:        # the loop has closed (the instrument sent its joints)
            self._publish_forces()
        wrist, jaw = joints[topics.WRIST_JOINT], joints[topics.JAW_JOINT]
        jaw_velocity = jaw[1] if len(jaw) > 1 else 0.0
        self._report(self.inputs.set_instrument(now, wrist[0], jaw[0], jaw_velocity,
                                                stamp_seconds(msg.header.stamp)))

    def _on_actuator(self, msg: JointState) -> None:
        """Actuator state: store it and run the control step on it (event-driven loop)."""
        fresh = self._read_actuator(msg)
        if not self._timer.is_canceled():  # cancelled: the loop is stopped
            self.steps['on_state'] += 1
            started = time.perf_counter()
            self._last_state_step = started
            self._step(started, msg.header.stamp if fresh else None)

    def _read_actuator(self, msg: JointState) -> bool:
        """Store the actuator state; True if it was accepted as a new, stamped sample."""
        now = self._now()
        fields = ('effort', 'position', 'velocity') if len(msg.velocity) else ('effort', 'position')
        try:
            (drum,) = read_joints(msg, _ACTUATOR_JOINTS, fields).values()
        except InputRejected as exc:
            self._reject('actuator', now, exc)
            return False
        velocity = drum[2] if len(drum) > 2 else 0.0
        stamp = stamp_seconds(msg.header.stamp)
        self._report(self.inputs.set_actuator(now, drum[0], drum[1], velocity, stamp))
        # accepted now (a duplicate or rejected sample leaves actuator_time as it was)
        return self.inputs.actuator_time == now and stamp != 0.0

    def _on_force(self, msg: WrenchStamped) -> None:
        self._report(self.inputs.set_force(self._now(), msg.wrench.force.z,
                                           stamp_seconds(msg.header.stamp)))

    def _update_force_subscription(self, enabled: bool) -> None:
        if enabled and self._force_sub is None:
            self._force_sub = self.create_subscription(WrenchStamped, topics.MEASURED_FORCE,
                                                       self._on_force, STATE_SUB_QOS)
        elif not enabled and self._force_sub is not None:
            self.destroy_subscription(self._force_sub)
            self._force_sub = None

    # ------------------------------------------------------------------ parameters
    def _on_params(self, params, changed) -> None:
        """Apply an accepted runtime change: retune bumplessly, keep the latest inputs."""
        self.controller.update_params(params)
        fresh = self.controller.new_inputs()
        for name in _INPUT_RANGES:
            setattr(self.inputs, name, getattr(fresh, name))
        self._update_force_subscription(params.force_sensor_enabled)
        self.get_logger().info(f'parameters changed: {sorted(changed)}')

    # ------------------------------------------------------------------ loop
    def _tick(self) -> None:
        """Run the ``control_rate`` timer: watchdog and fallback of the event-driven loop.

        Steps when no actuator state came for :data:`FALLBACK_AFTER_PERIODS`
        periods (a lost state; when they stop, every period, so the watchdog acts
        on the stale inputs), never within :data:`MIN_STEP_SPACING_PERIODS` of
        the previous step. A tick more than :data:`STALL_PERIODS` after the previous
        one (this process was not scheduled) does not step: the states that came in
        meanwhile run first, so a stall of this process is not taken for a lost input
        (the next tick, a period later, steps if none came).
        """
        started = time.perf_counter()
        previous, self._last_timer = self._last_timer, started
        if previous != -math.inf and started - previous > STALL_PERIODS * self._period:
            # this process did not run for a while: the inputs' age says nothing about them
            # until the callbacks queued meanwhile have run (a scheduling stall, not a fault)
            self.steps['deferred_after_stall'] += 1
            return
        if (started - self._last_state_step >= self._fallback_after
                and started - self._last_step >= self._min_spacing):
            self.steps['on_timer'] += 1
            self._step(started)

    def _step(self, started: float, answered_stamp=None) -> None:
        """One control step, timed (``started``: perf_counter s, now).

        ``answered_stamp``: header stamp of the fresh actuator state the step answers
        (the current command carries it), or None (the controller's clock).
        """
        self._last_step = started
        self._control(answered_stamp)
        timing = self.timing
        busy = time.perf_counter() - started
        timing['busy_sum'] += busy
        if busy > timing['busy_max']:
            timing['busy_max'] = busy
        if self._last_tick is not None:
            period = started - self._last_tick
            timing['ticks'] += 1
            timing['period_sum'] += period
            if period > timing['period_max']:
                timing['period_max'] = period
            if period > 1.5 * self._period:
                timing['late'] += 1
        self._last_tick = started

    def _publish_forces(self) -> None:
        """Estimated and target force of the last step (stamped with its time)."""
        self._forces_pending = False
        self._estimate_pub.publish(self._estimate_msg)
        self._target_pub.publish(self._target_msg)

    def _control(self, answered_stamp=None) -> None:
        if self._forces_pending:        # the previous step's, not sent yet: first
            self._publish_forces()
        stamp = self._now_ns()
        now = stamp.nanoseconds * 1e-9
        out = self.controller.step(now, self.inputs)
        self.last_output = out
        stamp_msg = stamp.to_msg()

        servo = self._servo_msg
        servo.header.stamp = answered_stamp if answered_stamp is not None else stamp_msg
        servo.effort[0] = out.current_command
        self._servo_pub.publish(servo)

        est = self._estimate_msg
        est.header.stamp = stamp_msg
        est.wrench.force.z = out.estimated_force
        est.wrench.force.x = out.pull_out_force
        target = self._target_msg
        target.header.stamp = stamp_msg
        target.wrench.force.z = out.target_force
        self._forces_pending = True     # sent once the loop has closed, see _on_instrument

        if out.limits_hit:
            self._limits_seen.update(out.limits_hit)
        key = (out.mode, out.limits_hit, out.reasons, len(self.inputs.rejected))
        since = now - self._diag_time
        if since >= 1.0 / DIAGNOSTICS_RATE or ((key != self._diag_key or self._new_rejections)
                                               and since >= DIAGNOSTICS_MIN_INTERVAL):
            self._publish_diagnostics(stamp_msg, out)
            self._diag_key, self._diag_time = key, now

    def diagnostic_status(self, out) -> DiagnosticStatus:
        """Build the controller's DiagnosticStatus for the last output ``out``."""
        params = self._param.params
        late = sum(self.controller.late_counts.values())
        if out is None or out.mode is Mode.SAFE:
            level = DiagnosticStatus.ERROR
        elif out.limits_hit or out.reasons or self._limits_seen or late > self._late_reported:
            level = DiagnosticStatus.WARN   # late inputs since the last report: a warning
        else:
            level = DiagnosticStatus.OK
        mode = out.mode if out is not None else 'starting'
        reasons = '; '.join(out.reasons) if out is not None and out.reasons else 'ok'
        values = dict(self.controller.status(self.inputs))
        values['limits_hit'] = ', '.join(sorted(self._limits_seen)) or 'none'
        tripped = out is not None and out.mode is Mode.SAFE and any(
            'stale' in r or 'input yet' in r for r in out.reasons)
        values['watchdog'] = 'tripped' if tripped else 'ok'
        values['watchdog_timeout_s'] = f'{params.watchdog_timeout:g}'
        values.update((f'watchdog_timeout_{source}_s', f'{timeout:g}')
                      for source, timeout in self.controller.timeouts.items())
        faults = [getattr(self.inputs, f'{s}_fault') for s in SOURCES]
        values['input_faults'] = '; '.join(f for f in faults if f) or 'none'
        values['new_rejections'] = '; '.join(self._new_rejections) or 'none'
        timing = self.timing
        if timing['ticks']:
            values['period_mean_ms'] = f"{timing['period_sum'] / timing['ticks'] * 1e3:.4f}"
            values['period_max_ms'] = f"{timing['period_max'] * 1e3:.3f}"
            values['late_periods'] = str(timing['late'])   # longer than 1.5 periods
            values['tick_mean_us'] = f"{timing['busy_sum'] / timing['ticks'] * 1e6:.1f}"
            values['tick_max_us'] = f"{timing['busy_max'] * 1e6:.1f}"
        values['steps_on_state'] = str(self.steps['on_state'])   # stepped on an actuator state
        values['steps_on_timer'] = str(self.steps['on_timer'])   # fallback: no fresh state
        values['steps_deferred_after_stall'] = str(self.steps['deferred_after_stall'])
        if out is not None:
            values['target_force_N'] = f'{out.target_force:.3f}'
            values['pull_out_force_N'] = f'{out.pull_out_force:.3f}'
        return DiagnosticStatus(
            level=level, name='grip_force_ros: controller', message=f'{mode}: {reasons}',
            hardware_id=params.instrument_name,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])

    def _publish_diagnostics(self, stamp_msg, out) -> None:
        array = DiagnosticArray()
        array.header.stamp = stamp_msg
        array.status = [self.diagnostic_status(out)]
        self._diag_pub.publish(array)
        self._limits_seen = set()
        self._new_rejections = []
        self._late_reported = sum(self.controller.late_counts.values())


def main(args=None) -> int:
    """Run the executable ``controller``."""
    return run_node(ControllerNode, 'controller', args)


if __name__ == '__main__':
    import sys
    sys.exit(main())
