"""The sim node's side of the loop: publish order and the round trip it measures.

The node is built on a real rclpy context and driven by calling its callbacks,
with its publishers replaced by recorders, so the order is exact.
"""
from __future__ import annotations

import pytest

from grip_force_ros import topics
from grip_force_ros.nodes.common import joint_state, stamp_nanoseconds
from grip_force_ros.nodes.harness import RosRunner
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode

pytestmark = pytest.mark.ros


class _Recorder:
    def __init__(self, name, log):
        self.name, self.log = name, log

    def publish(self, msg):
        self.log.append((self.name, stamp_nanoseconds(msg.header.stamp)))


@pytest.fixture
def sim():
    ros = RosRunner()
    node = ros.add(SimInstrumentNode)
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
    node.io._on_command(joint_state(stamp, [topics.DRUM_JOINT], effort=[current]))


def test_actuator_state_first_the_rest_once_answered(sim):
    node, log = sim
    node.io.defer_sensors = True
    node._last -= 1e-3
    node._tick()
    assert [name for name, _ in log] == ['actuator'], 'only the loop-closing state at once'
    stamp = log[0][1]
    _answer(node, stamp)
    assert [name for name, _ in log] == ['actuator', 'joint', 'force']
    assert {s for _, s in log} == {stamp}, 'one measurement time on all three'
    assert node.current_command == pytest.approx(0.1)
    summary = node.loop.summary()
    assert summary['answered'] == 1 and summary['round_trips'] == 1
    assert 0.0 <= summary['max_ms'] < 1000.0


def test_unanswered_state_sends_its_sensors_before_the_next_step(sim):
    node, log = sim
    node.io.defer_sensors = True
    node._last -= 1e-3
    node._tick()
    first = log[0][1]
    node._last -= 1e-3
    node._tick()                                  # no command came
    names = [name for name, _ in log]
    assert names == ['actuator', 'joint', 'force', 'actuator']
    assert log[1][1] == log[2][1] == first        # the previous step's sensors, its stamp
    assert log[3][1] > first
    _answer(node, first)                          # a late answer to the first state
    assert log[4:] == [('joint', log[3][1]), ('force', log[3][1])], 'the second step\'s, once'
    _answer(node, first)                          # the same answer again: nothing more to send
    assert len(log) == 6
    summary = node.loop.summary()
    assert summary['answered'] == 1 and summary['other_commands'] == 1


def test_sensors_first_the_step_finds_the_same_sample(sim):
    """The plain order: joint state and load cell of a sample before its actuator state, all at once."""
    node, log = sim
    node.io.defer_sensors = False
    node._last -= 1e-3
    node._tick()
    assert [name for name, _ in log] == ['joint', 'force', 'actuator']
    assert len({s for _, s in log}) == 1, 'one measurement time on all three'
    _answer(node, log[0][1])
    assert len(log) == 3, 'nothing left to send once answered'
    node._last -= 1e-3
    node._tick()                                  # the next step: the same order, a newer stamp
    assert [name for name, _ in log[3:]] == ['joint', 'force', 'actuator'] and log[3][1] > log[0][1]
