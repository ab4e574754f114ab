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
    if topic == topics.TARGET_FORCE:
        return {'target_force': float(msg.wrench.force.z)}
    if topic == topics.MEASURED_FORCE:
        return {'measured_force': float(msg.wrench.force.z)}
    raise KeyError(f'no value extractor for topic {topic!r}')


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
