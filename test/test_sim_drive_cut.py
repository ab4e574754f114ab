"""The simulated drive tells a cut of a held current from a cut at 0 A.

A calibration staircase whose drive cut a held current (a starved node, no command for
30 ms) gives a friction fit that is off (e.g. the long-jaw grasper's mu at 0.1149 where
its other runs give 0.1189-0.1194, a calibrated spread of 0.049 > 0.03). The sim counts
such cuts on /diagnostics (``drive_cuts_under_current``) and the instrument comparison
redoes a calibration run that has one.
"""
from __future__ import annotations

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.lab.demo.analysis import SIM_STATUS, drive_cuts_under_current
from grip_force_ros.nodes.common import STATE_PUB_QOS, joint_state
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode


def _status(cuts: int, name: str = SIM_STATUS) -> dict:
    return {'name': name, 'level': 1, 'message': '',
            'values': {'drive_timeouts': str(cuts + 2), 'drive_cuts_under_current': str(cuts)}}


def test_cuts_are_counted_up_to_the_end_of_the_task():
    diagnostics = [(1.0, [_status(0)]), (2.0, [_status(0), _status(5, 'controller')]),
                   (2.5, [_status(1)]), (3.0, [_status(1)]), (9.0, [_status(2)])]
    assert drive_cuts_under_current(diagnostics, until=0.5) == 0
    assert drive_cuts_under_current(diagnostics, until=2.4) == 0      # another node's key
    assert drive_cuts_under_current(diagnostics, until=2.5) == 1
    assert drive_cuts_under_current(diagnostics, until=8.0) == 1      # the stop's cut: after
    assert drive_cuts_under_current(diagnostics, until=float('inf')) == 2
    assert drive_cuts_under_current([(1.0, [{'name': SIM_STATUS, 'values': {}}])], 2.0) == 0


@pytest.fixture
def sim():
    ros = RosRunner()
    node = ros.add(SimInstrumentNode, sim_object='free')
    probe = ros.plain_node('drive_cut_probe')
    pub = probe.create_publisher(JointState, topics.SERVO_CURRENT, STATE_PUB_QOS)
    reported: list[dict] = []

    def keep(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == SIM_STATUS:
                reported.append({kv.key: kv.value for kv in status.values})

    probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, keep, 50)
    ros.start()
    yield ros, node, probe, pub, reported
    ros.stop()


def _hold_then_go_silent(ros, node, probe, pub, current: float) -> None:
    """Command ``current`` until the sim holds it, then stop sending (its drive times out).

    On a loaded machine the drive can also time out between two of these commands (each
    such cut is of ``current`` too); what the tests count is therefore per cut.
    """
    msg = joint_state(probe.get_clock().now().to_msg(), ['jaw_drum'], effort=[current])
    took = False
    for _ in range(500):                         # discovery first: up to 10 s
        pub.publish(msg)
        took = ros.wait_for(lambda: node.drive.armed and node.current_command == current, 0.02)
        if took:
            break
    # what the wait saw: reading the command again could find the drive's 30 ms cut already
    assert took, 'the sim never took the command'
    # the drive disarms a moment before the node cuts and counts (another thread): wait for
    # the cut itself (a fresh CI run read the current between the two)
    assert ros.wait_for(lambda: not node.drive.armed and node.current_command == 0.0
                        and node.live_cuts == (node.drive.expiries if current else 0), 10.0), \
        'the drive did not time out'


@pytest.mark.ros
def test_a_cut_of_a_held_current_is_counted_and_reported(sim):
    ros, node, probe, pub, reported = sim
    _hold_then_go_silent(ros, node, probe, pub, 0.05)
    assert node.current_command == 0.0
    assert node.live_cuts == node.drive.expiries >= 1     # every cut was of 0.05 A
    want = str(node.live_cuts)
    assert ros.wait_for(lambda: any(r.get('drive_cuts_under_current') == want for r in reported),
                        10.0), reported[-1:]


@pytest.mark.ros
def test_a_cut_at_zero_current_is_not_counted(sim):
    ros, node, probe, pub, reported = sim
    _hold_then_go_silent(ros, node, probe, pub, 0.0)
    assert node.drive.expiries >= 1 and node.live_cuts == 0
    assert ros.wait_for(lambda: any(int(r.get('drive_timeouts', 0)) >= 1 for r in reported), 10.0)
    assert all(r.get('drive_cuts_under_current') == '0' for r in reported)
