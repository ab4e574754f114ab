"""The loop's serialized messages (nodes/wire.py) against rclpy's own serializer."""
from __future__ import annotations

import math

import pytest
from geometry_msgs.msg import WrenchStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from grip_force_ros.nodes.common import InputRejected, read_joints
from grip_force_ros.nodes.wire import FIELDS, JointStateData, JointStateWriter, WrenchWriter, read_wrench

ROSBAGS = get_typestore(Stores.ROS2_JAZZY)

_names = st.lists(st.text(st.characters(min_codepoint=97, max_codepoint=122), min_size=1,
                          max_size=13), min_size=0, max_size=7, unique=True)
_value = st.floats(allow_nan=False, width=64)
#: ROS strings are C strings: no NUL inside
_frame = st.text(st.characters(blacklist_characters='\x00', blacklist_categories=('Cs',)), max_size=9)
_stamp = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 999_999_999))


@settings(max_examples=200, deadline=None)
@given(names=_names, frame=_frame, stamp=_stamp, data=st.data())
def test_a_serialized_joint_state_reads_as_rclpy_wrote_it(names, frame, stamp, data):
    fields = data.draw(st.lists(st.sampled_from(FIELDS), unique=True))
    msg = JointState(name=names)
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    for field in fields:
        setattr(msg, field, data.draw(st.lists(_value, min_size=len(names),
                                               max_size=len(names))))
    got = JointStateData(serialize_message(msg))
    assert (got.sec, got.nanosec, got.frame_id, got.name) == (*stamp, frame, names)
    for field in FIELDS:
        assert got.__getattribute__(field) == tuple(getattr(msg, field))
    assert got.stamp == pytest.approx(stamp[0] + stamp[1] * 1e-9)


@settings(max_examples=200, deadline=None)
@given(names=_names.filter(bool), frame=_frame, stamp=_stamp, data=st.data())
def test_the_writer_gives_the_bytes_rclpy_reads_back(names, frame, stamp, data):
    fields = data.draw(st.lists(st.sampled_from(FIELDS), unique=True, min_size=1))
    writer = JointStateWriter(names, fields, frame)
    values = {f: data.draw(st.lists(_value, min_size=len(names), max_size=len(names)))
              for f in writer.fields}
    for _ in range(2):                         # the template is reused: write twice
        msg = deserialize_message(writer.write(*stamp, *values.values()), JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == stamp
    assert msg.header.frame_id == frame and list(msg.name) == names
    for field in FIELDS:
        assert list(getattr(msg, field)) == values.get(field, [])
    # a strict CDR reader (a bag's) takes the bytes too: no trailing room
    bagged = ROSBAGS.deserialize_cdr(writer.write(*stamp, *values.values()),
                                     'sensor_msgs/msg/JointState')
    assert list(bagged.name) == names and bagged.header.stamp.nanosec == stamp[1]


def test_nan_goes_through_and_read_joints_refuses_it_as_for_a_message():
    writer = JointStateWriter(['jaw_drum'], ('position', 'effort'))
    data = JointStateData(writer.write(1, 2, (0.1,), (math.nan,)))
    assert math.isnan(data.effort[0])
    with pytest.raises(InputRejected, match="effort of 'jaw_drum' is nan"):
        read_joints(data, ('jaw_drum',), ('position', 'effort'))
    assert read_joints(data, ('jaw_drum',), ('position',)) == {'jaw_drum': (0.1,)}


@pytest.mark.parametrize('cut', [0, 3, 11, 20, 30, -9])
def test_truncated_bytes_are_rejected_not_raised(cut):
    msg = JointState(name=['wrist_pitch', 'jaw'], position=[0.1, 0.2], velocity=[0.0, 0.3])
    raw = serialize_message(msg)
    with pytest.raises(InputRejected, match='not a serialized JointState'):
        JointStateData(raw[:cut])


def test_a_wrench_reads_and_writes_as_rclpy_does():
    msg = WrenchStamped()
    msg.header.frame_id = 'jaw'
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = 0.5, -1.0, 2.5
    assert read_wrench(serialize_message(msg)) == (pytest.approx(12.000000345), 0.5, -1.0, 2.5)
    data = WrenchWriter('jaw').write(12, 345, (0.5, -1.0, 2.5), (0.0, 0.0, 0.1))
    back = deserialize_message(data, WrenchStamped)
    assert ROSBAGS.deserialize_cdr(data, 'geometry_msgs/msg/WrenchStamped').wrench.force.z == 2.5
    assert back.header.frame_id == 'jaw' and back.wrench.force.z == 2.5
    assert back.wrench.torque.z == 0.1 and back.header.stamp.nanosec == 345
    with pytest.raises(InputRejected, match='not a serialized WrenchStamped'):
        read_wrench(serialize_message(msg)[:20])


def test_unknown_fields_are_refused():
    with pytest.raises(ValueError, match='unknown JointState field'):
        JointStateWriter(['jaw'], ('torque',))
