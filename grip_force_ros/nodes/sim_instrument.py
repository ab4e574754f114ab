"""Simulated instrument node (``sim_instrument``): a thin shell around ``InstrumentSim``.

Its topics depend on the ``interface`` parameter: ``crtk`` (this package's topics, the
current in A) or ``dvrk`` (the sim plays a dVRK PSM named ``arm``: its jaw and arm joint
states, the jaw effort in N*m on ``<arm>/jaw/servo_jf``, the operating state machine
DISABLED -> ENABLED -> homed, 100 Hz by default); the wiring of each profile is
:mod:`grip_force_ros.nodes.sim_io`. In ``crtk``:

Subscribes (KEEP_LAST 1):
    instrument/actuator/servo_jf      jaw_drum: effort = motor current command (A)
Steps the plant in real time: a timer at ``publish_rate`` (1 kHz; dvrk 100 Hz) advances the
simulation by the time actually elapsed since the last step (capped at
:data:`MAX_STEP` or 2.5 periods, so a stalled process slows the simulation instead of
integrating one huge step), with the last accepted current command held.
Publishes each step's measurements, all with the same stamp (the time of the
measurement), at once, in this order (``state_message: combined``, the default):
    grip/measured_force               force.z = load-cell grip force (N)
    instrument/measured_js            wrist_pitch, jaw, jaw_drum: position (rad), velocity
                                      (rad/s); effort of jaw_drum = measured current (A),
                                      of the joints NaN (not measured)
        last: the controller steps on it, so the step finds the load cell of the same
        sample. ``state_message: split`` sends the joints (wrist_pitch, jaw) on
        instrument/measured_js, the load cell, then the drum on
        instrument/actuator/measured_js, on which the controller steps.
and its status on ``/diagnostics`` at 1 Hz, with the loop's round trip over the
last second: a command that carries the stamp of a state it answers
(the controller's convention) took arrival minus stamp, both on this node's clock
(:class:`~grip_force_ros.sim.loop_latency.LoopLatency`).

The drive side, in both profiles: with no accepted command for ``command_timeout``
(30 ms, the dVRK's) the current command becomes 0 A, as a real drive cuts its power
when its master stops talking (a controller killed mid-grasp); reported in the log and on
/diagnostics (``drive_timeouts``), re-armed by the next command
(:class:`~grip_force_ros.sim.drive.CommandTimeout`).

The plant's parameters are the 'instrument', 'sim' and 'effects' groups of the
schema (``friction_scale`` and ``stiffness_scale`` make the plant differ from
the instrument file; the controller is not told). A malformed command
(unknown joint, wrong length, NaN) is rejected and the last good one is held.
"""
from __future__ import annotations

import functools
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.task import Future

from grip_force_ros import topics
from grip_force_ros.nodes.common import DIAGNOSTICS_QOS, STATE_SUB_QOS
from grip_force_ros.nodes.lifetime import run_node
from grip_force_ros.nodes.realtime import loop_log
from grip_force_ros.nodes.ros_params import declare_node_parameters
from grip_force_ros.nodes.sim_io import CommandRefused, sim_io
from grip_force_ros.sim import InstrumentSim
from grip_force_ros.sim.drive import CommandTimeout
from grip_force_ros.sim.loop_latency import LoopLatency

GROUPS = ('instrument', 'limits', 'sim', 'effects', 'interface', 'realtime')
#: Largest simulated step per timer period (s), at least :data:`MAX_STEP_PERIODS` publish
#: periods; longer stalls slow the simulation down.
MAX_STEP = 0.01
MAX_STEP_PERIODS = 2.5
#: Period of the drive's own command-timeout check (s), as a drive's watchdog runs beside its
#: current loop: independent of the rate the sensors are published at (dvrk: 100 Hz).
DRIVE_CHECK_PERIOD = 1e-3
#: A check this much later than the previous one means this process was starved: commands
#: may be queued unprocessed, so the timeout is judged at the next check, not now (a real
#: drive's watchdog is hardware and never starved; the sim's is a Python callback).
DRIVE_CHECK_LATE = 5e-3
DIAGNOSTICS_PERIOD = 1.0  # s


class SimInstrumentNode(Node):
    """Integrates :class:`InstrumentSim` in real time and publishes its sensors."""

    def __init__(self, **kwargs):
        super().__init__('sim_instrument', **kwargs)
        self.finished = Future()
        self._param = declare_node_parameters(self, GROUPS, on_update=self._on_params)
        params = self._param.params
        self.sim = InstrumentSim(params, obj=None, seed=params.sim_seed)
        self.current_command = 0.0       # A, last accepted command
        self.rejected = 0                # refused commands (malformed; dvrk: not ready, too large)
        self.last_rejection = ''
        self.commands = 0                # accepted commands
        self.capped_steps = 0            # periods whose elapsed time exceeded MAX_STEP
        self.live_cuts = 0               # drive timeouts that cut a non-zero current
        self.drive = CommandTimeout(params.command_timeout)
        self._last_drive_check = time.monotonic()
        self._starved: tuple[float, float] | None = None   # (when, for how long) s, monotonic
        self.loop = LoopLatency(capacity=int(2 * params.publish_rate * DIAGNOSTICS_PERIOD) + 16)
        self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                               DIAGNOSTICS_QOS)
        try:                               # the profile's conversions (dvrk: needs crtk_msgs)
            self.io = sim_io(params)
        except ValueError:
            self.destroy_node()            # refuse to start: leave nothing in the ROS graph
            raise
        for msg_type, topic, raw, read in self.io.command_readers():
            self.create_subscription(msg_type, topic, functools.partial(self._on_command, read),
                                     STATE_SUB_QOS, raw=raw)
        self.io.attach(self)               # the sensor publishers (dvrk: the arm's channel)
        self._last = time.monotonic()
        self._started = self._last
        self._max_step = max(MAX_STEP, MAX_STEP_PERIODS / params.publish_rate)
        self._timer = self.create_timer(1.0 / params.publish_rate, self._tick)
        # at 1 kHz and above the step checks the drive; slower, its own timer does
        self._drive_timer = (self.create_timer(DRIVE_CHECK_PERIOD, self._check_drive)
                             if params.publish_rate * DRIVE_CHECK_PERIOD < 1.0 else None)
        self._diag_timer = self.create_timer(DIAGNOSTICS_PERIOD, self._publish_diagnostics)
        where = f' as arm {params.arm}' if params.interface == 'dvrk' else ''
        self.get_logger().info(
            f'{params.instrument_name}: {params.interface} interface{where}, object {self.sim.obj}, '
            f'friction x{params.friction_scale:g}, '
            f'stiffness x{params.stiffness_scale:g}, stepping at {params.publish_rate:.0f} Hz, '
            f'drive command timeout {params.command_timeout * 1e3:g} ms')

    def now(self) -> float:
        """Return the node's monotonic clock (s), the clock of the drive and the arm."""
        return time.monotonic()

    # ------------------------------------------------------------------ input
    def _on_command(self, read, data) -> None:
        """Take a command message (the profile's ``read`` converts it): hold its current, or refuse it."""
        try:
            current, stamp_ns = read(data)
        except CommandRefused as exc:
            self.refuse(str(exc), exc.stamp_ns)
            return
        self.accept(current, stamp_ns)

    def accept(self, current: float, stamp_ns: int) -> None:
        """Hold ``current`` (A), a command accepted by the profile; re-arm the drive timeout."""
        self.loop.command_received(stamp_ns, self.get_clock().now().nanoseconds)
        self.current_command = current
        self.commands += 1
        self.drive.command(self.now())

    def refuse(self, reason: str, stamp_ns: int) -> None:
        """Count a refused command (the last good one stays held), with a warning."""
        self.loop.command_received(stamp_ns, self.get_clock().now().nanoseconds)
        self.rejected += 1
        self.last_rejection = reason
        loop_log(self).put('warning', reason, throttle=1.0)

    # ------------------------------------------------------------------ parameters
    def _on_params(self, params, changed) -> None:
        self.sim.set_params(params)
        if 'sim_object' in changed:
            self.sim.set_object(params.sim_object)
        if 'publish_rate' in changed:
            self.destroy_timer(self._timer)
            self._max_step = max(MAX_STEP, MAX_STEP_PERIODS / params.publish_rate)
            self._timer = self.create_timer(1.0 / params.publish_rate, self._tick)
        if 'publish_rate' in changed and self._drive_timer is None \
                and params.publish_rate * DRIVE_CHECK_PERIOD < 1.0:
            self._drive_timer = self.create_timer(DRIVE_CHECK_PERIOD, self._check_drive)
        if 'command_timeout' in changed:
            self.drive.timeout = params.command_timeout
        self.get_logger().info(f'parameters changed: {sorted(changed)}')

    # ------------------------------------------------------------------ loop
    def _tick(self) -> None:
        now = time.monotonic()
        dt = now - self._last
        self._last = now
        if dt <= 0.0:
            return
        if dt > self._max_step:
            dt = self._max_step
            self.capped_steps += 1
        if self._drive_expired(now):
            self._cut()
        self.io.update(now)
        if not self.io.powered():        # dvrk: a disabled arm's drives carry no current
            self.current_command = 0.0
        self.io.step(self.sim, self.current_command, dt)
        stamp = self.get_clock().now()
        self.io.publish_state(self.sim.measure(), stamp.nanoseconds)
        self.loop.state_published(stamp.nanoseconds)

    def _check_drive(self) -> None:
        """Check the drive's command timeout between sensor steps (publish rate < 1 kHz).

        On a cut the plant is first advanced to now with the held command, so the current
        falls from the moment of the cut, not from the next sensor step.
        """
        now = time.monotonic()
        if not self._drive_expired(now):
            return
        dt = min(now - self._last, self._max_step)
        if dt > 0.0:
            self.io.step(self.sim, self.current_command, dt)
            self._last = now
        self._cut()

    def _drive_expired(self, now: float) -> bool:
        """Tell whether the command timeout expired, unless this process was just starved."""
        gap = now - self._last_drive_check
        late = gap > DRIVE_CHECK_LATE
        self._last_drive_check = now
        if late:
            self._starved = (now, gap)
        return not late and self.drive.expired(now)

    def _cut(self) -> None:
        """Cut the drive current (the command timeout expired) and say so."""
        # a check that came late because this process was not scheduled says so: on a real
        # drive the watchdog is hardware; here a stalled machine delays the Python check
        starved = ''
        if self._starved and time.monotonic() - self._starved[0] <= self.drive.last_silence:
            starved = (f'; this process was not scheduled for {self._starved[1] * 1e3:.1f} ms '
                       'before the check')
        held = self.io.drive_current(self.current_command)
        live = held != 0.0
        self.current_command = 0.0       # the cut first, then the words
        self.io.cut()                    # dvrk: the jaw's position loop stops too
        if live:
            self.live_cuts += 1
        loop_log(self).put(
            'warning', f'no command for {self.drive.last_silence * 1e3:.1f} ms (command timeout '
            f'{self.drive.timeout * 1e3:g} ms): drive current cut from {held:.4f} A '
            f'to 0 A{starved}')
        if live:
            self._publish_diagnostics()  # at once: a run with such a cut can be told apart

    def _publish_diagnostics(self) -> None:
        params = self._param.params
        wall = time.monotonic() - self._started
        warn = self.rejected or self.capped_steps or self.drive.expiries
        loop = self.loop.summary()
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if warn else DiagnosticStatus.OK,
            name=topics.diagnostic_name(self.get_namespace(), 'sim_instrument'),
            message=f'simulating {self.sim.obj}' + (f'; rejected {self.rejected} commands'
                                                    if self.rejected else ''),
            hardware_id=params.instrument_name,
            values=[KeyValue(key=k, value=v) for k, v in {
                'object': self.sim.obj,
                'sim_time_s': f'{self.sim.t:.3f}',
                'real_time_factor': f'{self.sim.t / wall:.3f}' if wall > 0 else 'n/a',
                'current_command_A': f'{self.io.drive_current(self.current_command):.4f}',
                'commands_accepted': str(self.commands),
                'commands_rejected': str(self.rejected),
                'last_rejection': self.last_rejection or 'none',
                'drive_timeouts': str(self.drive.expiries),   # current cut: no command in time
                'drive_cuts_under_current': str(self.live_cuts),  # of them, a non-zero current
                'drive': 'holding command' if self.drive.armed else 'no command (0 A)',
                'capped_steps': str(self.capped_steps),
                # the last second: actuator state -> command answering it, this node's clock
                'loop_round_trip_p50_ms': f"{loop['p50_ms']:.3f}",
                'loop_round_trip_p99_ms': f"{loop['p99_ms']:.3f}",
                'loop_round_trip_max_ms': f"{loop['max_ms']:.3f}",
                'loop_states_unanswered': str(loop['unanswered']),
                'friction_scale': f'{params.friction_scale:g}',
                'stiffness_scale': f'{params.stiffness_scale:g}',
                **self.io.status(),
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
