"""Step scheduling of the controller node: a step per actuator state, the timer as fallback.

The node is built on a real rclpy context but not spun: the test calls the
actuator-state callback and the timer callback itself, on a fake perf_counter,
so every arrival time is exact and the figures do not depend on the machine.
"""
from __future__ import annotations

import bisect
import math
import random
import time
import types

import pytest

from grip_force_ros import topics
from grip_force_ros.nodes import controller as controller_module
from grip_force_ros.nodes.common import joint_state
from grip_force_ros.nodes.controller import (FALLBACK_AFTER_PERIODS, MIN_STEP_SPACING_PERIODS,
                                             ControllerNode)
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.nodes.wire import JointStateData
from rclpy.serialization import serialize_message

pytestmark = pytest.mark.ros


class _Clock:
    """Stands in for the ``time`` module of the node: perf_counter is set by the test."""

    def __init__(self):
        self.now = 100.0     # s

    def perf_counter(self) -> float:
        return self.now


@pytest.fixture
def node(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(controller_module, 'time',
                        types.SimpleNamespace(perf_counter=clock.perf_counter))
    ros = RosRunner()
    ctl = ros.add(ControllerNode)
    step_times: list[float] = []
    update = ctl._update

    def recorded_update(now_ns, answered_ns, started):
        step_times.append(clock.now)
        update(now_ns, answered_ns, started)

    ctl._update = recorded_update
    try:
        yield ctl, clock, step_times
    finally:
        ros.stop()


def _state(ctl) -> None:
    """One actuator state (drum current, position, velocity) delivered to the node."""
    stamp = ctl.get_clock().now().to_msg()
    ctl._on_state(ctl.io.read_actuator, serialize_message(
        joint_state(stamp, [topics.DRUM_JOINT], [0.1], [0.0], [0.05])))


def _run(ctl, clock, events) -> list[float]:
    """Deliver ('state' | 'tick', time s) events in time order; the timer's steps (s)."""
    timer_steps = []
    for kind, t in sorted(events, key=lambda e: e[1]):
        clock.now = t
        if kind == 'state':
            _state(ctl)
        else:
            before = ctl.steps['on_timer']
            ctl._tick()
            if ctl.steps['on_timer'] > before:
                timer_steps.append(t)
    return timer_steps


def test_each_state_is_answered_at_once_and_the_timer_stays_quiet(node):
    ctl, clock, steps = node
    period = ctl._period
    start = clock.now
    states = [('state', start + k * period) for k in range(200)]
    ticks = [('tick', start + (k + 0.3) * period) for k in range(200)]   # timer phase 0.3
    _run(ctl, clock, states + ticks)
    assert steps == [t for _, t in states], 'one step per state, at its arrival'
    assert ctl.steps == {'on_state': 200, 'on_timer': 0, 'deferred_after_stall': 0}
    assert ctl.last_output is not None
    assert ctl.timing['late'] == 0


def test_timer_steps_every_period_once_the_states_stop(node):
    ctl, clock, steps = node
    period = ctl._period
    start = clock.now
    _run(ctl, clock, [('state', start + k * period) for k in range(10)]
         + [('tick', start + (k + 0.6) * period) for k in range(60)])
    last_state = start + 9 * period
    timer_steps = [t for t in steps if t > last_state]
    # the first fallback step comes within two periods of the last state, then every period
    assert timer_steps[0] - last_state <= 2 * period + 1e-12
    assert len(timer_steps) == 60 - 10
    assert max(b - a for a, b in zip(timer_steps, timer_steps[1:])) == pytest.approx(period)
    assert ctl.steps['on_timer'] == len(timer_steps)


def test_every_state_is_stepped_on_and_the_timer_keeps_half_a_period_away(node):
    ctl, clock, steps = node
    period = ctl._period
    t0 = clock.now
    # a late state right before the next one: both are answered at once, the timer is quiet
    _run(ctl, clock, [('state', t0), ('state', t0 + 0.2 * period), ('tick', t0 + 0.7 * period)])
    assert steps == [t0, t0 + 0.2 * period]
    # states stop: a late tick steps, the on-time tick 0.1 period after it does not
    _run(ctl, clock, [('tick', t0 + 1.9 * period), ('tick', t0 + 2.0 * period),
                      ('tick', t0 + 3.0 * period)])
    assert steps[2:] == [t0 + 1.9 * period, t0 + 3.0 * period]
    assert ctl.steps == {'on_state': 2, 'on_timer': 2, 'deferred_after_stall': 0}


def test_a_stall_of_this_process_is_not_taken_for_a_lost_input(node):
    """The process is not scheduled for 40 ms (longer than the 30 ms watchdog): when it runs
    again, the timer tick that comes first does not step on the old inputs; the state that
    came in meanwhile is stepped on. When no state comes, the tick a period later steps
    (and the watchdog acts)."""
    ctl, clock, steps = node
    period = ctl._period
    t0 = clock.now
    deliver = [('state', t0 + k * period) for k in range(50)] + \
        [('tick', t0 + (k + 0.5) * period) for k in range(50)]
    _run(ctl, clock, deliver)
    stall_end = t0 + 90 * period                                   # 40 periods later
    _run(ctl, clock, [('tick', stall_end), ('state', stall_end + 0.01 * period)])
    assert ctl.steps['deferred_after_stall'] == 1
    assert stall_end not in steps and steps[-1] == stall_end + 0.01 * period   # the state's
    # a stall and no state at all: the next regular tick steps
    later = stall_end + 50 * period
    _run(ctl, clock, [('tick', later), ('tick', later + period)])
    assert ctl.steps['deferred_after_stall'] == 2
    assert steps[-1] == later + period


def test_a_stopped_loop_does_not_step(node):
    ctl, clock, steps = node
    ctl._running = False
    _state(ctl)
    assert steps == [] and ctl.last_output is None
    assert ctl.inputs.measured_current == pytest.approx(0.05), 'the state is still read'


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_steps_keep_their_spacing_under_jitter(node, seed):
    """States with delivery jitter up to 0.8 period and 2 % lost, any timer phase: each state
    is stepped on; the timer steps exactly at the ticks that come FALLBACK_AFTER_PERIODS or
    more after the last state (and half a period after the last step), so a late state
    costs no extra step and no more than 2.5 periods pass without a command."""
    ctl, clock, steps = node
    rng = random.Random(seed)
    period = ctl._period
    start = clock.now
    n = 2000
    phase = rng.random()
    states = [('state', start + (k + rng.uniform(0.0, 0.8)) * period)
              for k in range(n) if rng.random() > 0.02]
    ticks = [('tick', start + (k + phase) * period) for k in range(n)]
    timer_steps = _run(ctl, clock, states + ticks)
    assert ctl.steps == {'on_state': len(states), 'on_timer': len(timer_steps),
                         'deferred_after_stall': 0}
    assert len(steps) == len(states) + len(timer_steps)
    state_times = sorted(t for _, t in states)
    previous_step = {b: a for a, b in zip(steps, steps[1:])}
    fallback_after = FALLBACK_AFTER_PERIODS * period - 1e-12
    min_spacing = MIN_STEP_SPACING_PERIODS * period - 1e-12
    expected = []
    for _, t in ticks:                                         # the rule, tick by tick
        i = bisect.bisect_right(state_times, t) - 1
        last_state = state_times[i] if i >= 0 else -math.inf
        last_step = max([last_state] + [s for s in expected if s < t][-1:])
        if t - last_state >= fallback_after and t - last_step >= min_spacing:
            expected.append(t)
    assert timer_steps == expected
    assert all(t - previous_step.get(t, -math.inf) >= min_spacing for t in timer_steps)
    lost = n - len(states)
    assert len(timer_steps) <= 2 * lost + 5, 'fallback steps come from lost states, not jitter'
    gaps = [b - a for a, b in zip(steps, steps[1:])]
    assert max(gaps) <= (FALLBACK_AFTER_PERIODS + 1.0) * period + 1e-12


class _Recorder:
    """Stands in for a publisher: notes its name in ``log`` and keeps the last message."""

    def __init__(self, name, log):
        self.name, self.log, self.last = name, log, None

    def publish(self, msg):
        self.log.append(self.name)
        self.last = msg


def _record_outputs(ctl, log) -> None:
    ctl._command_pub, ctl._estimate_pub, ctl._band_pub, ctl._target_pub = (
        _Recorder('command', log), _Recorder('estimate', log), _Recorder('band', log),
        _Recorder('target', log))


def test_outputs_carry_the_stamp_of_the_state_they_answer(node):
    """A fresh, stamped actuator state's stamp goes on the current command; timer steps,
    duplicated and unstamped states get the controller's clock, the force outputs always."""
    ctl, clock, steps = node
    period = ctl._period
    _record_outputs(ctl, [])

    def command_stamp():
        sent = JointStateData(ctl._command_pub.last)
        return sent.sec, sent.nanosec

    def deliver(stamp):
        ctl._on_state(ctl.io.read_actuator, serialize_message(
            joint_state(stamp, [topics.DRUM_JOINT], [0.1], [0.0], [0.05])))
        return command_stamp(), ctl.io.estimate_msg.header.stamp

    stamp = ctl.get_clock().now().to_msg()
    stamp.nanosec = (stamp.nanosec // 1000) * 1000 + 123          # recognisable
    servo, estimate = deliver(stamp)
    assert servo == (stamp.sec, stamp.nanosec)
    assert (estimate.sec, estimate.nanosec) != (stamp.sec, stamp.nanosec)
    clock.now += 0.5 * period
    servo, _ = deliver(stamp)                                       # duplicate: no news
    assert servo != (stamp.sec, stamp.nanosec)
    clock.now += 2 * period
    ctl._tick()                                                     # fallback step
    assert ctl.steps['on_timer'] == 1
    assert command_stamp() != (stamp.sec, stamp.nanosec)
    zero = type(stamp)()                                            # unstamped driver
    servo, _ = deliver(zero)
    assert servo[0] > 0


def test_command_every_step_forces_at_their_own_rate(node):
    """The current command goes out in every step; the estimated force, its band and the
    target force at force_output_rate (100 Hz: the first step, then not before 10 ms minus
    half a period)."""
    ctl, clock, steps = node
    log = []
    _record_outputs(ctl, log)
    assert ctl.params.force_output_rate == 100.0
    _state(ctl)
    assert log == ['command', 'estimate', 'band', 'target']
    for _ in range(4):
        clock.now += ctl._period
        _state(ctl)
    assert log[4:] == ['command'] * 4, 'the forces wait for their period'
    time.sleep(0.0105)                                              # the node's ROS clock
    clock.now += ctl._period
    _state(ctl)
    assert log[8:] == ['command', 'estimate', 'band', 'target']
    # the one sent is the step's own output, stamped with the controller's clock at it
    est = ctl._estimate_pub.last
    assert est.wrench.force.z == ctl.last_output.estimated_force
    band = ctl._band_pub.last.wrench.force        # paper instrument: no band, the estimate
    assert (band.x, band.y, band.z) == (ctl.last_output.estimated_force,) * 3
    assert est.header.stamp.sec > 0


def test_a_state_reaches_the_publisher_within_four_frames(node):
    """One read-compute-write path: subscription callback -> _update -> Publisher.publish."""
    import sys
    ctl, clock, steps = node
    depths = []

    class _Counting:
        def publish(self, msg):
            frame, names = sys._getframe(), []
            while frame is not None and frame.f_code.co_name != '_on_state':
                names.append(frame.f_code.co_name)
                frame = frame.f_back
            depths.append(names + ['_on_state'])

    ctl._update = type(ctl)._update.__get__(ctl)          # the shipped step, not the recorder
    ctl._command_pub = _Counting()
    _state(ctl)
    # _on_state, _update, publish: the stand-in publisher's own frame is Publisher.publish's
    assert depths == [['publish', '_update', '_on_state']]
