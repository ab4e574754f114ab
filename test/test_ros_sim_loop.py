"""The sim node's side of the loop: publish order and the round trip it measures.

The node is built on a real rclpy context and driven by calling its callbacks,
with its publishers replaced by recorders, so the order is exact.
"""
from __future__ import annotations

import struct

import pytest
from rclpy.serialization import serialize_message

from grip_force_ros import topics
from grip_force_ros.nodes.common import joint_state
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode
from grip_force_ros.nodes.wire import JointStateData, read_wrench

pytestmark = pytest.mark.ros


class _Recorder:
    def __init__(self, name, log):
        self.name, self.log = name, log

    def publish(self, data):
        """Note the name and the header stamp (ns) of the serialized message."""
        decoded = read_wrench(data) if self.name == 'force' else JointStateData(data)
        sec, nanosec = struct.unpack_from('<iI', data, 4)       # the CDR header's stamp
        assert decoded is not None
        self.log.append((self.name, sec * 1_000_000_000 + nanosec))


@pytest.fixture(params=['split', 'combined'])
def sim(request):
    ros = RosRunner()
    node = ros.add(SimInstrumentNode, state_message=request.param)
    node._timer.cancel()                       # the test ticks it
    log: list = []
    node.io._actuator_pub = _Recorder('actuator', log)
    node.io._joint_pub = _Recorder('joint', log)
    node.io._force_pub = _Recorder('force', log)
    try:
        yield node, log
    finally:
        ros.stop()


def _answer(node, stamp_ns, current=0.1):
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    stamp = node.get_clock().now().to_msg()
    stamp.sec, stamp.nanosec = sec, nanosec
    read = node.io.command_readers()[0][3]                 # the crtk profile's one command topic
    node._on_command(read, serialize_message(joint_state(stamp, [topics.DRUM_JOINT], effort=[current])))


def test_sensors_first_the_step_finds_the_same_sample(sim):
    """The load cell (and the joints, split) of a sample before the state the controller steps on."""
    node, log = sim
    order = ['joint', 'force', 'actuator'] if not node.io.combined else ['force', 'joint']
    node._last -= 1e-3
    node._tick()
    assert [name for name, _ in log] == order
    assert len({s for _, s in log}) == 1, 'one measurement time on all of them'
    n = len(log)
    _answer(node, log[0][1])
    assert len(log) == n, 'nothing left to send once answered'
    assert node.current_command == pytest.approx(0.1)
    summary = node.loop.summary()
    assert summary['answered'] == 1 and summary['round_trips'] == 1
    assert 0.0 <= summary['max_ms'] < 1000.0
    node._last -= 1e-3
    node._tick()                                  # the next step: the same order, a newer stamp
    assert [name for name, _ in log[n:]] == order and log[n][1] > log[0][1]
