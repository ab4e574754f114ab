"""Grip-force controller node (``controller``): a thin shell around ``GripController``.

Its topics depend on the ``interface`` parameter: ``crtk`` (this package's topics, the
current in A) or ``dvrk`` (a da Vinci Research Kit PSM's and MTM's topics, the jaw effort
in N*m, the arm's operating state); the wiring of each profile is
:mod:`grip_force_ros.nodes.controller_io`. In ``crtk``:

Subscribes (KEEP_LAST 1; only the newest sample matters):
    master/gripper/measured_js        gripper: position (rad)
    instrument/measured_js            wrist_pitch, jaw: position (rad), velocity (rad/s, optional)
    instrument/actuator/measured_js   jaw_drum: position (rad), velocity (rad/s),
                                      effort = measured current (A)
    grip/measured_force               force.z = grip force (N), only when force_sensor_enabled
Publishes, every control step (one per instrument state, ``expected_state_rate``):
    instrument/actuator/servo_jf      jaw_drum: effort = current command (A)
    grip/estimated_force              force.z = grip force (N), force.x = needle pull-out force (N)
    grip/target_force                 force.z = target grip force (N)
        in this order, in the step (deferring the two forces until the loop had closed was
        measured and dropped: BENCHMARKS.md, "Full path").
and ``/diagnostics`` at 10 Hz and on a change of mode, limits or input faults.

Loop timing, as hardware interfaces do it: the control step runs when a fresh
instrument state arrives (the actuator state; dvrk: the jaw's ``measured_js``, in its
subscription callback), so each command answers the newest state without waiting for a
free-running timer. The step integrates over the time measured since the previous step
(:class:`~grip_force_ros.control.GripController`), so the loop is the same at any state
rate from 100 to 1500 Hz (``expected_state_rate``; the dVRK publishes at 100 Hz). The
``control_rate`` timer (1 kHz) is the watchdog and fallback: it steps when no state came
for :data:`FALLBACK_AFTER_PERIODS` state periods (a lost state, or silence: then it steps
every half state period at most, and the safe state still comes within a timer period or
two of ``watchdog_timeout``), never within :data:`MIN_STEP_SPACING_PERIODS` of the previous
step. Cancelling the timer stops the loop altogether (no step on states either).

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
from rclpy.node import Node
from rclpy.task import Future

from grip_force_ros import topics
from grip_force_ros.control import SOURCES, ControlInputs, GripController, Mode
from grip_force_ros.nodes.common import DIAGNOSTICS_QOS, InputRejected, run_node
from grip_force_ros.nodes.controller_io import controller_io
from grip_force_ros.nodes.ros_params import declare_node_parameters

GROUPS = ('instrument', 'limits', 'controller', 'interface')
#: Periodic /diagnostics rate (Hz); changes are published sooner, at most this often:
DIAGNOSTICS_RATE = 10.0
DIAGNOSTICS_MIN_INTERVAL = 0.01  # s
#: The timer does not step sooner than this many state periods after the previous step:
MIN_STEP_SPACING_PERIODS = 0.5
#: The timer steps only when no instrument state came for this many state periods:
FALLBACK_AFTER_PERIODS = 1.5
#: A timer tick this many timer periods after the previous one follows a stall of this process:
#: it does not step (once), so that the states that came in meanwhile are taken first.
STALL_PERIODS = 5.0

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
        self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                               DIAGNOSTICS_QOS)
        self._diag_key = None          # (mode, limits_hit, reasons, rejected count) last published
        self._diag_time = -math.inf    # s, when /diagnostics was last published
        self._limits_seen: set = set()  # limits hit since the last /diagnostics
        self._new_rejections: list = []  # rejection reasons since the last /diagnostics
        # Loop timing (perf_counter s): for /diagnostics and the loop benchmark.
        self._period = 1.0 / params.expected_state_rate     # s, nominal time between states
        self.timing = {'ticks': 0, 'late': 0, 'period_sum': 0.0, 'period_max': 0.0,
                       'busy_sum': 0.0, 'busy_max': 0.0}
        self._last_tick = None
        # Step scheduling (perf_counter s): see the module docstring.
        self._min_spacing = MIN_STEP_SPACING_PERIODS * self._period
        self._fallback_after = FALLBACK_AFTER_PERIODS * self._period
        self._last_step = -math.inf        # when the last control step started
        self._last_timer = -math.inf       # when the timer last fired
        self._timer_period = 1.0 / params.control_rate   # s, between timer ticks
        self._late_reported = 0            # late inputs counted at the last /diagnostics
        self._last_state_step = -math.inf  # when the last step on an instrument state started
        self.steps = {'on_state': 0, 'on_timer': 0, 'deferred_after_stall': 0}   # by trigger
        self._timer = self.create_timer(1.0 / params.control_rate, self._tick)
        try:                               # the profile's topics (dvrk: needs crtk_msgs)
            self.io = controller_io(self, params)
        except ValueError:
            self.destroy_node()            # refuse to start: leave nothing in the ROS graph
            raise
        where = (f'arm {params.arm}, master {params.master}' if params.interface == 'dvrk'
                 else 'crtk topics')
        self.get_logger().info(
            f'{params.instrument_name}: {params.interface} interface ({where}), stepping on '
            f'instrument states (expected {params.expected_state_rate:g} Hz), watchdog timer '
            f'{params.control_rate:.0f} Hz, feedback '
            f"{'force sensor' if params.force_sensor_enabled else 'model estimate'}, "
            f'object {params.object_kind}')

    # ------------------------------------------------------------------ time
    def now(self) -> float:
        """Return the controller clock (s), the clock of receive times and of the watchdog."""
        return self._now_ns().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs (the profile's)
    def reject(self, source: str, now: float, exc: InputRejected) -> None:
        """Count a malformed message of ``source``: the input is faulted until a good one."""
        reason = self.inputs.reject(source, now, f'malformed message: {exc}')
        self._note_rejection(reason)
        self.get_logger().warning(f'rejected {reason}', throttle_duration_sec=1.0)

    def _note_rejection(self, reason: str) -> None:
        """Keep a rejection for the next /diagnostics, even if it is over by then."""
        if reason not in self._new_rejections and len(self._new_rejections) < 5:
            self._new_rejections.append(reason)

    def report(self, reason) -> None:
        """Note the result of a ``set_*`` of the inputs (None, or why the sample was rejected)."""
        if reason is not None:
            self._note_rejection(reason)
            self.get_logger().warning(f'rejected {reason}', throttle_duration_sec=1.0)

    def on_state(self, answered_stamp=None) -> None:
        """Run a control step on an instrument state (event-driven loop).

        ``answered_stamp``: the state's header stamp when it was accepted fresh (the command
        carries it), else None.
        """
        if not self._timer.is_canceled():  # cancelled: the loop is stopped
            self.steps['on_state'] += 1
            started = time.perf_counter()
            self._last_state_step = started
            self._step(started, answered_stamp)

    # ------------------------------------------------------------------ parameters
    def _on_params(self, params, changed) -> None:
        """Apply an accepted runtime change: retune bumplessly, keep the latest inputs."""
        self.controller.update_params(params)
        fresh = self.controller.new_inputs()
        for name in _INPUT_RANGES:
            setattr(self.inputs, name, getattr(fresh, name))
        self.io.update_params(params)
        if 'request_enable' in changed and params.request_enable and hasattr(self.io,
                                                                             'request_enable'):
            self.io.request_enable()
        self.get_logger().info(f'parameters changed: {sorted(changed)}')

    # ------------------------------------------------------------------ loop
    def _tick(self) -> None:
        """Run the ``control_rate`` timer: watchdog and fallback of the event-driven loop.

        Steps when no instrument state came for :data:`FALLBACK_AFTER_PERIODS` state
        periods (a lost state; when they stop, every half state period at most, so the
        watchdog acts on the stale inputs), never within :data:`MIN_STEP_SPACING_PERIODS`
        state periods of the previous step. A tick more than :data:`STALL_PERIODS` timer
        periods after the previous one (this process was not scheduled) does not step: the
        states that came in meanwhile run first, so a stall of this process is not taken for a
        lost input (the next tick steps if none came).
        """
        started = time.perf_counter()
        previous, self._last_timer = self._last_timer, started
        if previous != -math.inf and started - previous > STALL_PERIODS * self._timer_period:
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

    def _control(self, answered_stamp=None) -> None:
        stamp = self._now_ns()
        now = stamp.nanoseconds * 1e-9
        out = self.controller.step(now, self.inputs, self.io.interlock())
        self.last_output = out
        stamp_msg = stamp.to_msg()
        self.io.publish(out, stamp_msg, answered_stamp)

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
        values['steps_on_state'] = str(self.steps['on_state'])   # stepped on an instrument state
        values['steps_on_timer'] = str(self.steps['on_timer'])   # fallback: no fresh state
        values.update(self.io.status())
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
