"""Grip-force controller node (``controller``): a thin shell around ``GripController``.

Its topics depend on the ``interface`` parameter: ``crtk`` (this package's topics, the
current in A) or ``dvrk`` (a da Vinci Research Kit PSM's and MTM's topics, the jaw effort
in N*m, the arm's operating state); the wiring of each profile is
:mod:`grip_force_ros.nodes.controller_io`. In ``crtk``:

Subscribes (KEEP_LAST 1; only the newest sample matters):
    master/gripper/measured_js        gripper: position (rad)
    instrument/measured_js            wrist_pitch, jaw: position (rad), velocity (rad/s, optional);
                                      and jaw_drum (the sim's combined state, ``state_message``):
                                      position (rad), velocity (rad/s), effort = current (A)
    instrument/actuator/measured_js   jaw_drum, as above (an instrument with a split state)
    grip/measured_force               force.z = grip force (N), only when force_sensor_enabled
Publishes:
    instrument/actuator/servo_jf      jaw_drum: effort = current command (A), every control step
                                      (one per instrument state, ``expected_state_rate``)
    grip/estimated_force              force.z = grip force (N), force.x = needle pull-out force (N)
    grip/estimate_band                force.x, force.y = the estimate band's low and high edge (N),
                                      force.z = grip force (N): held in stick while x < z < y
    grip/target_force                 force.z = target grip force (N)
        all three at ``force_output_rate`` (100 Hz), right after the step's command;
and ``/diagnostics`` at 10 Hz and on a change of mode, limits or input faults. The 1 kHz
messages are read and written as serialized bytes (:mod:`grip_force_ros.nodes.wire`).

Loop timing, as hardware interfaces do it: the control step runs when a fresh
instrument state arrives (the combined state or the actuator state; dvrk: the jaw's
``measured_js``, in its subscription callback), so each command answers the newest state
without waiting for a free-running timer. The step integrates over the time measured since
the previous step (:class:`~grip_force_ros.control.GripController`), so the loop is the same
at any state rate from 100 to 1500 Hz (``expected_state_rate``; the dVRK publishes at 100
Hz). The ``control_rate`` timer (1 kHz) is the watchdog and fallback: it runs once no state
came for :data:`FALLBACK_AFTER_PERIODS` state periods (a watch timer looks every
:data:`WATCH_PERIOD`, so the first fallback step comes at most that much later) and then
steps every half state period at most (the safe state still comes within a timer period or
two of ``watchdog_timeout``), never within :data:`MIN_STEP_SPACING_PERIODS` of the previous
step; the next state puts it to sleep again. The loop runs while the node is active
(``_running``): activation sets it, the start of a deactivation clears it (no step on states
or on the timer then).

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

Lifecycle (``rclpy.lifecycle``; ``ros2 lifecycle get|set /controller``):

``unconfigured``
    Parameters declared and the parameter file validated (a bad file refuses the node at
    construction, exit 2, as a plain node). Nothing is published: the drive gets no
    command (the sim, like a drive with a command timeout, holds 0 A).
``configure`` -> ``inactive``
    The controller core built from the parameters, the profile's topics created (the
    conversions are :mod:`~grip_force_ros.nodes.controller_io`'s; subscriptions fill the
    inputs, so they are fresh at activation); no step runs, nothing is published (zero current). A
    failure (e.g. the dvrk profile without crtk_msgs) leaves the node unconfigured and logs
    why.
``activate`` -> ``active``
    A fresh controller state (0 A, as after a start): the loop closes, bumplessly from 0 A
    (the force target ramps up from the estimate, the current at most at the slew limit).
``deactivate`` -> ``inactive``
    The loop stops at once; inside the transition the current ramps to 0 A at
    ``max_current_slew`` (safe steps, one per state period), and the transition completes
    when the command is 0 A: so ``inactive`` always means 0 A, and no command follows the
    0 A one. The ramp takes at most ``max_current / max_current_slew`` (5 ms for the
    shipped instruments).
``cleanup`` -> ``unconfigured``: the topics are destroyed. ``shutdown`` from any state:
    the same ramp if active, then the release; the process then ends (exit 0).

``autostart`` (default true) configures and activates the node at start, so ``ros2 run``,
the launch files, the demo, the bench and the fault check run as a plain node did.

Services (:mod:`~grip_force_ros.nodes.controller_services`): ``~/set_object``, ``~/tare``,
``~/calibrate``. Actions (:mod:`~grip_force_ros.nodes.controller_actions`, with control_msgs):
``grip_command`` (GripperCommand) and ``parallel_grip_command`` (ParallelGripperCommand): a
goal takes the jaw over from the master, closes it and holds the goal's grip force.
"""
from __future__ import annotations

import functools
import math
import time
import traceback

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.task import Future
from rclpy.time import Time
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.control import SOURCES, ControlInputs, GripController, Mode
from grip_force_ros.nodes.common import DIAGNOSTICS_QOS, STATE_PUB_QOS, STATE_SUB_QOS
from grip_force_ros.nodes.controller_actions import ControllerActions
from grip_force_ros.nodes.controller_io import NO_STEP, controller_io
from grip_force_ros.nodes.controller_services import ControllerServices
from grip_force_ros.nodes.lifetime import run_node
from grip_force_ros.nodes.realtime import loop_log
from grip_force_ros.nodes.ros_params import declare_node_parameters

GROUPS = ('instrument', 'limits', 'controller', 'interface', 'realtime')
#: Periodic /diagnostics rate (Hz); changes are published sooner, at most this often:
DIAGNOSTICS_RATE = 10.0
DIAGNOSTICS_MIN_INTERVAL = 0.01  # s
#: The timer does not step sooner than this many state periods after the previous step:
MIN_STEP_SPACING_PERIODS = 0.5
#: The timer steps only when no instrument state came for this many state periods:
FALLBACK_AFTER_PERIODS = 1.5
#: Period of the loop's watch timer (s): while states come, the ``control_rate`` fallback
#: timer sleeps and this one looks whether they still come (a 1 kHz timer that fires for
#: nothing costs a 1 kHz node several % of a core: BENCHMARKS.md, "The nodes' own cost").
WATCH_PERIOD = 0.005
#: After ``shutdown`` the process ends this long later (s): the transition's reply goes out first.
EXIT_DELAY = 0.2
#: A timer tick this many timer periods after the previous one follows a stall of this process:
#: it does not step (once), so that the states that came in meanwhile are taken first.
STALL_PERIODS = 5.0

#: The plausibility ranges of ControlInputs (copied on a runtime parameter change).
_INPUT_RANGES = ('master_angle_min', 'master_angle_max', 'master_angle_tolerance',
                 'jaw_angle_min', 'jaw_angle_max', 'wrist_angle_limit', 'current_limit',
                 'force_limit', 'stamp_future_tolerance')

_SUCCESS = TransitionCallbackReturn.SUCCESS
_FAILURE = TransitionCallbackReturn.FAILURE


def _transition(method):
    """Log a transition callback's exception (rclpy turns it into ERROR without a word)."""
    @functools.wraps(method)
    def logged(self, state):
        try:
            return method(self, state)
        except Exception:
            self.get_logger().error(f'{method.__name__} failed:\n{traceback.format_exc()}')
            raise
    return logged


class _ZeroRamp:
    """The loop's step while the node leaves the active state: safe, with ``reason``."""

    drives_current = False
    finished = False
    name = 'ramp to 0 A'

    def __init__(self, node, reason: str):
        self.node = node
        self.reason = reason

    def step(self, now, inputs, interlock):
        return self.node.controller.step(now, inputs, self.reason)

    def status(self) -> str:
        return f'{self.reason}: ramping the current to 0 A'


class ControllerNode(LifecycleNode):
    """Runs :class:`GripController` once per actuator state, the timer as watchdog fallback.

    The loop is one read-compute-write update per instrument state: the state topic's
    subscription callback (:meth:`_on_state`) converts the message into the inputs (the
    profile's ``read_*``, :mod:`~grip_force_ros.nodes.controller_io`), and :meth:`_update`
    steps the controller, converts its output (the profile's ``command``) and publishes it.
    """

    def __init__(self, **kwargs):
        super().__init__('controller', **kwargs)
        self.finished = Future()
        self._now_ns = self.get_clock().now
        self._param = declare_node_parameters(self, GROUPS, on_update=self._on_params)
        self.user_services = ControllerServices(self)
        self.actions = ControllerActions(self)   # the grasp actions (control_msgs), in any state
        self.add_on_set_parameters_callback(self._refuse_unsafe_set)
        self.controller: GripController | None = None
        self.inputs: ControlInputs | None = None
        self.io = None                 # the profile's conversions (controller_io)
        self._loop_entities: list = []  # the loop's subscriptions and publishers (configure)
        self._force_sub = None         # the load cell's subscription, while listened to
        self._force_wanted = False     # a service needs the load cell (start_procedure)
        self._command_pub = self._estimate_pub = self._target_pub = self._band_pub = None
        self._next_forces_ns = 0       # controller clock (ns) at which the forces are due
        self._running = False          # the loop steps (active, not stopping)
        self.procedure = None          # a service's procedure or the deactivation ramp, or None
        self.last_output = None
        self._timer = None             # the watch timer: exists while configured, runs while active
        self._fallback = None          # the control_rate timer: runs while no state comes
        self._fallback_idle = True     # the fallback timer is cancelled (states come)
        self._diag_pub = None
        self._exit_timer = None
        self._configure_error = None
        self._quiet_failure = False    # autostart: the exception reports a failed configure
        self.steps = {'on_state': 0, 'on_timer': 0, 'deferred_after_stall': 0}   # by trigger
        if self._param.params.autostart:
            self._quiet_failure = True
            configured = self.trigger_configure() == _SUCCESS
            self._quiet_failure = False
            if not configured or self.trigger_activate() != _SUCCESS:
                why = self._configure_error or 'the autostart transitions failed (see the log)'
                self.destroy_node()        # refuse to start: leave nothing in the ROS graph
                raise ValueError(why)

    # ------------------------------------------------------------------ state
    @property
    def params(self):
        """The node's current :class:`~grip_force_ros.params.ParamSet`."""
        return self._param.params

    @property
    def lifecycle_state(self) -> str:
        """Return the label of the lifecycle state ('unconfigured', 'inactive', 'active', ...)."""
        return self._state_machine.current_state[1]

    @property
    def active(self) -> bool:
        """Whether the loop runs (the lifecycle state is active, the timer not cancelled)."""
        return self._running

    # ------------------------------------------------------------------ lifecycle
    @_transition
    def on_configure(self, state) -> TransitionCallbackReturn:
        """Build the controller core and the profile's topics; nothing steps or publishes yet."""
        params = self.params
        self._configure_error = None
        try:
            self.controller = GripController(params)
            self.inputs = self.controller.new_inputs()
            self._diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                   DIAGNOSTICS_QOS)
            self._timer = self.create_timer(WATCH_PERIOD, self._watch, autostart=False)
            self._fallback = self.create_timer(1.0 / params.control_rate, self._tick,
                                               autostart=False)
            self.io = controller_io(params)     # the profile's conversions (dvrk: crtk_msgs)
            self._create_loop_entities()
        except ValueError as exc:
            self._release()
            self._configure_error = str(exc)
            if not self._quiet_failure:
                self.get_logger().error(f'configure failed: {exc}')
            return _FAILURE
        self._reset_loop_state()
        where = (f'arm {params.arm}, master {params.master}' if params.interface == 'dvrk'
                 else 'crtk topics')
        self.get_logger().info(
            f'{params.instrument_name}: {params.interface} interface ({where}), stepping on '
            f'instrument states (expected {params.expected_state_rate:g} Hz), watchdog timer '
            f'{params.control_rate:.0f} Hz, feedback '
            f"{'force sensor' if params.force_sensor_enabled else 'model estimate'}, "
            f'object {params.object_kind}')
        self.get_logger().info(self.controller.gains.describe())   # the schedule at this rate
        return _SUCCESS

    @_transition
    def on_activate(self, state) -> TransitionCallbackReturn:
        """Close the loop from a fresh controller state (0 A, as after a start)."""
        if self.controller.steps:
            self.controller = GripController(self.params)
        self._reset_loop_state()
        self._timer.reset()
        self._running = True
        self.get_logger().info('active: closing the loop')
        return _SUCCESS

    @_transition
    def on_deactivate(self, state) -> TransitionCallbackReturn:
        """Stop the loop; ramp the current to 0 A at the slew limit before completing."""
        self._stop_loop('deactivated')
        self.get_logger().info('inactive: current 0 A, loop stopped')
        return _SUCCESS

    @_transition
    def on_cleanup(self, state) -> TransitionCallbackReturn:
        """Destroy the profile's topics and the controller core."""
        self._release()
        return _SUCCESS

    @_transition
    def on_shutdown(self, state) -> TransitionCallbackReturn:
        """From any state: ramp to 0 A if active, release, then end the process."""
        self._stop_loop('shutting down')
        self._release()
        self._exit_timer = self.create_timer(EXIT_DELAY, self._exit)
        self.get_logger().info('finalized: the process ends')
        return _SUCCESS

    @_transition
    def on_error(self, state) -> TransitionCallbackReturn:
        """Make safe after a transition raised (ramp to 0 A, release); back to unconfigured."""
        self._stop_loop('error in a transition')
        self._release()
        return _SUCCESS

    def _exit(self) -> None:
        self._exit_timer.cancel()
        if not self.finished.done():
            self.finished.set_result(True)

    def destroy_node(self) -> None:
        """Destroy the node and, with it, its lifecycle state machine.

        rclpy's ``LifecycleNode.destroy_node`` (Jazzy) leaves the state machine to the garbage
        collector, and the state machine holds the node, so the node's DDS participant lives
        on (its threads still taking discovery traffic) until a collection, in whichever
        thread it runs: a collection in a test's spinning thread, under the GIL, while that
        leaked participant was caught in a Fast DDS
        deadlock (eProsima/Fast-DDS#6502: ``unregister_timer`` against
        ``check_remote_participant_liveliness``): the whole test process hung.
        """
        actions = getattr(self, 'actions', None)   # None: construction failed before them
        if actions is not None:
            actions.destroy()
        super().destroy_node()
        self._state_machine.destroy_when_not_in_use()

    def _reset_loop_state(self) -> None:
        """Forget the previous activation's timing and /diagnostics (not the inputs)."""
        params = self.params
        self.last_output = None
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

    def _stop_loop(self, reason: str) -> None:
        """Stop the loop (if it runs): a running procedure is stopped, the current ramps to 0 A.

        The ramp is a safe step of the controller every state period, paced here (the
        executor is held: the inputs age, which is safe), until the command is 0 A; then the
        forces and /diagnostics ('inactive') go out and nothing more.
        """
        if not self.active:
            return
        self.user_services.stop(f'the controller is {reason}')
        self.actions.stop(f'the controller is {reason}')
        self._running = False
        self._timer.cancel()
        self._fallback.cancel()
        self._fallback_idle = True
        self.procedure = _ZeroRamp(self, reason)
        longest = 2.0 * self.controller.current_limit / self.params.max_current_slew + 1.0  # s
        give_up = time.monotonic() + longest
        while True:
            self._update(self._now_ns().nanoseconds, None, None)
            if self.last_output.current_command == 0.0 or time.monotonic() > give_up:
                break
            time.sleep(self._period)
        self.procedure = None
        stamp = self._now_ns()
        now_ns = stamp.nanoseconds
        self._next_forces_ns = now_ns + self.io.forces_period_ns
        self.io.fill_forces(self.last_output, now_ns)    # the last ramp step's
        self._estimate_pub.publish(self.io.estimate_msg)
        self._band_pub.publish(self.io.band_msg)
        self._target_pub.publish(self.io.target_msg)
        self._publish_diagnostics(stamp.to_msg(), self.last_output)

    def _create_loop_entities(self) -> None:
        """Create the profile's loop topics: the callbacks are this node's, the conversions the IO's."""
        io, names, raw = self.io, self.io.names, self.io.raw_states
        subscribe, entities = self.create_subscription, self._loop_entities
        on_state = self._on_state
        entities.append(subscribe(JointState, names.master_js,
                                  functools.partial(on_state, io.read_master), STATE_SUB_QOS,
                                  raw=True))
        entities.append(subscribe(JointState, names.instrument_js,
                                  functools.partial(on_state, io.read_instrument), STATE_SUB_QOS,
                                  raw=raw))
        entities.append(subscribe(JointState, names.actuator_js,
                                  functools.partial(on_state, io.read_actuator), STATE_SUB_QOS,
                                  raw=raw))
        self._command_pub = self.create_publisher(JointState, io.command_topic, STATE_PUB_QOS)
        self._estimate_pub = self.create_publisher(WrenchStamped, names.estimated_force,
                                                   STATE_PUB_QOS)
        self._band_pub = self.create_publisher(WrenchStamped, names.estimate_band, STATE_PUB_QOS)
        self._target_pub = self.create_publisher(WrenchStamped, names.target_force, STATE_PUB_QOS)
        entities += (self._command_pub, self._estimate_pub, self._band_pub, self._target_pub)
        self._next_forces_ns = 0
        self._follow_force()
        io.attach(self)

    def _follow_force(self) -> None:
        """Subscribe to the load cell while force_sensor_enabled or a service needs it."""
        listen = self.params.force_sensor_enabled or self._force_wanted
        if listen and self._force_sub is None:
            self._force_sub = self.create_subscription(
                WrenchStamped, self.io.names.measured_force,
                functools.partial(self._on_state, self.io.read_force), STATE_SUB_QOS, raw=True)
        elif not listen and self._force_sub is not None:
            self.destroy_subscription(self._force_sub)
            self._force_sub = None

    def load_cell_publishers(self) -> int:
        """Return how many publishers the load-cell topic has (0: no load cell)."""
        return self.count_publishers(self.resolve_topic_name(self.io.names.measured_force))

    def _release(self) -> None:
        """Destroy what configure created (safe on a half-made configuration)."""
        io, self.io = self.io, None    # first: a callback queued before this drops its event
        self._running = False
        if io is not None:
            io.detach(self)
        if self._force_sub is not None:
            self.destroy_subscription(self._force_sub)
            self._force_sub = None
        for entity in reversed(self._loop_entities):
            if type(entity).__name__ == 'Subscription':
                self.destroy_subscription(entity)
            else:
                self.destroy_publisher(entity)
        self._loop_entities = []
        self._command_pub = self._estimate_pub = self._target_pub = self._band_pub = None
        for timer in (self._timer, self._fallback):
            if timer is not None:
                self.destroy_timer(timer)
        self._timer = self._fallback = None
        if self._diag_pub is not None:
            self.destroy_publisher(self._diag_pub)
            self._diag_pub = None
        self.controller = None
        self.inputs = None
        self.last_output = None

    # ------------------------------------------------------------------ procedures (services)
    def start_procedure(self, procedure, needs_load_cell: bool) -> None:
        """Let ``procedure`` step instead of the controller (and listen to the load cell)."""
        self.procedure = procedure
        if needs_load_cell:
            self._force_wanted = True
            self._follow_force()

    def end_procedure(self, procedure) -> None:
        """Hand the loop back to the controller, which continues from the current last sent."""
        if self.procedure is not procedure:
            return
        self.procedure = None
        if procedure.drives_current:     # stopped mid-staircase: the ramp continues from there
            self.controller.command = procedure.command
        self._force_wanted = False
        self._follow_force()

    # ------------------------------------------------------------------ time
    def now(self) -> float:
        """Return the controller clock (s), the clock of receive times and of the watchdog."""
        return self._now_ns().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs
    def _on_state(self, read, data) -> None:
        """Take one message of a loop topic; on an instrument state, run the control step.

        The subscription callback of every loop topic (bound to the profile's converter
        ``read`` with :func:`functools.partial`): one clock read gives the receive time and
        the step's time; ``read`` fills the inputs and returns :data:`NO_STEP`, or the
        state's stamp that the command answers (int ns, or None: the controller's clock).
        """
        io = self.io
        if io is None:                     # released: an event queued before is dropped
            return
        now_ns = self._now_ns().nanoseconds
        answered = read(data, now_ns * 1e-9, self.inputs)
        if io.rejections:
            self._take_rejections(io.rejections)
        if answered is NO_STEP or not self._running:   # not running: inactive or stopping
            return
        self.steps['on_state'] += 1
        started = time.perf_counter()
        self._last_state_step = started
        self._update(now_ns, answered, started)
        if not self._fallback_idle:        # the states came back: the fallback sleeps
            self._fallback.cancel()
            self._fallback_idle = True

    def _take_rejections(self, rejections: list) -> None:
        """Keep the rejection reasons ``rejections`` for /diagnostics, warn, and empty the list."""
        for reason in rejections:
            self._note_rejection(reason)
            loop_log(self).put('warning', f'rejected {reason}', throttle=1.0)
        rejections.clear()

    def _note_rejection(self, reason: str) -> None:
        """Keep a rejection for the next /diagnostics, even if it is over by then."""
        if reason not in self._new_rejections and len(self._new_rejections) < 5:
            self._new_rejections.append(reason)

    # ------------------------------------------------------------------ parameters
    def _refuse_unsafe_set(self, parameters) -> SetParametersResult:
        """on-set callback: refuse what the schema allows but the moment does not."""
        why = self.user_services.object_change_refusal(parameters)
        return SetParametersResult(successful=why is None, reason=why or '')

    def _on_params(self, params, changed) -> None:
        """Apply an accepted runtime change: retune bumplessly, keep the latest inputs."""
        self.get_logger().info(f'parameters changed: {sorted(changed)}')
        if self.controller is None:        # unconfigured: configure reads them
            return
        self.controller.update_params(params)
        fresh = self.controller.new_inputs()
        for name in _INPUT_RANGES:
            setattr(self.inputs, name, getattr(fresh, name))
        self.io.update_params(params)
        self._follow_force()
        if 'request_enable' in changed and params.request_enable and hasattr(self.io,
                                                                             'request_enable'):
            self.io.request_enable()

    # ------------------------------------------------------------------ loop
    def _watch(self) -> None:
        """Run the watch timer: wake the fallback timer when no state came for a while.

        Every :data:`WATCH_PERIOD` while the loop runs; once no instrument state came for
        :data:`FALLBACK_AFTER_PERIODS` state periods, the ``control_rate`` timer starts
        (:meth:`_tick`), until the next state.
        """
        if (self._fallback_idle
                and time.perf_counter() - self._last_state_step >= self._fallback_after):
            self._fallback_idle = False
            self._last_timer = -math.inf   # its first tick is no stall
            self._fallback.reset()

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
        if not self._running:              # a queued event after a stop
            return
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
            self._update(self._now_ns().nanoseconds, None, started)

    def _update(self, now_ns: int, answered_ns, started) -> None:
        """One read-compute-write step: step the controller, convert its output, publish.

        Parameters
        ----------
        now_ns : int
            The controller's clock at the step (ns): the receive time of the state it answers.
        answered_ns : int or None
            Header stamp (ns) of the fresh instrument state the step answers (the current
            command carries it), or None (the command carries ``now_ns``).
        started : float or None
            perf_counter (s) at the step's start, for the loop timing; None: not timed (the
            ramp to 0 A of a deactivation).
        """
        if started is not None:
            self._last_step = started
        now = now_ns * 1e-9
        io, inputs, procedure = self.io, self.inputs, self.procedure
        if procedure is None:
            out = self.controller.step(now, inputs, io.interlock())
        else:                               # a service's procedure, or the ramp to 0 A
            out = procedure.step(now, inputs, io.interlock())
        self.last_output = out
        command = io.command(out, now_ns if answered_ns is None else answered_ns)
        if command is not None:
            self._command_pub.publish(command)
        if now_ns >= self._next_forces_ns:
            self._next_forces_ns = now_ns + io.forces_period_ns
            io.fill_forces(out, now_ns)
            self._estimate_pub.publish(io.estimate_msg)
            self._band_pub.publish(io.band_msg)
            self._target_pub.publish(io.target_msg)
        actions = self.actions
        if actions.current is not None and now_ns >= actions.due_ns:   # a goal runs
            actions.tick(out, now_ns)

        if out.limits_hit:
            self._limits_seen.update(out.limits_hit)
        key = (out.mode, out.limits_hit, out.reasons, len(inputs.rejected))
        since = now - self._diag_time
        if since >= 1.0 / DIAGNOSTICS_RATE or ((key != self._diag_key or self._new_rejections)
                                               and since >= DIAGNOSTICS_MIN_INTERVAL):
            self._publish_diagnostics(Time(nanoseconds=now_ns).to_msg(), out)
            self._diag_key, self._diag_time = key, now
        if started is None:
            return
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

    def diagnostic_status(self, out) -> DiagnosticStatus:
        """Build the controller's DiagnosticStatus for the last output ``out``."""
        params = self._param.params
        late = sum(self.controller.late_counts.values())
        procedure = self.procedure
        if not self.active and procedure is None:   # deactivated: the ramp is over
            level, mode, reasons = DiagnosticStatus.OK, 'inactive', 'current 0 A, loop stopped'
        elif procedure is not None and procedure.drives_current:
            level, mode, reasons = DiagnosticStatus.WARN, 'calibrating', procedure.status()
        else:
            if out is None or out.mode is Mode.SAFE:
                level = DiagnosticStatus.ERROR
            elif out.limits_hit or out.reasons or self._limits_seen or late > self._late_reported:
                level = DiagnosticStatus.WARN   # late inputs since the last report: a warning
            else:
                level = DiagnosticStatus.OK
            mode = out.mode if out is not None else 'starting'
            reasons = '; '.join(out.reasons) if out is not None and out.reasons else 'ok'
        values = dict(self.controller.status(self.inputs))
        values['mode'] = str(mode)
        values['lifecycle_state'] = self.lifecycle_state
        values['procedure'] = procedure.status() if procedure is not None else 'none'
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
        values.update(self.actions.status())
        values['steps_deferred_after_stall'] = str(self.steps['deferred_after_stall'])
        if out is not None:
            values['target_force_N'] = f'{out.target_force:.3f}'
            values['pull_out_force_N'] = f'{out.pull_out_force:.3f}'
        return DiagnosticStatus(
            level=level, name=topics.diagnostic_name(self.get_namespace(), 'controller'),
            message=f'{mode}: {reasons}',
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
