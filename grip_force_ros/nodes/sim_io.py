"""The simulated instrument's I/O wiring of one interface profile: topics, messages, units.

:class:`SimInstrumentNode` (nodes/sim_instrument.py) steps the plant, holds the current
command and its drive-side timeout, takes the command topic and publishes /diagnostics; the
profile object made by :func:`sim_io` converts the command message into a current
(:meth:`SimIO.read_command`, which never calls the node), and, once attached to the node
(:meth:`SimIO.attach`: the sensor publishers, the dvrk arm's operating-state channel),
publishes the sensors:

``crtk`` (:class:`CrtkSimIO`)
    command ``instrument/actuator/servo_jf`` (jaw_drum, effort = current, A); sensors
    ``grip/measured_force``, then ``instrument/measured_js`` with the joints and the drum
    (``state_message: combined``; the controller steps on it, with the load cell of the same
    sample), or the joints there, the load cell, then the drum on
    ``instrument/actuator/measured_js`` (``split``).
``dvrk`` (:class:`DvrkSimIO`): the sim as a dVRK PSM named ``arm``
    command ``<arm>/jaw/servo_jf`` (jaw, effort = jaw effort, N*m; turned into the motor
    current with the dVRK's conversion, :mod:`grip_force_ros.model.dvrk_jaw`), taken only
    while the arm is ENABLED and homed and within the tool's effort limit
    (``dvrk_jaw_effort_max``), refused with a warning otherwise; sensors ``<arm>/measured_js``
    (the PSM's six joints by name, :data:`grip_force_ros.topics.DVRK_PSM_JOINTS`; the sim
    moves only the wrist pitch, the others hold 0), ``<arm>/jaw/measured_js`` (jaw position,
    velocity, effort computed from the measured current as the dVRK does; sent last, the
    controller steps on it) and the load cell ``<arm>/grip/measured_force`` (not a dVRK topic:
    the sim's extra; sent before the jaw); the arm's
    ``<arm>/operating_state`` (crtk_msgs/OperatingState: published on every change and in
    answer to every state command, and a service of the same name) driven by
    ``<arm>/state_command`` (crtk_msgs/StringStamped: enable, disable, pause, resume, home,
    unhome; :class:`grip_force_ros.sim.drive.ArmState`). The arm's control space and mode
    as the dVRK keeps them (:class:`grip_force_ros.sim.psm.PsmControl`, reported on
    /diagnostics): ``<arm>/jaw/servo_jf`` puts the whole arm in Cartesian effort mode (its
    joints drift, said once in the log); ``<arm>/jaw/servo_jp`` (jaw position, rad),
    ``<arm>/servo_cp`` (geometry_msgs/PoseStamped) and ``<arm>/servo_jp`` (the arm's joints)
    put it in position mode (the jaw effort reset to 0); in position mode the jaw follows its
    setpoint through the disc PIDs at 1.5 kHz inside the step.
"""
from __future__ import annotations

import time

from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.time import Time
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.model.dvrk_jaw import JawEffortConversion, JawPositionLoop
from grip_force_ros.nodes.common import STATE_PUB_QOS, STATE_SUB_QOS, InputRejected, read_joints, \
    stamp_nanoseconds
from grip_force_ros.nodes.dvrk_msgs import crtk_msgs
from grip_force_ros.nodes.wire import JointStateData, JointStateWriter, WrenchWriter
from grip_force_ros.sim.drive import ArmState
from grip_force_ros.sim.psm import ARM_JOINTS, PsmControl

_COMMAND_JOINTS = (topics.DRUM_JOINT,)
#: The crtk state's joints: the wrist and the jaw, then the drum (combined: one message).
_STATE_JOINTS = (topics.WRIST_JOINT, topics.JAW_JOINT, topics.DRUM_JOINT)
_NAN = float('nan')
_JAW_JOINTS = (topics.JAW_JOINT,)


class CommandRefused(ValueError):
    """A command the drive does not take; ``str()`` is the reason.

    Parameters
    ----------
    reason : str
        Why it was refused.
    stamp_ns : int
        The command's header stamp (ns; 0 when it could not be read).
    """

    def __init__(self, reason: str, stamp_ns: int):
        super().__init__(reason)
        self.stamp_ns = stamp_ns


class SimIO:
    """What both profiles share: the load cell.

    Parameters
    ----------
    params : ParamSet
        The node's parameters.
    names : TopicSet
        The profile's topics (:func:`grip_force_ros.topics.topic_set`).

    Attributes
    ----------
    raw_command : bool
        The command topic is taken as serialized bytes (:mod:`~grip_force_ros.nodes.wire`).
    """

    interface = ''
    raw_command = True

    def __init__(self, params, names: topics.TopicSet):
        self.names = names
        self._force_pub = None
        self._force_msg = WrenchStamped()
        self._force_msg.header.frame_id = topics.JAW_FRAME
        self._log = None

    def attach(self, node) -> None:
        """Create the sensor publishers (and the profile's own entities) on ``node``."""
        self._log = node.get_logger()
        self._force_pub = node.create_publisher(WrenchStamped, self.names.measured_force,
                                                STATE_PUB_QOS)

    def read_command(self, data):
        """Return ``(current, stamp_ns)`` of a command message: the current to hold (A).

        Raises
        ------
        CommandRefused
            The message is malformed, or the drive does not take it now.
        """
        raise NotImplementedError

    def command_readers(self):
        """Return ``(msg_type, topic, raw, read)`` of each jaw command topic the node takes.

        ``read(msg)`` returns ``(current, stamp_ns)`` (the current to hold, A) or raises
        :class:`CommandRefused`; every accepted one re-arms the drive's command timeout.
        """
        return [(JointState, self.names.command, self.raw_command, self.read_command)]

    def powered(self) -> bool:
        """Tell whether the drive may carry a current (the dVRK arm: ENABLED)."""
        return True

    def step(self, plant, current: float, dt: float) -> None:
        """Advance ``plant`` by ``dt`` (s) with the held ``current`` (A)."""
        plant.step(current, dt)

    def cut(self) -> None:
        """Take the drive's command timeout: it cut the current (the node already holds 0 A)."""

    def drive_current(self, current: float) -> float:
        """Return the current command (A) the drive follows now, given the held ``current``."""
        return current

    def update(self, now: float) -> None:
        """Advance the profile's own state to ``now`` (s)."""

    def status(self) -> dict[str, str]:
        """Key/value strings of the profile for /diagnostics."""
        return {'interface': self.interface}


class CrtkSimIO(SimIO):
    """The ``crtk`` profile: this package's topics, the current in A.

    The 1 kHz messages go as serialized bytes (:mod:`~grip_force_ros.nodes.wire`): the
    command is read from them, the sensors are written into them.
    """

    interface = 'crtk'

    def __init__(self, params, names: topics.TopicSet):
        super().__init__(params, names)
        self.combined = params.state_message == 'combined'
        self._joint_pub = self._actuator_pub = None
        self._force = WrenchWriter(topics.JAW_FRAME)
        if self.combined:
            self._state = JointStateWriter(_STATE_JOINTS, ('position', 'velocity', 'effort'))
            return
        self._joints = JointStateWriter(_STATE_JOINTS[:2], ('position', 'velocity'))
        self._actuator = JointStateWriter(_STATE_JOINTS[2:], ('position', 'velocity', 'effort'))

    def attach(self, node) -> None:
        """Create the sensor publishers on ``node``: the state (split: and the actuator's)."""
        super().attach(node)
        self._joint_pub = node.create_publisher(JointState, self.names.instrument_js,
                                                STATE_PUB_QOS)
        if not self.combined:
            self._actuator_pub = node.create_publisher(JointState, self.names.actuator_js,
                                                       STATE_PUB_QOS)

    def read_command(self, data: bytes):
        """Return ``(current, stamp_ns)`` of a ``servo_jf`` (jaw_drum effort = current, A).

        Raises
        ------
        CommandRefused
            The bytes are not a JointState, or not one current for the drum.
        """
        try:
            msg = JointStateData(data)
        except InputRejected as exc:
            raise CommandRefused(f'rejected current command: {exc}', 0) from None
        stamp = msg.sec * 1_000_000_000 + msg.nanosec
        try:
            (current,), = read_joints(msg, _COMMAND_JOINTS, ('effort',)).values()
        except InputRejected as exc:
            raise CommandRefused(f'rejected current command: {exc}', stamp) from None
        return current, stamp

    def publish_state(self, m, stamp_ns: int) -> None:
        """Publish a step's sensors, stamped ``stamp_ns`` (ns): the load cell, then the state.

        The message the controller steps on goes last (the combined state, or the actuator
        state after the joints), so the step finds the load cell of the same sample in.
        """
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        if self.combined:
            self._force_pub.publish(self._force.write(sec, nanosec, (0.0, 0.0, m.grip_force)))
            self._joint_pub.publish(self._state.write(
                sec, nanosec, (m.wrist_angle, m.jaw_angle, m.motor_angle),
                (0.0, m.jaw_velocity, m.motor_velocity), (_NAN, _NAN, m.current)))
            return
        self._joint_pub.publish(self._joints.write(sec, nanosec, (m.wrist_angle, m.jaw_angle),
                                                   (0.0, m.jaw_velocity)))
        self._force_pub.publish(self._force.write(sec, nanosec, (0.0, 0.0, m.grip_force)))
        self._actuator_pub.publish(self._actuator.write(sec, nanosec, (m.motor_angle,),
                                                        (m.motor_velocity,), (m.current,)))


class DvrkSimIO(SimIO):
    """The ``dvrk`` profile: the sim as a dVRK PSM (topics, units, operating state).

    Raises
    ------
    MissingCrtkMsgs
        crtk_msgs cannot be imported (the node refuses to start, saying how to get it).
    """

    interface = 'dvrk'
    raw_command = False

    def __init__(self, params, names: topics.TopicSet):
        self.msgs = crtk_msgs()          # first: without crtk_msgs nothing is created
        super().__init__(params, names)
        self.arm_name = params.arm
        self.arm = ArmState(params.homing_time)
        self.conversion = JawEffortConversion.from_params(params)
        self.effort_limit = params.dvrk_jaw_effort_max       # N*m
        self.refused_not_ready = 0       # servo_jf while not ENABLED and homed
        self.refused_effort = 0          # servo_jf beyond the effort limit
        self.refused_position = 0        # jaw/servo_jp, servo_cp, servo_jp while not ready
        self.psm = PsmControl(JawPositionLoop.from_params(params), params.jaw_angle_min,
                              params.jaw_angle_max)
        self._arm_index = [topics.DVRK_PSM_JOINTS.index(j) for j in ARM_JOINTS]
        self.state_commands = 0
        self._clock = self._state_pub = self._arm_pub = self._jaw_pub = None
        self._arm_msg = JointState(name=list(topics.DVRK_PSM_JOINTS),
                                   position=[0.0] * len(topics.DVRK_PSM_JOINTS))
        self._wrist_index = topics.DVRK_PSM_JOINTS.index(topics.WRIST_JOINT)
        self._jaw_msg = JointState(name=[topics.JAW_JOINT], position=[0.0], velocity=[0.0],
                                   effort=[0.0])
        self._published_state = None

    def attach(self, node) -> None:
        """Create on ``node`` the sensor publishers and the arm's operating-state channel."""
        super().attach(node)
        names = self.names
        self._clock = node.get_clock()
        node.create_subscription(self.msgs.StringStamped, names.state_command,
                                 self._on_state_command, STATE_SUB_QOS)
        self._state_pub = node.create_publisher(self.msgs.OperatingState, names.operating_state,
                                                STATE_PUB_QOS)
        node.create_service(self.msgs.TriggerOperatingState, names.operating_state,
                            self._on_state_request)
        self._arm_pub = node.create_publisher(JointState, names.instrument_js, STATE_PUB_QOS)
        self._jaw_pub = node.create_publisher(JointState, names.actuator_js, STATE_PUB_QOS)
        node.create_subscription(PoseStamped, names.servo_cp, self._on_servo_cp, STATE_SUB_QOS)
        node.create_subscription(JointState, names.servo_jp, self._on_servo_jp, STATE_SUB_QOS)
        self.publish_operating_state()

    # ------------------------------------------------------------------ the arm
    def _operating_state_msg(self):
        msg = self.msgs.OperatingState()
        msg.header.stamp = self._clock.now().to_msg()
        msg.header.frame_id = self.arm_name
        msg.state, msg.is_homed, msg.is_busy = self.arm.key()
        return msg

    def publish_operating_state(self) -> None:
        """Publish the arm's operating state (on change, and in answer to a state command)."""
        self._published_state = self.arm.key()
        self._state_pub.publish(self._operating_state_msg())

    def _on_state_request(self, _request, response):
        response.operating_state = self._operating_state_msg()
        return response

    def _on_state_command(self, msg) -> None:
        command = str(msg.string)
        self.state_commands += 1
        before = self.arm.key()
        why = self.arm.command(command, time.monotonic())   # the drive's clock
        log = self._log
        if why is not None:
            log.warning(f'{self.arm_name}: {why}')
        elif self.arm.key() != before:
            log.info(f'{self.arm_name}: {command} -> {self.arm.state}'
                     f'{", homing" if self.arm.is_busy else ""}')
        self.publish_operating_state()   # every command gets an answer (the client waits on it)

    def powered(self) -> bool:
        """Tell whether the drives of the arm carry current: it is ENABLED (homing or not)."""
        return self.arm.state == 'ENABLED'

    def update(self, now: float) -> None:
        """Complete a homing in progress; publish the operating state when it changed."""
        self.arm.update(now)
        if self.arm.ready and self.psm.mode == 'UNDEFINED_MODE':
            self.psm.homed()             # homed: joint position mode, the arm held
        notice = self.psm.take_notice()
        if notice:
            self._log.warning(f'{self.arm_name}: {notice}')
        if self.arm.key() != self._published_state:
            self._log.info(f'{self.arm_name}: {self.arm.state}, '
                           f'{"homed" if self.arm.is_homed else "not homed"}')
            self.publish_operating_state()

    # ------------------------------------------------------------------ commands
    def read_command(self, msg: JointState):
        """Return ``(current, stamp_ns)`` of a ``<arm>/jaw/servo_jf``: the jaw effort as current (A).

        Raises
        ------
        CommandRefused
            Malformed, the arm not ENABLED and homed, or beyond the tool's effort limit.
        """
        stamp = stamp_nanoseconds(msg.header.stamp)
        if not msg.name and len(msg.effort) == 1:    # the dVRK's own client names no joint
            msg = JointState(header=msg.header, name=[topics.JAW_JOINT], effort=list(msg.effort))
        try:
            (effort,), = read_joints(msg, _JAW_JOINTS, ('effort',)).values()
        except InputRejected as exc:
            raise CommandRefused(f'rejected jaw effort: {exc}', stamp) from None
        if not self.arm.ready:
            self.refused_not_ready += 1
            raise CommandRefused(f'servo_jf refused: arm {self.arm_name} is {self.arm.state}'
                                 f'{"" if self.arm.is_homed else ", not homed"}'
                                 f'{", busy homing" if self.arm.is_busy else ""}', stamp)
        if abs(effort) > self.effort_limit:
            self.refused_effort += 1
            raise CommandRefused(f'servo_jf refused: jaw effort {effort:.4f} N*m beyond the tool '
                                 f'limit +-{self.effort_limit:g} N*m (a current in A on the '
                                 'effort topic?)', stamp)
        self.psm.jaw_effort()
        return self.conversion.current(effort), stamp

    def command_readers(self):
        """Return the jaw's two command topics: ``jaw/servo_jf`` (effort) and ``jaw/servo_jp`` (position)."""
        return [(JointState, self.names.command, False, self.read_command),
                (JointState, self.names.jaw_servo_jp, False, self.read_jaw_position)]

    def _not_ready(self, what: str) -> str | None:
        if self.arm.ready:
            return None
        self.refused_position += 1
        return (f'{what} refused: arm {self.arm_name} is {self.arm.state}'
                f'{"" if self.arm.is_homed else ", not homed"}'
                f'{", busy homing" if self.arm.is_busy else ""}')

    def read_jaw_position(self, msg: JointState):
        """Take a ``<arm>/jaw/servo_jp``: the jaw's setpoint (rad), the arm in position mode.

        Returns ``(0.0, stamp_ns)``: the held jaw effort is 0 (the PID drives the jaw).

        Raises
        ------
        CommandRefused
            Malformed, or the arm not ENABLED and homed.
        """
        stamp = stamp_nanoseconds(msg.header.stamp)
        if not msg.name and len(msg.position) == 1:   # the dVRK's own client names no joint
            msg = JointState(header=msg.header, name=[topics.JAW_JOINT],
                             position=list(msg.position))
        try:
            (setpoint,), = read_joints(msg, _JAW_JOINTS, ('position',)).values()
        except InputRejected as exc:
            raise CommandRefused(f'rejected jaw setpoint: {exc}', stamp) from None
        why = self._not_ready('jaw/servo_jp')
        if why is not None:
            raise CommandRefused(why, stamp)
        self.psm.jaw_position(setpoint)
        return 0.0, stamp

    def _on_servo_cp(self, msg) -> None:
        why = self._not_ready('servo_cp')
        if why is not None:
            self._log.warning(why, throttle_duration_sec=1.0)
            return
        self.psm.arm_cartesian_position()

    def _on_servo_jp(self, msg: JointState) -> None:
        why = self._not_ready('servo_jp')
        if why is None and not all(q == q for q in msg.position):
            why = 'servo_jp refused: a position is not finite'
        if why is not None:
            self._log.warning(why, throttle_duration_sec=1.0)
            return
        self.psm.arm_joint_position(list(msg.position))

    def step(self, plant, current: float, dt: float) -> None:
        """Advance the plant and the arm's joints by ``dt`` (s) in the arm's control mode."""
        self.psm.advance(plant, current, dt, self.powered())

    def cut(self) -> None:
        """Take the command timeout: the jaw's position loop stops too (0 A) until the next command."""
        self.psm.cut()

    def drive_current(self, current: float) -> float:
        """Return the current (A): the held effort's in effort mode, the jaw PID's output in position mode."""
        if not self.powered():
            return 0.0
        return current if self.psm.effort_mode else self.psm.pid_current

    # ------------------------------------------------------------------ sensors
    def publish_state(self, m, stamp_ns: int) -> None:
        """Publish a step's arm joints and load cell, then the jaw (the controller steps on it)."""
        stamp = Time(nanoseconds=stamp_ns).to_msg()
        arm = self._arm_msg
        arm.header.stamp = stamp
        arm.position[self._wrist_index] = m.wrist_angle
        for i, q in zip(self._arm_index, self.psm.joints):
            arm.position[i] = q
        self._arm_pub.publish(arm)
        force = self._force_msg
        force.header.stamp = stamp
        force.wrench.force.z = m.grip_force
        self._force_pub.publish(force)
        jaw = self._jaw_msg
        jaw.header.stamp = stamp
        jaw.position[0], jaw.velocity[0] = m.jaw_angle, m.jaw_velocity
        jaw.effort[0] = self.conversion.effort(m.current)   # the dVRK: from the measured current
        self._jaw_pub.publish(jaw)

    def status(self) -> dict[str, str]:
        """Key/value strings of the dvrk profile for /diagnostics."""
        state, homed, busy = self.arm.key()
        return {'interface': self.interface, 'arm': self.arm_name, 'arm_state': state,
                'arm_homed': str(homed).lower(), 'arm_busy': str(busy).lower(),
                'servo_jf_refused_not_ready': str(self.refused_not_ready),
                'servo_jf_refused_effort_limit': str(self.refused_effort),
                'position_commands_refused_not_ready': str(self.refused_position),
                'state_commands': str(self.state_commands), **self.psm.status()}


def sim_io(params) -> SimIO:
    """Make the converters of the ``interface`` profile of ``params`` (then :meth:`SimIO.attach`)."""
    names = topics.topic_set(params.interface, params.arm, params.master)
    if params.interface == 'dvrk':
        return DvrkSimIO(params, names)
    return CrtkSimIO(params, names)
