"""The controller's conversions of one interface profile: messages <-> values, units.

:class:`ControllerNode` (nodes/controller.py) owns the loop's subscriptions and publishers,
the loop, the timing and /diagnostics; the profile object made by :func:`controller_io`
says which topics and converts: a ``read_*`` method turns one message into the controller's
:class:`~grip_force_ros.control.ControlInputs` (given as an argument) and tells whether the
node steps on it; :meth:`ControllerIO.command` turns a step's output into the command
message; :meth:`ControllerIO.fill_forces` fills the force messages (the estimate's band
among them). The profile objects
never call the node. Topics:

``crtk`` (:class:`CrtkControllerIO`; topics.py, docs/ros_interface.md)
    ``master/gripper/measured_js``, ``instrument/measured_js`` (wrist_pitch, jaw; combined:
    and jaw_drum, the step runs on it), ``instrument/actuator/measured_js`` (jaw_drum,
    effort = current, A): the step runs on it; command ``instrument/actuator/servo_jf``
    (jaw_drum, effort = current, A).
``dvrk`` (:class:`DvrkControllerIO`; docs/dvrk.md)
    ``<master>/gripper/measured_js`` (gripper), ``<arm>/measured_js`` (the wrist picked by
    name among the arm's joints), ``<arm>/jaw/measured_js`` (jaw: position, velocity, effort
    in N*m, turned into the motor current with the dVRK's own conversion,
    :mod:`grip_force_ros.model.dvrk_jaw`): the step runs on it; command, by ``dvrk_command``,
    ``<arm>/jaw/servo_jp`` (``position``, the default: the jaw setpoint, rad, whose PID
    effort at the measured jaw angle is the step's current,
    :class:`~grip_force_ros.model.dvrk_jaw.JawPositionLoop`; the arm stays in position mode)
    or ``<arm>/jaw/servo_jf`` (``effort``: jaw effort, N*m; the whole arm goes to effort
    mode, said once at start), sent only while ``<arm>/operating_state`` is ENABLED and homed
    (the step is safe otherwise, with the reason); ``<arm>/state_command`` when asked to enable
    and home (``request_enable``); the grip force topics under ``<arm>/grip/``. The arm's
    operating-state channel (that subscription, its service client, a poll timer and the
    state_command publisher) is the profile's own: :meth:`DvrkControllerIO.attach` creates it
    on the node, its callbacks change only the profile's arm state.

Both profiles subtract the tare's offsets (``current_sensor_offset``, ``load_cell_offset``)
from the measured current and the load cell before the controller sees them.
"""
from __future__ import annotations

import math
import time

from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.model.dvrk_jaw import JawEffortConversion, JawPositionLoop, SetpointOrigin
from grip_force_ros.nodes.common import STATE_PUB_QOS, InputRejected, read_joints, stamp_seconds
from grip_force_ros.nodes.dvrk_msgs import arm_interlock, crtk_msgs
from grip_force_ros.nodes.wire import JointStateData, JointStateWriter, read_wrench

_MASTER_JOINTS = (topics.MASTER_JOINT,)
_INSTRUMENT_JOINTS = (topics.WRIST_JOINT, topics.JAW_JOINT)
_ACTUATOR_JOINTS = (topics.DRUM_JOINT,)
_JAW_JOINTS = (topics.JAW_JOINT,)
_DRUM_FIELDS = ('effort', 'position', 'velocity')
#: The joints of a combined crtk state (instrument/measured_js): wrist, jaw and the drum.
_STATE_JOINTS = (topics.WRIST_JOINT, topics.JAW_JOINT, topics.DRUM_JOINT)
#: How often the dvrk profile asks the arm's operating_state service while it knows no state,
#: and resends a pending enable/home request (s).
ARM_POLL_PERIOD = 0.5
#: Longest wait for the answer of the operating_state service before it is asked again (s).
#: A service answer can be lost (Fast DDS drops a reply whose client reader the server has
#: not discovered 100 ms after the request; ros2/rmw_fastrtps#890); without a
#: new request the profile would wait for a state change of the arm that may never come.
STATE_REPLY_WAIT = 2.0


class _NoStep:
    """The type of :data:`NO_STEP`."""

    __slots__ = ()

    def __repr__(self) -> str:
        return 'NO_STEP'


#: What a ``read_*`` returns for a message the node does not step on (a master sample, the
#: load cell, the joints of a split state). Otherwise it returns the header stamp (int ns) of
#: a fresh, stamped instrument state, which the command answering it carries, or None (a
#: state the node steps on with the controller's clock: rejected, duplicated or unstamped).
NO_STEP = _NoStep()


class ControllerIO:
    """What both profiles share: the master, the load cell, the force outputs.

    Parameters
    ----------
    params : ParamSet
        The node's parameters.
    names : TopicSet
        The profile's topics (:func:`grip_force_ros.topics.topic_set`).

    Attributes
    ----------
    names : TopicSet
        The profile's topics.
    raw_states : bool
        The instrument's state topics are taken as serialized bytes
        (:mod:`~grip_force_ros.nodes.wire`; the master and the load cell always are).
    rejections : list of str
        Why the samples read since the node last emptied it were rejected (the node reports
        and clears them).
    forces_period_ns : int
        Least time between two publications of the force outputs (ns).
    estimate_msg, band_msg, target_msg : WrenchStamped
        The force outputs, filled by :meth:`fill_forces` (reused every time): the estimated
        force, the estimate's band (``grip/estimate_band``: force.x and force.y the band's
        low and high edge, force.z the estimated force, N) and the target force.
    """

    interface = ''
    raw_states = True

    def __init__(self, params, names: topics.TopicSet):
        self.names = names
        self.command_topic = names.command   # where the node publishes :meth:`command`'s message
        self.rejections: list[str] = []
        self.update_params(params)
        # Messages reused every step: fill, do not rebuild.
        self.estimate_msg = WrenchStamped()
        self.estimate_msg.header.frame_id = topics.JAW_FRAME
        self.band_msg = WrenchStamped()
        self.band_msg.header.frame_id = topics.JAW_FRAME
        self.target_msg = WrenchStamped()
        self.target_msg.header.frame_id = topics.JAW_FRAME

    def update_params(self, params) -> None:
        """Apply accepted parameters (offsets, the wrist's freshness bound, the force rate)."""
        self.force_offset = params.load_cell_offset          # N
        self.current_offset = params.current_sensor_offset   # A
        self.wrist_timeout = params.watchdog_timeout         # s, the controller's watchdog
        # due again one output period after, less half a state period (so that at equal
        # rates the forces go out every step, whatever the states' jitter)
        self.forces_period_ns = max(0, int(1e9 / params.force_output_rate
                                           - 0.5e9 / params.expected_state_rate))

    # ------------------------------------------------------------------ inputs
    def _reject(self, inputs, source: str, now: float, exc: InputRejected) -> None:
        """Record a malformed message of ``source`` received at ``now`` (s)."""
        self.rejections.append(inputs.reject(source, now, f'malformed message: {exc}'))

    def read_master(self, data: bytes, now: float, inputs):
        """Store a master gripper state received at ``now`` (s); returns :data:`NO_STEP`."""
        try:
            msg = JointStateData(data)
            (angle,), = read_joints(msg, _MASTER_JOINTS, ('position',)).values()
        except InputRejected as exc:
            self._reject(inputs, 'master', now, exc)
            return NO_STEP
        why = inputs.set_master(now, angle, msg.stamp)[1]
        if why is not None:
            self.rejections.append(why)
        return NO_STEP

    def read_force(self, data: bytes, now: float, inputs):
        """Store a load-cell sample (N, less the tare) received at ``now`` (s); :data:`NO_STEP`."""
        try:
            stamp, _, _, force = read_wrench(data)
        except InputRejected as exc:
            self._reject(inputs, 'force', now, exc)
            return NO_STEP
        why = inputs.set_force(now, force - self.force_offset, stamp)[1]
        if why is not None:
            self.rejections.append(why)
        return NO_STEP

    # ------------------------------------------------------------------ outputs
    def fill_forces(self, out, now_ns: int) -> None:
        """Fill the three force messages with ``out``, stamped ``now_ns`` (ns).

        The band: force.x = ``out.band_low``, force.y = ``out.band_high``, force.z =
        ``out.estimated_force`` (N): the estimate is held in stick while x < z < y; the
        width is y - x (0: no band, with the load cell or without jaw friction terms).
        """
        sec, nanosec = divmod(now_ns, 1_000_000_000)
        est = self.estimate_msg
        est.header.stamp.sec, est.header.stamp.nanosec = sec, nanosec
        est.wrench.force.z = out.estimated_force
        est.wrench.force.x = out.pull_out_force
        band = self.band_msg
        band.header.stamp.sec, band.header.stamp.nanosec = sec, nanosec
        force = band.wrench.force
        force.x, force.y, force.z = out.band_low, out.band_high, out.estimated_force
        target = self.target_msg
        target.header.stamp.sec, target.header.stamp.nanosec = sec, nanosec
        target.wrench.force.z = out.target_force

    def command(self, out, stamp_ns: int):
        """Return the step's command message (the profile's unit), stamped ``stamp_ns`` (ns).

        None: no command goes out (the instrument may not be driven).
        """
        raise NotImplementedError

    # ------------------------------------------------------------------ state
    def interlock(self) -> str | None:
        """Return why the instrument may not be driven now (None: it may)."""
        return None

    def attach(self, node) -> None:
        """Create the profile's own entities on ``node`` (beside the loop's; none here)."""

    def detach(self, node) -> None:
        """Destroy what :meth:`attach` created on ``node``."""

    def status(self) -> dict[str, str]:
        """Key/value strings of the profile for /diagnostics."""
        return {'interface': self.interface}


class CrtkControllerIO(ControllerIO):
    """The ``crtk`` profile: this package's own topics, the current in A."""

    interface = 'crtk'

    def __init__(self, params, names: topics.TopicSet):
        super().__init__(params, names)
        self._servo = JointStateWriter([topics.DRUM_JOINT], ('effort',))

    def read_instrument(self, data: bytes, now: float, inputs):
        """Store wrist and jaw; with the drum too (combined), the step runs on it.

        Returns :data:`NO_STEP` for the joints alone, else as :meth:`read_actuator`.
        """
        combined = False
        try:
            msg = JointStateData(data)
            combined = len(msg.name) == 3
            fields = ('position', 'velocity') if len(msg.velocity) else ('position',)
            joints = read_joints(msg, _STATE_JOINTS if combined else _INSTRUMENT_JOINTS, fields)
            if combined:
                current = _drum_effort(msg)
        except InputRejected as exc:
            self._reject(inputs, 'instrument', now, exc)
            if combined:
                self._reject(inputs, 'actuator', now, exc)
                return None
            return NO_STEP
        wrist, jaw = joints[topics.WRIST_JOINT], joints[topics.JAW_JOINT]
        stamp = msg.stamp
        why = inputs.set_instrument(now, wrist[0], jaw[0], jaw[1] if len(jaw) > 1 else 0.0,
                                    stamp)[1]
        if why is not None:
            self.rejections.append(why)
        if not combined:
            return NO_STEP
        drum = joints[topics.DRUM_JOINT]
        fresh, why = inputs.set_actuator(now, current - self.current_offset, drum[0],
                                         drum[1] if len(drum) > 1 else 0.0, stamp)
        if why is not None:
            self.rejections.append(why)
        return msg.sec * 1_000_000_000 + msg.nanosec if fresh and stamp != 0.0 else None

    def read_actuator(self, data: bytes, now: float, inputs):
        """Store the actuator state (the step runs on it).

        Returns its header stamp (int ns) when it was accepted as a new, stamped sample, else
        None (the step carries the controller's clock).
        """
        try:
            msg = JointStateData(data)
            fields = _DRUM_FIELDS if len(msg.velocity) else _DRUM_FIELDS[:2]
            (drum,) = read_joints(msg, _ACTUATOR_JOINTS, fields).values()
        except InputRejected as exc:
            self._reject(inputs, 'actuator', now, exc)
            return None
        stamp = msg.stamp
        fresh, why = inputs.set_actuator(now, drum[0] - self.current_offset, drum[1],
                                         drum[2] if len(drum) > 2 else 0.0, stamp)
        if why is not None:
            self.rejections.append(why)
        return msg.sec * 1_000_000_000 + msg.nanosec if fresh and stamp != 0.0 else None

    def command(self, out, stamp_ns: int) -> bytes:
        """Return the CDR bytes of the motor current setpoint (A) on ``instrument/actuator/servo_jf``."""
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        return self._servo.write(sec, nanosec, (out.current_command,))


class DvrkControllerIO(ControllerIO):
    """The ``dvrk`` profile: a dVRK PSM's jaw and wrist, its operating state, effort in N*m.

    Raises
    ------
    MissingCrtkMsgs
        crtk_msgs cannot be imported (the node refuses to start, saying how to get it).
    """

    interface = 'dvrk'
    raw_states = False

    def __init__(self, params, names: topics.TopicSet):
        self.msgs = crtk_msgs()          # first: without crtk_msgs nothing is created
        self.arm = params.arm
        super().__init__(params, names)
        self.conversion = JawEffortConversion.from_params(params)
        self.effort_limit = params.dvrk_jaw_effort_max      # N*m
        self.position = params.dvrk_command == 'position'
        self.loop = JawPositionLoop.from_params(params)
        self.setpoint_bounds = (params.jaw_angle_min, params.jaw_angle_max)   # rad: jaw.qmin, qmax
        if self.position:
            self.command_topic = names.jaw_servo_jp
        self.origin = SetpointOrigin()   # the measured jaw angle, low-passed: the setpoint's origin
        self.jaw = math.nan              # rad, its value at the last state
        self.setpoint = math.nan         # rad, last jaw/servo_jp sent
        self.wrist = math.nan            # rad, last wrist pitch of <arm>/measured_js
        self.wrist_time = math.nan       # s, its receive time
        self.wrist_joint = None          # the name the arm uses for it
        self.state: str | None = None    # crtk operating state of the arm (None: not known)
        self.is_homed = False
        self.is_busy = False
        self.state_stamp = -math.inf     # s, header stamp of the operating state held
        self.withheld = 0                # steps whose command was not sent (arm not ready)
        self.requested = False           # an enable/home request is pending (request_enable)
        self._request_at_start = params.request_enable
        self._last_request = -math.inf   # perf_counter s of the last state_command sent
        self._state_future = None
        self._state_asked = -math.inf    # perf_counter s of the last operating_state request
        self._servo_msg = (JointState(name=[topics.JAW_JOINT], position=[0.0]) if self.position
                           else JointState(name=[topics.JAW_JOINT], effort=[0.0]))
        self._entities: list = []        # the arm channel (attach)
        self.alive = False               # the arm channel exists: its callbacks take events
        self._log = self._clock = self._state_client = self._command_pub = None

    # ------------------------------------------------------------------ the arm channel
    def attach(self, node) -> None:
        """Create the arm's operating-state channel on ``node``; ask to enable if configured."""
        self._log, self._clock = node.get_logger(), node.get_clock()
        self.alive = True
        self._entities = [
            node.create_subscription(self.msgs.OperatingState, self.names.operating_state,
                                     self._live(self._on_operating_state), STATE_PUB_QOS),
            node.create_client(self.msgs.TriggerOperatingState, self.names.operating_state),
            node.create_publisher(self.msgs.StringStamped, self.names.state_command,
                                  STATE_PUB_QOS),
            node.create_timer(ARM_POLL_PERIOD, self._live(self._poll))]
        self._state_client, self._command_pub = self._entities[1], self._entities[2]
        if not self.position:
            self._log.warning(
                f'dvrk_command effort: {self.names.command} puts the whole arm {self.arm} in '
                'Cartesian effort mode (its joints commanded zero effort, no longer held), and '
                'any position command (teleoperation servo_cp) sets the jaw effort back to 0: '
                'only for an arm that is not teleoperated (dvrk_command position uses '
                f'{self.names.jaw_servo_jp})')
        if self._request_at_start:
            self.request_enable()

    def detach(self, node) -> None:
        """Destroy the arm's channel; what it had queued is dropped."""
        self.alive = False
        for entity in reversed(self._entities):
            kind = type(entity).__name__.lower()     # subscription, publisher, client, timer
            getattr(node, f'destroy_{kind}')(entity)
        self._entities = []

    def _live(self, callback):
        """Wrap ``callback`` to drop what comes after :meth:`detach`.

        The EventsExecutor may still run an event it queued before the entity was destroyed.
        """
        def live(*args):
            if self.alive:
                callback(*args)
        return live

    # ------------------------------------------------------------------ inputs
    def read_instrument(self, msg: JointState, now: float, inputs):
        """Keep the wrist pitch of the arm's joints (other joints are normal, not a fault).

        Returns :data:`NO_STEP`.
        """
        names = list(msg.name)
        joint = next((j for j in topics.DVRK_WRIST_JOINTS if j in names), None)
        if joint is None:
            self._reject(inputs, 'instrument', now, InputRejected(
                f'no wrist pitch joint ({" or ".join(topics.DVRK_WRIST_JOINTS)}) in '
                f'{self.names.instrument_js}: {names}'))
            return NO_STEP
        try:
            (wrist,), = read_joints(msg, (joint,), ('position',), others=True).values()
        except InputRejected as exc:
            self._reject(inputs, 'instrument', now, exc)
            return NO_STEP
        self.wrist, self.wrist_time, self.wrist_joint = wrist, now, joint
        return NO_STEP

    def read_actuator(self, msg: JointState, now: float, inputs):
        """Feed the jaw to the instrument (with the wrist) and actuator (current) inputs.

        The step runs on it: returns its header stamp (int ns) when the actuator sample was
        accepted as a new, stamped one, else None.
        """
        fields = ('position', 'effort', 'velocity') if len(msg.velocity) else ('position', 'effort')
        try:
            (jaw,) = read_joints(msg, _JAW_JOINTS, fields).values()
        except InputRejected as exc:
            self._reject(inputs, 'actuator', now, exc)
            self._reject(inputs, 'instrument', now, exc)
            return None
        header = msg.header.stamp
        stamp = stamp_seconds(header)
        self.jaw = self.origin.update(jaw[0], now)
        age = now - self.wrist_time
        if age <= self.wrist_timeout:
            why = inputs.set_instrument(now, self.wrist, jaw[0], jaw[2] if len(jaw) > 2 else 0.0,
                                        stamp)[1]
            if why is not None:
                self.rejections.append(why)
        else:
            why = ('no wrist yet' if age != age else f'stale wrist: {age * 1e3:.1f} ms old')
            self._reject(inputs, 'instrument', now,
                         InputRejected(f'{why} ({self.names.instrument_js})'))
        # the dVRK's effort is computed from the measured motor currents: invert its conversion
        fresh, why = inputs.set_actuator(now, self.conversion.current(jaw[1]) - self.current_offset,
                                         stamp=stamp)
        if why is not None:
            self.rejections.append(why)
        return header.sec * 1_000_000_000 + header.nanosec if fresh and stamp != 0.0 else None

    def _on_operating_state(self, msg) -> None:
        stamp = stamp_seconds(msg.header.stamp)
        if stamp and stamp < self.state_stamp:
            return                      # an older state (a service reply overtaken by a topic)
        previous = (self.state, self.is_homed, self.is_busy)
        self.state, self.is_homed, self.is_busy = msg.state, bool(msg.is_homed), bool(msg.is_busy)
        self.state_stamp = stamp if stamp else self.state_stamp
        if (self.state, self.is_homed, self.is_busy) != previous:
            self._log.info(
                f'arm {self.arm}: {self.state}, {"homed" if self.is_homed else "not homed"}'
                f'{", busy" if self.is_busy else ""}')
        if self.requested and self.interlock() is None:
            self.requested = False
            self._log.info(f'arm {self.arm} is enabled and homed')

    # ------------------------------------------------------------------ the arm
    def request_enable(self) -> None:
        """Ask the arm to enable and home (sent when the arm's state_command is subscribed)."""
        self.requested = True
        self._last_request = -math.inf
        if self.alive:
            self._poll()

    def _poll(self) -> None:
        """Ask for the operating state while none is known; send a pending enable/home."""
        now = time.perf_counter()
        pending = self._state_future is not None and not self._state_future.done()
        if pending and now - self._state_asked > STATE_REPLY_WAIT:
            self._state_client.remove_pending_request(self._state_future)   # its answer: lost
            pending = False
        if self.state is None and not pending and self._state_client.service_is_ready():
            self._state_future = self._state_client.call_async(
                self.msgs.TriggerOperatingState.Request())
            self._state_future.add_done_callback(self._on_state_reply)
            self._state_asked = now
        if not self.requested or self._command_pub.get_subscription_count() == 0:
            return                      # a state_command nobody hears is lost (sent once)
        if time.perf_counter() - self._last_request < ARM_POLL_PERIOD * 1.9:
            return
        if self.state != 'ENABLED':
            self._send('enable')
        elif not self.is_homed and not self.is_busy:
            self._send('home')

    def _on_state_reply(self, future) -> None:
        if not self.alive:
            return
        try:
            self._on_operating_state(future.result().operating_state)
        except Exception as exc:  # noqa: BLE001 - a failed call: poll again later
            self._log.warning(f'operating_state service of {self.arm} failed: {exc}',
                              throttle_duration_sec=5.0)

    def _send(self, command: str) -> None:
        msg = self.msgs.StringStamped()
        msg.header.stamp = self._clock.now().to_msg()
        msg.string = command
        self._command_pub.publish(msg)
        self._last_request = time.perf_counter()
        self._log.info(f'asked arm {self.arm} to {command} ({self.names.state_command})')

    def interlock(self) -> str | None:
        """Return why the arm may not be driven: not ENABLED, not homed, busy, or unknown."""
        return arm_interlock(self.arm, self.state, self.is_homed, self.is_busy)

    # ------------------------------------------------------------------ outputs
    def command(self, out, stamp_ns: int):
        """Return the step's jaw command; None while the arm is not ready.

        ``position``: the ``<arm>/jaw/servo_jp`` setpoint (rad): in free motion the jaw's
        target angle; in grip and safe the setpoint at which the PSM's jaw loop gives, at the
        measured jaw angle (low-passed, :class:`~grip_force_ros.model.dvrk_jaw.SetpointOrigin`),
        the jaw effort of the step's current (so a current ramping to 0 brings the setpoint to
        the measured angle, without a jump); bounded by
        ``jaw_angle_min`` / ``jaw_angle_max`` (the tool's qmin, qmax;
        :meth:`~grip_force_ros.model.dvrk_jaw.JawPositionLoop.command_setpoint`). ``effort``: the jaw
        effort (N*m) for ``<arm>/jaw/servo_jf``.
        """
        if self.interlock() is not None:
            self.withheld += 1          # a disabled arm gets nothing (a command takes over the jaw)
            return None
        effort = self.conversion.effort(out.current_command)
        limit = self.effort_limit       # the current limit already keeps it inside; rounding
        effort = limit if effort > limit else (-limit if effort < -limit else effort)
        servo = self._servo_msg
        servo.header.stamp.sec, servo.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        if not self.position:
            servo.effort[0] = effort
            return servo
        if self.jaw != self.jaw:
            self.withheld += 1          # no jaw angle yet: no setpoint to start from
            return None
        self.setpoint = self.loop.command_setpoint(str(out.mode), effort, self.jaw,
                                                   out.target_jaw_angle, *self.setpoint_bounds)
        servo.position[0] = self.setpoint
        return servo

    def status(self) -> dict[str, str]:
        """Key/value strings of the dvrk profile for /diagnostics."""
        return {'interface': self.interface, 'arm': self.arm,
                'arm_state': self.state or 'unknown', 'arm_homed': str(self.is_homed).lower(),
                'arm_busy': str(self.is_busy).lower(),
                'wrist_joint': self.wrist_joint or 'none yet',
                'dvrk_command': 'position' if self.position else 'effort',
                'command_topic': self.command_topic,
                'jaw_setpoint_rad': f'{self.setpoint:.5f}' if self.setpoint == self.setpoint
                else 'none',
                'commands_withheld': str(self.withheld),
                'enable_requested': str(self.requested).lower()}


def _drum_effort(msg) -> float:
    """Return the drum's effort (measured current, A) of a combined state; only its is read.

    Raises
    ------
    InputRejected
        No effort for every joint, or the drum's is not finite.
    """
    if len(msg.effort) != len(msg.name):
        raise InputRejected(f'effort has {len(msg.effort)} values for {len(msg.name)} joints')
    current = msg.effort[msg.name.index(topics.DRUM_JOINT)]
    if not math.isfinite(current):
        raise InputRejected(f"effort of '{topics.DRUM_JOINT}' is {current}")
    return current


def controller_io(params) -> ControllerIO:
    """Make the converters of the ``interface`` profile of ``params``."""
    names = topics.topic_set(params.interface, params.arm, params.master)
    if params.interface == 'dvrk':
        return DvrkControllerIO(params, names)
    return CrtkControllerIO(params, names)
