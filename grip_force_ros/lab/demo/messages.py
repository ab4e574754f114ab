"""Message types of the recorded topics, and plain values out of messages.

The extractors are duck-typed: they read the same fields from an rclpy
message (live) and from a message deserialised by ``rosbags`` (a bag), so
the live view, the monitor and the bag analysis share one definition of
"what a message means". No rclpy import here.
"""
from __future__ import annotations

from typing import Any

from grip_force_ros import topics

#: Topic (as in topics.py) -> ROS 2 type name, as written into a bag.
TOPIC_TYPES: dict[str, str] = {
    topics.MASTER_JS: 'sensor_msgs/msg/JointState',
    topics.INSTRUMENT_JS: 'sensor_msgs/msg/JointState',
    topics.ACTUATOR_JS: 'sensor_msgs/msg/JointState',
    topics.SERVO_CURRENT: 'sensor_msgs/msg/JointState',
    topics.ESTIMATED_FORCE: 'geometry_msgs/msg/WrenchStamped',
    topics.ESTIMATE_BAND: 'geometry_msgs/msg/WrenchStamped',
    topics.TARGET_FORCE: 'geometry_msgs/msg/WrenchStamped',
    topics.MEASURED_FORCE: 'geometry_msgs/msg/WrenchStamped',
    topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray',
}

#: Short series names used by the analysis, per topic. Units in the comments.
FIELDS: dict[str, tuple[str, ...]] = {
    topics.MASTER_JS: ('master_angle',),                     # rad, gripper opening
    topics.INSTRUMENT_JS: ('wrist_angle', 'jaw_angle', 'jaw_velocity'),  # rad, rad, rad/s
    topics.ACTUATOR_JS: ('motor_angle', 'motor_velocity', 'current'),    # rad, rad/s, A
    topics.SERVO_CURRENT: ('current_command',),              # A
    topics.ESTIMATED_FORCE: ('estimated_force', 'pull_out_force'),       # N, N
    topics.ESTIMATE_BAND: ('estimate_band_low', 'estimate_band_high'),   # N, N
    topics.TARGET_FORCE: ('target_force',),                  # N
    topics.MEASURED_FORCE: ('measured_force',),              # N (load cell)
}


def absolute(topic: str) -> str:
    """Return the topic name in the root namespace ('/grip/target_force')."""
    return topic if topic.startswith('/') else '/' + topic


def stamp_seconds(msg: Any) -> float:
    """``header.stamp`` in seconds (0.0 when the message has no stamp)."""
    header = getattr(msg, 'header', None)
    if header is None:
        return 0.0
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _joint(msg: Any, name: str, field: str, index: int | None = None) -> float:
    """Value of ``field`` for joint ``name`` (or at ``index`` if names are absent)."""
    names = list(msg.name)
    values = getattr(msg, field)
    if name in names:
        i = names.index(name)
    elif index is not None and not names:
        i = index
    else:
        return float('nan')
    return float(values[i]) if i < len(values) else float('nan')


def values_of(topic: str, msg: Any) -> dict[str, float]:
    """Return the plain values (SI) a message of ``topic`` carries, named as in :data:`FIELDS`."""
    if topic == topics.MASTER_JS:
        names = list(msg.name)
        i = names.index(topics.MASTER_JOINT) if topics.MASTER_JOINT in names else 0
        return {'master_angle': float(msg.position[i]) if len(msg.position) > i else float('nan')}
    if topic == topics.INSTRUMENT_JS:
        return {'wrist_angle': _joint(msg, topics.WRIST_JOINT, 'position', 0),
                'jaw_angle': _joint(msg, topics.JAW_JOINT, 'position', 1),
                'jaw_velocity': _joint(msg, topics.JAW_JOINT, 'velocity', 1)}
    if topic == topics.ACTUATOR_JS:
        return {'motor_angle': _joint(msg, topics.DRUM_JOINT, 'position', 0),
                'motor_velocity': _joint(msg, topics.DRUM_JOINT, 'velocity', 0),
                'current': _joint(msg, topics.DRUM_JOINT, 'effort', 0)}
    if topic == topics.SERVO_CURRENT:
        return {'current_command': _joint(msg, topics.DRUM_JOINT, 'effort', 0)}
    if topic == topics.ESTIMATED_FORCE:
        return {'estimated_force': float(msg.wrench.force.z),
                'pull_out_force': float(msg.wrench.force.x)}
    if topic == topics.ESTIMATE_BAND:
        return {'estimate_band_low': float(msg.wrench.force.x),
                'estimate_band_high': float(msg.wrench.force.y)}
    if topic == topics.TARGET_FORCE:
        return {'target_force': float(msg.wrench.force.z)}
    if topic == topics.MEASURED_FORCE:
        return {'measured_force': float(msg.wrench.force.z)}
    raise KeyError(f'no value extractor for topic {topic!r}')


class RecordedTopics:
    """The recorded topics of one interface profile, their types and what they mean.

    Parameters
    ----------
    names : TopicSet
        The profile's topics (:func:`grip_force_ros.topics.topic_set`).
    conversion : JawEffortConversion, optional
        The dVRK's jaw effort <-> current conversion (``dvrk``: the jaw effort of
        ``jaw/measured_js`` and ``jaw/servo_jf`` becomes the series ``current`` and
        ``current_command``, A, as the controller sees them).

    Notes
    -----
    ``crtk`` is :data:`TOPIC_TYPES`, :data:`FIELDS` and :func:`values_of`. In ``dvrk`` the
    arm's ``measured_js`` gives the wrist and ``jaw/measured_js`` the jaw angle, velocity
    and the current; the arm's ``operating_state`` (crtk_msgs) is not recorded: the
    controller's /diagnostics carry it (``arm_state``), and the bag keeps standard types only.
    """

    def __init__(self, names: topics.TopicSet, conversion=None, combined: bool = False):
        self.names = names
        self.conversion = conversion
        self.combined = combined and names.interface == 'crtk'
        #: the topics that carry the instrument's state (the sim's ``state_message``)
        self.state_topics = ((names.instrument_js,) if self.combined
                             else (names.instrument_js, names.actuator_js))
        if names.interface == 'crtk':
            self.fields = dict(FIELDS)
            self.types = dict(TOPIC_TYPES)
            if self.combined:       # the drum rides in instrument/measured_js
                self.fields[topics.INSTRUMENT_JS] += self.fields.pop(topics.ACTUATOR_JS)
                del self.types[topics.ACTUATOR_JS]
            return
        if conversion is None:
            raise ValueError('the dvrk profile needs the jaw effort conversion')
        js, wrench = 'sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped'
        self.fields = {names.master_js: ('master_angle',),                         # rad
                       names.instrument_js: ('wrist_angle',),                      # rad
                       names.actuator_js: ('jaw_angle', 'jaw_velocity', 'current'),  # rad, rad/s, A
                       names.command: ('current_command',),                        # A
                       names.estimated_force: ('estimated_force', 'pull_out_force'),  # N, N
                       names.estimate_band: ('estimate_band_low', 'estimate_band_high'),  # N, N
                       names.target_force: ('target_force',),                      # N
                       names.measured_force: ('measured_force',)}                  # N
        self.types = {names.master_js: js, names.instrument_js: js, names.actuator_js: js,
                      names.command: js, names.estimated_force: wrench,
                      names.estimate_band: wrench, names.target_force: wrench, names.measured_force: wrench,
                      topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray'}

    def values(self, topic: str, msg: Any) -> dict[str, float]:
        """Return the plain SI numbers a message of ``topic`` carries, named as in ``fields``."""
        n = self.names
        if n.interface == 'crtk':
            if self.combined and topic == topics.INSTRUMENT_JS:
                return {**values_of(topic, msg), **values_of(topics.ACTUATOR_JS, msg)}
            return values_of(topic, msg)
        if topic == n.master_js:
            return values_of(topics.MASTER_JS, msg)
        if topic == n.instrument_js:
            names = list(msg.name)
            joint = next((j for j in topics.DVRK_WRIST_JOINTS if j in names), None)
            return {'wrist_angle': _joint(msg, joint, 'position') if joint else float('nan')}
        if topic == n.actuator_js:
            effort = _joint(msg, topics.JAW_JOINT, 'effort', 0)
            return {'jaw_angle': _joint(msg, topics.JAW_JOINT, 'position', 0),
                    'jaw_velocity': _joint(msg, topics.JAW_JOINT, 'velocity', 0),
                    'current': self.conversion.current(effort)}
        if topic == n.command:
            return {'current_command': self.conversion.current(
                _joint(msg, topics.JAW_JOINT, 'effort', 0))}
        for crtk_topic, own in ((topics.ESTIMATED_FORCE, n.estimated_force),
                                (topics.ESTIMATE_BAND, n.estimate_band),
                                (topics.TARGET_FORCE, n.target_force),
                                (topics.MEASURED_FORCE, n.measured_force)):
            if topic == own:
                return values_of(crtk_topic, msg)
        raise KeyError(f'no value extractor for topic {topic!r}')


def recorded_topics(params) -> RecordedTopics:
    """Return the :class:`RecordedTopics` of an instrument ParamSet's ``interface`` profile."""
    names = topics.topic_set(params.interface, params.arm, params.master)
    conversion = None
    if params.interface == 'dvrk':
        from grip_force_ros.model.dvrk_jaw import JawEffortConversion
        conversion = JawEffortConversion.from_params(params)
    return RecordedTopics(names, conversion, combined=params.state_message == 'combined')


def diagnostic_summary(msg: Any) -> list[dict[str, Any]]:
    """One dict per DiagnosticStatus: name, level (0 OK .. 3 STALE), message, values."""
    out = []
    for status in msg.status:
        level = status.level
        if isinstance(level, (bytes, bytearray)):   # rclpy gives the byte field as bytes
            level = int.from_bytes(level, 'little')
        level = int(level)
        out.append({'name': str(status.name), 'level': level, 'message': str(status.message),
                    'values': {str(kv.key): str(kv.value) for kv in status.values}})
    return out
