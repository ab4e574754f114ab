"""The master node over DDS: publishes its trajectory at its rate, replays, exits when done."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.nodes.master import EXIT_GRACE, MasterNode

pytestmark = pytest.mark.ros

DOCS = Path(__file__).resolve().parents[1] / 'docs' / 'ros_interface.md'


def _collect(ros, received):
    probe = ros.plain_node('master_probe')
    probe.create_subscription(
        JointState, topics.MASTER_JS,
        lambda m: received.append((time.monotonic(), list(m.name), m.position[0],
                                   m.velocity[0])), 50)


def test_needle_grasp_is_published_and_the_node_finishes():
    received = []
    with RosRunner() as ros:
        _collect(ros, received)
        master = ros.add(MasterNode, time_scale=0.4, exit_when_done=True, master_rate=200.0)
        ros.start()
        duration = master.trajectory.duration
        assert ros.wait_for(master.finished.done, duration + EXIT_GRACE + 10.0)
    t = np.array([r[0] for r in received])
    angle = np.array([r[2] for r in received])
    assert all(r[1] == [topics.MASTER_JOINT] for r in received)
    assert angle.max() == pytest.approx(0.8) and angle.min() == pytest.approx(0.0, abs=1e-9)
    # opens, closes, holds closed, opens again
    closed = np.flatnonzero(angle < 1e-6)
    assert closed.size and angle[: closed[0]].max() == pytest.approx(0.8)
    assert angle[closed[-1]:].max() == pytest.approx(0.8)
    rate = (len(t) - 1) / (t[-1] - t[0])
    assert rate == pytest.approx(200.0, rel=0.25)
    # velocity is the trajectory's: negative while closing
    velocity = np.array([r[3] for r in received])
    assert velocity.min() < -0.5 and velocity.max() > 0.5


def test_csv_replay_and_a_runtime_trajectory_change(tmp_path):
    csv = tmp_path / 'm.csv'
    csv.write_text('t,master_angle\n0,0.33\n0.1,0.33\n')
    received = []
    with RosRunner() as ros:
        _collect(ros, received)
        master = ros.add(MasterNode, trajectory='csv', trajectory_file=str(csv))
        ros.start()
        assert ros.wait_for(lambda: len(received) > 5, 10.0)
        assert received[-1][2] == pytest.approx(0.33)
        # a missing file is refused at runtime, and the replay goes on
        res = master.set_parameters([Parameter('trajectory_file', value=str(tmp_path / 'x'))])[0]
        assert not res.successful and 'cannot read' in res.reason
        res = master.set_parameters([Parameter('trajectory', value='steps')])[0]
        assert res.successful
        n = len(received)
        assert ros.wait_for(lambda: len(received) > n + 5 and received[-1][2] == pytest.approx(0.8),
                            5.0)


def test_docs_list_every_node_parameter():
    from grip_force_ros.params import specs_in
    from grip_force_ros.trajectories import MASTER_SPECS
    text = DOCS.read_text()
    missing = [s.name for s in list(specs_in()) + MASTER_SPECS if f'`{s.name}`' not in text]
    assert not missing, f'docs/ros_interface.md lacks {missing}: python -m grip_force_ros.nodes.docs'
    for topic in topics.RECORDED:
        assert f'`{topic}`' in text


def test_trajectory_clock_waits_for_a_subscriber():
    # DDS discovery can take seconds on a loaded machine: the task must not run unseen
    with RosRunner() as ros:
        master = ros.add(MasterNode, time_scale=0.4)
        ros.start()
        time.sleep(0.5)
        assert master.elapsed() == 0.0 and not master._started
        received = []
        _collect(ros, received)
        assert ros.wait_for(lambda: len(received) > 5, 10.0)
        assert master._started and master.elapsed() > 0.0
        # it started when the subscriber matched, not at node start: the probe saw the open angle
        assert received[0][2] == pytest.approx(0.8)


def test_start_when_subscribed_false_runs_from_node_start():
    with RosRunner() as ros:
        master = ros.add(MasterNode, time_scale=0.4, start_when_subscribed=False)
        ros.start()
        # the clock starts at the master's first tick (a starved spin thread ticks late)
        assert ros.wait_for(lambda: master._started, 10.0)
        assert ros.wait_for(lambda: master.elapsed() >= 0.2, 10.0)
