"""The controller's I/O wiring of one interface profile: topics, messages, units.

:class:`ControllerNode` (nodes/controller.py) keeps the loop, the timing and
/diagnostics; the profile object made by :func:`controller_io` subscribes to the inputs,
fills the controller's :class:`~grip_force_ros.control.ControlInputs`, asks the node to step
when a fresh instrument state arrives, and publishes the command and the force outputs:

``crtk`` (:class:`CrtkControllerIO`; topics.py, docs/ros_interface.md)
    ``master/gripper/measured_js``, ``instrument/measured_js`` (wrist_pitch, jaw),
    ``instrument/actuator/measured_js`` (jaw_drum, effort = current, A): the step runs on it;
    command ``instrument/actuator/servo_jf`` (jaw_drum, effort = current, A).
``dvrk`` (:class:`DvrkControllerIO`; docs/dvrk.md)
    ``<master>/gripper/measured_js`` (gripper), ``<arm>/measured_js`` (the wrist picked by
    name among the arm's joints), ``<arm>/jaw/measured_js`` (jaw: position, velocity, effort
    in N*m, turned into the motor current with the dVRK's own conversion,
    :mod:`grip_force_ros.model.dvrk_jaw`): the step runs on it; command ``<arm>/jaw/servo_jf``
    (jaw effort, N*m), sent only while ``<arm>/operating_state`` is ENABLED and homed (the
    step is safe otherwise, with the reason); ``<arm>/state_command`` when asked to enable
    and home (``request_enable``); the grip force topics under ``<arm>/grip/``.

The node calls :meth:`ControllerIO.publish` after each step with the step's output. Both
profiles subtract the tare's offsets (``current_sensor_offset``, ``load_cell_offset``) from
the measured current and the load cell before the controller sees them. The node creates
the I/O object when it is configured and calls :meth:`ControllerIO.destroy` when it is
cleaned up (lifecycle, nodes/controller.py).
"""
from __future__ import annotations

import math
import time

from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.model.dvrk_jaw import JawEffortConversion
from grip_force_ros.nodes.common import STATE_PUB_QOS, STATE_SUB_QOS, InputRejected, read_joints, \
    stamp_seconds
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


class ControllerIO:
    """What both profiles share: the master, the load cell, the force outputs.

    Parameters
    ----------
    node : ControllerNode
        Provides ``inputs`` (ControlInputs), ``now()`` (s), ``report(reason)``,
        ``reject(source, now, exc)``, ``on_state(stamp)`` (run a control step on a fresh
        state; ``stamp``: the state's header stamp, or None) and ``get_logger()``.
    params : ParamSet
        The node's parameters.
    names : TopicSet
        The profile's topics (:func:`grip_force_ros.topics.topic_set`).
    """

    interface = ''

    def __init__(self, node, params, names: topics.TopicSet):
        self.node = node
        self.names = names
        self._entities: list = []      # what this object created on the node (destroy())
        self.alive = True              # False once destroy() ran: callbacks drop their event
        self.subscribe(JointState, names.master_js, self._on_master, STATE_SUB_QOS, raw=True)
        self._force_sub = None
        self._force_wanted = False     # a service needs the load cell (want_force)
        self.update_params(params)
        self._estimate_pub = self.publisher(WrenchStamped, names.estimated_force, STATE_PUB_QOS)
        self._target_pub = self.publisher(WrenchStamped, names.target_force, STATE_PUB_QOS)
        # Messages reused every step: fill, do not rebuild.
        self._estimate_msg = WrenchStamped()
        self._estimate_msg.header.frame_id = topics.JAW_FRAME
        self._target_msg = WrenchStamped()
        self._target_msg.header.frame_id = topics.JAW_FRAME
        self._next_forces_ns = 0       # controller clock (ns) at which the forces are due

    # ------------------------------------------------------------------ entities
    def subscribe(self, msg_type, topic: str, callback, qos, raw: bool = False):
        """Create a subscription on the node, for :meth:`destroy`; see :meth:`_live`.

        ``raw``: the callback takes the serialized bytes (:mod:`~grip_force_ros.nodes.wire`).
        """
        sub = self.node.create_subscription(msg_type, topic, self._live(callback), qos, raw=raw)
        self._entities.append(sub)
        return sub

    def _live(self, callback):
        """Wrap ``callback`` to drop what comes after :meth:`destroy`.

        The EventsExecutor may still run an event it queued before the entity was destroyed
        (seen: a joint state after ``shutdown`` released the inputs).
        """
        def live(*args):
            if self.alive:
                callback(*args)
        return live

    def publisher(self, *args):
        """Create a publisher on the node (``create_publisher`` arguments), for :meth:`destroy`."""
        pub = self.node.create_publisher(*args)
        self._entities.append(pub)
        return pub

    def destroy(self) -> None:
        """Destroy every subscription, publisher, client and timer this object created."""
        node = self.node
        self.alive = False
        if self._force_sub is not None:
            node.destroy_subscription(self._force_sub)
            self._force_sub = None
        for entity in reversed(self._entities):
            kind = type(entity).__name__.lower()     # subscription, publisher, client, timer
            getattr(node, f'destroy_{kind}')(entity)
        self._entities = []

    # ------------------------------------------------------------------ inputs
    def _on_master(self, data: bytes) -> None:
        node = self.node
        now = node.now()
        try:
            msg = JointStateData(data)
            (angle,), = read_joints(msg, _MASTER_JOINTS, ('position',)).values()
        except InputRejected as exc:
            return node.reject('master', now, exc)
        node.report(node.inputs.set_master(now, angle, msg.stamp))

    def _on_force(self, data: bytes) -> None:
        node = self.node
        now = node.now()
        try:
            stamp, _, _, force = read_wrench(data)
        except InputRejected as exc:
            return node.reject('force', now, exc)
        node.report(node.inputs.set_force(now, force - self.force_offset, stamp))

    def update_params(self, params) -> None:
        """Apply accepted parameters (the load-cell subscription follows force_sensor_enabled)."""
        self._force_enabled = params.force_sensor_enabled
        self.force_offset = params.load_cell_offset          # N
        self.current_offset = params.current_sensor_offset   # A
        # due again one output period after, less half a state period (so that at equal
        # rates the forces go out every step, whatever the states' jitter)
        self._forces_period_ns = max(0, int(1e9 / params.force_output_rate
                                            - 0.5e9 / params.expected_state_rate))
        self._follow_force()

    def want_force(self, wanted: bool) -> None:
        """Subscribe to the load cell while a service needs it, whatever force_sensor_enabled says."""
        self._force_wanted = wanted
        self._follow_force()

    def load_cell_publishers(self) -> int:
        """Return how many publishers the load-cell topic has (0: no load cell)."""
        node = self.node
        return node.count_publishers(node.resolve_topic_name(self.names.measured_force))

    def _follow_force(self) -> None:
        listen = self._force_enabled or self._force_wanted
        if listen and self._force_sub is None:
            self._force_sub = self.node.create_subscription(
                WrenchStamped, self.names.measured_force, self._live(self._on_force), STATE_SUB_QOS,
                raw=True)
        elif not listen and self._force_sub is not None:
            self.node.destroy_subscription(self._force_sub)
            self._force_sub = None

    # ------------------------------------------------------------------ outputs
    def publish(self, out, now_ns: int, answered_ns: int | None = None) -> None:
        """Publish the command of one step, then its forces when due (``force_output_rate``).

        ``now_ns``: the controller's clock at the step (ns); ``answered_ns``: the header stamp
        (ns) of the fresh state the step answers, which the command carries, or None (the
        command carries ``now_ns``).
        """
        self.publish_command(out, answered_ns if answered_ns is not None else now_ns)
        if now_ns >= self._next_forces_ns:
            self.publish_forces(out, now_ns)

    def publish_forces(self, out, now_ns: int) -> None:
        """Publish the estimated and target force of ``out``, stamped ``now_ns`` (ns)."""
        self._next_forces_ns = now_ns + self._forces_period_ns
        sec, nanosec = divmod(now_ns, 1_000_000_000)
        est = self._estimate_msg
        est.header.stamp.sec, est.header.stamp.nanosec = sec, nanosec
        est.wrench.force.z = out.estimated_force
        est.wrench.force.x = out.pull_out_force
        target = self._target_msg
        target.header.stamp.sec, target.header.stamp.nanosec = sec, nanosec
        target.wrench.force.z = out.target_force
        self._estimate_pub.publish(est)
        self._target_pub.publish(target)

    def publish_command(self, out, stamp_ns: int) -> None:
        """Send the step's command (the profile's topic and unit), stamped ``stamp_ns`` (ns)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ state
    def interlock(self) -> str | None:
        """Return why the instrument may not be driven now (None: it may)."""
        return None

    def status(self) -> dict[str, str]:
        """Key/value strings of the profile for /diagnostics."""
        return {'interface': self.interface}


class CrtkControllerIO(ControllerIO):
    """The ``crtk`` profile: this package's own topics, the current in A."""

    interface = 'crtk'

    def __init__(self, node, params, names: topics.TopicSet):
        super().__init__(node, params, names)
        self.subscribe(JointState, names.instrument_js, self._on_instrument, STATE_SUB_QOS,
                       raw=True)
        self.subscribe(JointState, names.actuator_js, self._on_actuator, STATE_SUB_QOS, raw=True)
        self._servo_pub = self.publisher(JointState, names.command, STATE_PUB_QOS)
        self._servo = JointStateWriter([topics.DRUM_JOINT], ('effort',))

    def _on_instrument(self, data: bytes) -> None:
        """Joint state: wrist and jaw; with the drum too (combined), the step runs on it."""
        node = self.node
        now = node.now()
        combined = False
        try:
            msg = JointStateData(data)
            combined = len(msg.name) == 3
            fields = ('position', 'velocity') if len(msg.velocity) else ('position',)
            joints = read_joints(msg, _STATE_JOINTS if combined else _INSTRUMENT_JOINTS, fields)
            if combined:
                current = _drum_effort(msg)
        except InputRejected as exc:
            node.reject('instrument', now, exc)
            if combined:
                node.reject('actuator', now, exc)
                node.on_state(None)
            return
        wrist, jaw = joints[topics.WRIST_JOINT], joints[topics.JAW_JOINT]
        jaw_velocity = jaw[1] if len(jaw) > 1 else 0.0
        stamp = msg.stamp
        inputs = node.inputs
        node.report(inputs.set_instrument(now, wrist[0], jaw[0], jaw_velocity, stamp))
        if not combined:
            return
        drum = joints[topics.DRUM_JOINT]
        node.report(inputs.set_actuator(now, current - self.current_offset, drum[0],
                                        drum[1] if len(drum) > 1 else 0.0, stamp))
        fresh = inputs.actuator_time == now and stamp != 0.0
        node.on_state(msg.sec * 1_000_000_000 + msg.nanosec if fresh else None)

    def _on_actuator(self, data: bytes) -> None:
        """Actuator state: store it and run the control step on it (event-driven loop)."""
        self.node.on_state(self._read_actuator(data))

    def _read_actuator(self, data: bytes) -> int | None:
        """Store the actuator state; its stamp (ns) if it was accepted as a new, stamped sample."""
        node = self.node
        now = node.now()
        try:
            msg = JointStateData(data)
            fields = _DRUM_FIELDS if len(msg.velocity) else _DRUM_FIELDS[:2]
            (drum,) = read_joints(msg, _ACTUATOR_JOINTS, fields).values()
        except InputRejected as exc:
            node.reject('actuator', now, exc)
            return None
        velocity = drum[2] if len(drum) > 2 else 0.0
        stamp = msg.stamp
        inputs = node.inputs
        node.report(inputs.set_actuator(now, drum[0] - self.current_offset, drum[1], velocity, stamp))
        # accepted now (a duplicate or rejected sample leaves actuator_time as it was)
        fresh = inputs.actuator_time == now and stamp != 0.0
        return msg.sec * 1_000_000_000 + msg.nanosec if fresh else None

    def publish_command(self, out, stamp_ns: int) -> None:
        """Send the current command (A) on ``instrument/actuator/servo_jf``."""
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        self._servo_pub.publish(self._servo.write(sec, nanosec, (out.current_command,)))


class DvrkControllerIO(ControllerIO):
    """The ``dvrk`` profile: a dVRK PSM's jaw and wrist, its operating state, effort in N*m.

    Raises
    ------
    MissingCrtkMsgs
        crtk_msgs cannot be imported (the node refuses to start, saying how to get it).
    """

    interface = 'dvrk'

    def __init__(self, node, params, names: topics.TopicSet):
        self.msgs = crtk_msgs()          # first: without crtk_msgs nothing is created
        self.arm = params.arm
        super().__init__(node, params, names)
        self.conversion = JawEffortConversion.from_params(params)
        self.effort_limit = params.dvrk_jaw_effort_max      # N*m
        self.wrist = math.nan            # rad, last wrist pitch of <arm>/measured_js
        self.wrist_time = math.nan       # s, its receive time
        self.wrist_joint = None          # the name the arm uses for it
        self.state: str | None = None    # crtk operating state of the arm (None: not known)
        self.is_homed = False
        self.is_busy = False
        self.state_stamp = -math.inf     # s, header stamp of the operating state held
        self.withheld = 0                # steps whose command was not sent (arm not ready)
        self.requested = False           # an enable/home request is pending (request_enable)
        self._last_request = -math.inf   # perf_counter s of the last state_command sent
        self._state_future = None
        self._state_asked = -math.inf    # perf_counter s of the last operating_state request
        self.subscribe(JointState, names.instrument_js, self._on_arm, STATE_SUB_QOS)
        self.subscribe(JointState, names.actuator_js, self._on_jaw, STATE_SUB_QOS)
        self.subscribe(self.msgs.OperatingState, names.operating_state, self._on_operating_state,
                       STATE_PUB_QOS)
        self._state_client = node.create_client(self.msgs.TriggerOperatingState,
                                                names.operating_state)
        self._entities.append(self._state_client)
        self._command_pub = self.publisher(self.msgs.StringStamped, names.state_command,
                                           STATE_PUB_QOS)
        self._servo_pub = self.publisher(JointState, names.command, STATE_PUB_QOS)
        self._servo_msg = JointState(name=[topics.JAW_JOINT], effort=[0.0])
        self._poll_timer = node.create_timer(ARM_POLL_PERIOD, self._live(self._poll))
        self._entities.append(self._poll_timer)
        if params.request_enable:
            self.request_enable()

    # ------------------------------------------------------------------ inputs
    def _on_arm(self, msg: JointState) -> None:
        """Keep the wrist pitch of the arm's joints (other joints are normal, not a fault)."""
        node = self.node
        now = node.now()
        names = list(msg.name)
        joint = next((j for j in topics.DVRK_WRIST_JOINTS if j in names), None)
        if joint is None:
            return node.reject('instrument', now, InputRejected(
                f'no wrist pitch joint ({" or ".join(topics.DVRK_WRIST_JOINTS)}) in '
                f'{self.names.instrument_js}: {names}'))
        try:
            (wrist,), = read_joints(msg, (joint,), ('position',), others=True).values()
        except InputRejected as exc:
            return node.reject('instrument', now, exc)
        self.wrist, self.wrist_time, self.wrist_joint = wrist, now, joint

    def _on_jaw(self, msg: JointState) -> None:
        """Feed the jaw to the instrument (with the wrist) and actuator (current) inputs; step."""
        node = self.node
        now = node.now()
        fields = ('position', 'effort', 'velocity') if len(msg.velocity) else ('position', 'effort')
        try:
            (jaw,) = read_joints(msg, _JAW_JOINTS, fields).values()
        except InputRejected as exc:
            node.reject('actuator', now, exc)
            node.reject('instrument', now, exc)
            node.on_state(None)
            return
        stamp = stamp_seconds(msg.header.stamp)
        inputs = node.inputs
        jaw_velocity = jaw[2] if len(jaw) > 2 else 0.0
        age = now - self.wrist_time
        if age <= inputs_timeout(node):
            node.report(inputs.set_instrument(now, self.wrist, jaw[0], jaw_velocity, stamp))
        else:
            why = ('no wrist yet' if age != age else f'stale wrist: {age * 1e3:.1f} ms old')
            node.reject('instrument', now, InputRejected(f'{why} ({self.names.instrument_js})'))
        # the dVRK's effort is computed from the measured motor currents: invert its conversion
        node.report(inputs.set_actuator(now, self.conversion.current(jaw[1]) - self.current_offset,
                                        stamp=stamp))
        fresh = inputs.actuator_time == now and stamp != 0.0
        node.on_state(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                      if fresh else None)

    def _on_operating_state(self, msg) -> None:
        stamp = stamp_seconds(msg.header.stamp)
        if stamp and stamp < self.state_stamp:
            return                      # an older state (a service reply overtaken by a topic)
        previous = (self.state, self.is_homed, self.is_busy)
        self.state, self.is_homed, self.is_busy = msg.state, bool(msg.is_homed), bool(msg.is_busy)
        self.state_stamp = stamp if stamp else self.state_stamp
        if (self.state, self.is_homed, self.is_busy) != previous:
            self.node.get_logger().info(
                f'arm {self.arm}: {self.state}, {"homed" if self.is_homed else "not homed"}'
                f'{", busy" if self.is_busy else ""}')
        if self.requested and self.interlock() is None:
            self.requested = False
            self.node.get_logger().info(f'arm {self.arm} is enabled and homed')

    # ------------------------------------------------------------------ the arm
    def request_enable(self) -> None:
        """Ask the arm to enable and home (sent when the arm's state_command is subscribed)."""
        self.requested = True
        self._last_request = -math.inf
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
        try:
            self._on_operating_state(future.result().operating_state)
        except Exception as exc:  # noqa: BLE001 - a failed call: poll again later
            self.node.get_logger().warning(f'operating_state service of {self.arm} failed: {exc}',
                                           throttle_duration_sec=5.0)

    def _send(self, command: str) -> None:
        msg = self.msgs.StringStamped()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.string = command
        self._command_pub.publish(msg)
        self._last_request = time.perf_counter()
        self.node.get_logger().info(f'asked arm {self.arm} to {command} ({self.names.state_command})')

    def interlock(self) -> str | None:
        """Return why the arm may not be driven: not ENABLED, not homed, busy, or unknown."""
        return arm_interlock(self.arm, self.state, self.is_homed, self.is_busy)

    # ------------------------------------------------------------------ outputs
    def publish_command(self, out, stamp_ns: int) -> None:
        """Send the jaw effort (N*m) on ``<arm>/jaw/servo_jf`` while the arm is ready."""
        if self.interlock() is not None:
            self.withheld += 1          # a disabled arm gets nothing (servo_jf takes over the jaw)
            return
        effort = self.conversion.effort(out.current_command)
        limit = self.effort_limit       # the current limit already keeps it inside; rounding
        servo = self._servo_msg
        servo.header.stamp.sec, servo.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        servo.effort[0] = limit if effort > limit else (-limit if effort < -limit else effort)
        self._servo_pub.publish(servo)

    def status(self) -> dict[str, str]:
        """Key/value strings of the dvrk profile for /diagnostics."""
        return {'interface': self.interface, 'arm': self.arm,
                'arm_state': self.state or 'unknown', 'arm_homed': str(self.is_homed).lower(),
                'arm_busy': str(self.is_busy).lower(),
                'wrist_joint': self.wrist_joint or 'none yet',
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


def inputs_timeout(node) -> float:
    """Return the node controller's watchdog timeout (s): the wrist's freshness bound too."""
    return node.controller.watchdog_timeout


def controller_io(node, params) -> ControllerIO:
    """Make the I/O object of the node's ``interface`` profile."""
    names = topics.topic_set(params.interface, params.arm, params.master)
    if params.interface == 'dvrk':
        return DvrkControllerIO(node, params, names)
    return CrtkControllerIO(node, params, names)
