"""Malformed messages reach the real controller and sim nodes over DDS.

Each bad message must be rejected with its reason (on /diagnostics) while the
last good input is kept.
"""
from __future__ import annotations

import math
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.nodes.common import STATE_PUB_QOS, InputRejected, joint_state, read_joints
from grip_force_ros.nodes.controller import ControllerNode
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode

pytestmark = pytest.mark.ros


# ---------------------------------------------------------------- ROS-free checks
@pytest.mark.parametrize('names,position,velocity,needle', [
    (['wrist_pitch', 'jaw', 'elbow'], [0.0, 0.1, 0.0], [], 'unknown joint'),
    (['jaw'], [0.1], [], 'missing joint'),
    (['jaw', 'jaw'], [0.1, 0.1], [], 'duplicate'),
    (['wrist_pitch', 'jaw'], [0.0], [], 'position has 1 values for 2 joints'),
    (['wrist_pitch', 'jaw'], [0.0, math.nan], [], "position of 'jaw' is nan"),
    (['wrist_pitch', 'jaw'], [0.0, math.inf], [], "position of 'jaw' is inf"),
    (['wrist_pitch', 'jaw'], [0.0, 0.1], [1.0], 'velocity has 1 values'),
])
def test_read_joints_names_the_problem(names, position, velocity, needle):
    msg = joint_state(JointState().header.stamp, names, position, velocity)
    fields = ('position', 'velocity') if velocity else ('position',)
    with pytest.raises(InputRejected, match='.*') as err:
        read_joints(msg, ('wrist_pitch', 'jaw'), fields)
    assert needle in str(err.value)


def test_read_joints_accepts_any_order():
    msg = joint_state(JointState().header.stamp, ['jaw', 'wrist_pitch'], [0.2, -0.1], [1.0, 0.0])
    got = read_joints(msg, ('wrist_pitch', 'jaw'), ('position', 'velocity'))
    assert got == {'jaw': (0.2, 1.0), 'wrist_pitch': (-0.1, 0.0)}


# ---------------------------------------------------------------- over DDS
@pytest.fixture(scope='module')
def loop():
    ros = RosRunner()
    ctl = ros.add(ControllerNode)
    probe = ros.plain_node('fault_injector')
    pubs = {t: probe.create_publisher(JointState, t, STATE_PUB_QOS)
            for t in (topics.MASTER_JS, topics.INSTRUMENT_JS, topics.ACTUATOR_JS,
                      topics.SERVO_CURRENT)}
    diags: list[DiagnosticArray] = []
    probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, diags.append, 50)
    ros.start()
    yield ros, ctl, probe, pubs, diags
    ros.stop()


def _publish_until(ros, pub, msg, predicate, timeout=5.0):
    """Publish ``msg`` every 20 ms until ``predicate()`` (discovery takes a moment)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        pub.publish(msg)
        if ros.wait_for(predicate, 0.02):
            return True
    return False


def test_malformed_inputs_are_rejected_keeping_the_last_good_one(loop):
    ros, ctl, probe, pubs, diags = loop
    now = lambda: probe.get_clock().now().to_msg()   # noqa: E731
    good = joint_state(now(), ['wrist_pitch', 'jaw'], [0.1, 0.3], [0.0, 0.0])
    assert _publish_until(ros, pubs[topics.INSTRUMENT_JS], good,
                          lambda: ctl.inputs.jaw_angle == pytest.approx(0.3))
    cases = [
        (joint_state(now(), ['wrist_pitch', 'jaw', 'elbow'], [0.1, 0.9, 0.0]), 'unknown joint'),
        (joint_state(now(), ['wrist_pitch', 'jaw'], [0.1]), 'position has 1 values'),
        (joint_state(now(), ['wrist_pitch', 'jaw'], [0.1, math.nan]), 'is nan'),
        (joint_state(now(), ['wrist_pitch', 'jaw'], [0.1, 0.2], [0.0]), 'velocity has 1 values'),
        (joint_state(now(), ['wrist_pitch', 'jaw'], [0.1, 3.0]), 'jaw angle'),  # core: out of range
    ]
    for msg, needle in cases:
        assert _publish_until(ros, pubs[topics.INSTRUMENT_JS], msg,
                              lambda: needle in (ctl.inputs.instrument_fault or '')), needle
        assert ctl.inputs.jaw_angle == pytest.approx(0.3), 'the last good input was replaced'
    # the rejection reasons are on /diagnostics
    assert ros.wait_for(lambda: any(
        'unknown joint' in kv.key for d in diags for s in d.status for kv in s.values
        if kv.key.startswith('rejected:')), 3.0)

    def last_status() -> dict:
        status = [s for d in diags for s in d.status if s.name.endswith('controller')]
        return {kv.key: kv.value for kv in status[-1].values} if status else {}

    # /diagnostics comes at its own rate: the newest status received may predate the last
    # rejection; wait for one that counts every case
    ros.wait_for(lambda: int(last_status().get('rejected_inputs', 0)) >= len(cases), 5.0)
    last = last_status()
    assert int(last['rejected_inputs']) >= len(cases), last
    assert 'instrument' in last['input_faults']


def test_master_with_the_wrong_joint_is_rejected(loop):
    ros, ctl, probe, pubs, diags = loop
    msg = joint_state(probe.get_clock().now().to_msg(), ['jaw'], [0.5])
    assert _publish_until(ros, pubs[topics.MASTER_JS], msg,
                          lambda: 'unknown joint' in (ctl.inputs.master_fault or ''))
    # without all inputs the controller is in the safe state and commands no current
    assert ctl.last_output.mode == 'safe' and ctl.last_output.current_command == 0.0


def test_sim_holds_its_last_good_command(loop):
    ros, ctl, probe, pubs, diags = loop
    # the drive's 30 ms command timeout would cut the held command while the bad ones are
    # published on a loaded machine: this test is about rejection, so the timeout is long
    sim = ros.add(SimInstrumentNode, sim_object='free', command_timeout=10.0)
    pub = pubs[topics.SERVO_CURRENT]
    stamp = probe.get_clock().now().to_msg()
    # the controller node in this process also publishes servo_jf (0 A, safe): silence it
    ctl._running = False                       # the loop stops: no step, no command
    try:
        assert _publish_until(ros, pub, joint_state(stamp, ['jaw_drum'], effort=[0.05]),
                              lambda: sim.current_command == pytest.approx(0.05))
        for bad in (joint_state(stamp, ['jaw_drum'], effort=[math.nan]),
                    joint_state(stamp, ['motor'], effort=[0.4]),
                    joint_state(stamp, ['jaw_drum'], effort=[])):
            before = sim.rejected
            assert _publish_until(ros, pub, bad, lambda: sim.rejected > before)
            assert sim.current_command == pytest.approx(0.05)
    finally:
        ctl._running = True


def test_diagnostic_names_carry_the_namespace():
    """At the root 'grip_force_ros: controller'; in /PSM1 'grip_force_ros: /PSM1/controller'."""
    assert topics.diagnostic_name('/', 'controller') == 'grip_force_ros: controller'
    assert topics.diagnostic_name('', 'sim_instrument') == 'grip_force_ros: sim_instrument'
    assert topics.diagnostic_name('/PSM1', 'controller') == 'grip_force_ros: /PSM1/controller'
    assert topics.is_status_of('grip_force_ros: /PSM2/sim_instrument', 'sim_instrument')
    assert topics.is_status_of('grip_force_ros: sim_instrument', 'sim_instrument')
    assert not topics.is_status_of('grip_force_ros: /PSM2/controller', 'sim_instrument')
    assert not topics.is_status_of('other: /x/sim_instrument', 'sim_instrument')


def test_two_arms_statuses_on_one_diagnostics_topic_are_told_apart():
    """Controllers and sims of /PSM1 and /PSM2 publish on the one /diagnostics under their own names."""
    import functools
    with RosRunner() as ros:
        for arm in ('PSM1', 'PSM2'):
            ros.add(functools.partial(ControllerNode, namespace=arm))
            ros.add(functools.partial(SimInstrumentNode, namespace=arm))
        probe = ros.plain_node('diagnostics_reader')
        names: set[str] = set()
        probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS,
                                  lambda m: names.update(s.name for s in m.status), 50)
        ros.start()
        want = {f'grip_force_ros: /{arm}/{node}' for arm in ('PSM1', 'PSM2')
                for node in ('controller', 'sim_instrument')}
        assert ros.wait_for(lambda: want <= names, 30.0), sorted(names)
