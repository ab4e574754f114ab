"""The bench's own rclpy processes: ping and echo, the middleware floor.

Run by :mod:`grip_force_ros.lab.bench.loop`, one process each::

    python -m grip_force_ros.lab.bench.child ping  --seconds 20 [variant options]
    python -m grip_force_ros.lab.bench.child echo  [variant options]

``ping`` plays the sim: a 1 kHz timer publishes the actuator state
(``sensor_msgs/JointState`` on :data:`topics.ACTUATOR_JS`) stamped with the
wall clock (``time.time_ns``, the clock of rclpy's ROS time); ``echo`` plays the
controller at its barest: it answers every state in the subscription callback
with a current command (``JointState`` on :data:`topics.SERVO_CURRENT`) that
carries the state's stamp. With ``--sensors`` both play the topic contract's whole
period: ``ping`` publishes the load cell (``geometry_msgs/WrenchStamped`` on
:data:`topics.MEASURED_FORCE`) and then ONE combined joint state (wrist_pitch, jaw,
jaw_drum on :data:`topics.INSTRUMENT_JS`), as the sim node does by default
(``state_message: combined``), and ``echo`` keeps the load cell's value and answers
the combined state with a command computed from the jaw it carries and the load cell
it holds: two messages out, one back, no model and no control law. The round trip is
the receive time minus that stamp; a period is missed when its state got no answer.
The product is measured the same way by the shipped sim node (:mod:`.product_sim`).

Protocol on stdout (one line each, read by the parent): ``START`` when the
measurement window opens (after discovery and a warm-up), then one JSON line
with the figures, then the process exits.
"""
from __future__ import annotations

import argparse
import gc
import json
import sys
import time

import numpy as np
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState

from grip_force_ros import topics
from grip_force_ros.nodes.common import stamp_nanoseconds, state_qos
from grip_force_ros.nodes.lifetime import close_node, shutdown_once
from grip_force_ros.lab.bench.stats import latency_summary, missed_periods

#: Longest wait for the first answer before giving up (s).
DISCOVERY_TIMEOUT = 20.0


def make_executor(kind: str):
    """'events' (rclpy.experimental.EventsExecutor), 'single' or 'multi' (2 threads)."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    if kind == 'multi':
        return MultiThreadedExecutor(num_threads=2)
    return SingleThreadedExecutor()


class _Window:
    """Discovery, warm-up and measurement window of a measuring process."""

    def __init__(self, node: Node, seconds: float, warmup: float, capacity: int, gc_freeze: bool,
                 open_at_ns: int = 0):
        self.node = node
        # wall clock (ns) before which the window does not open (0: at the warm-up's end):
        # several measuring processes (the arms of a two-arm run) then share one window
        self.open_at_ns = open_at_ns
        self.seconds = seconds
        self.warmup = warmup
        self.gc_freeze = gc_freeze
        self.state = 'discover'
        self.t_state = time.monotonic()
        self.t_created = self.t_state
        self.finished = Future()
        self.capacity = capacity
        self.ticks = np.zeros(capacity, np.int64)      # ns, perf_counter
        self.n_ticks = 0
        self.latencies = np.zeros(capacity, np.int64)  # ns, round trip of each answer
        self.answered = np.zeros(capacity, np.int64)   # ns, stamp of the state it answered
        self.n_latencies = 0
        self.received = 0
        self.sent = 0
        self.opened_ns = None     # wall clock (ns) when the window opened
        self.result: dict = {}

    @property
    def measuring(self) -> bool:
        return self.state == 'measure'

    def counts(self, stamp_ns: int) -> bool:
        """Whether the answer to a state stamped ``stamp_ns`` (wall clock) is in the window."""
        return self.state == 'measure' and stamp_ns >= self.opened_ns

    def saw_answer(self) -> None:
        if self.state == 'discover':
            self.state, self.t_state = 'warm', time.monotonic()

    def record_tick(self, t_ns: int) -> None:
        if self.n_ticks < self.capacity:
            self.ticks[self.n_ticks] = t_ns
            self.n_ticks += 1

    def record_answer(self, stamp_ns: int, round_trip_ns: int) -> None:
        """Record an answer in the window: the stamp of the state it answers and its round trip (ns)."""
        self.received += 1
        if self.n_latencies < self.capacity:
            self.answered[self.n_latencies] = stamp_ns
            self.latencies[self.n_latencies] = round_trip_ns
            self.n_latencies += 1

    def answer_summary(self, period: float) -> dict:
        """Round trips, missed periods (states without an answer) and the timer's own gaps."""
        answered = self.answered[:self.n_latencies]
        round_trips = self.latencies[:self.n_latencies]
        worst = np.argsort(round_trips)[-5:][::-1]
        t0 = answered.min() if answered.size else 0
        return {'latency': latency_summary(round_trips),
                # a period is missed when no answer to a state of it came back, whether
                # the publisher's timer or the answering side skipped it
                'periods': missed_periods(np.sort(answered), period),
                'timer_periods': missed_periods(self.ticks[:self.n_ticks], period),
                # the five longest round trips: (s into the window, ms)
                'worst': [(float((answered[i] - t0) * 1e-9), float(round_trips[i] * 1e-6))
                          for i in worst],
                # when the window opened (wall clock, ns): the windows of several arms compared
                'opened_ns': int(self.opened_ns or 0)}

    def advance(self, summary) -> None:
        """Move through the states; call it from a periodic callback."""
        now = time.monotonic()
        if self.state == 'discover' and now - self.t_created > DISCOVERY_TIMEOUT:
            self.result = {'error': f'no answer within {DISCOVERY_TIMEOUT:.0f} s (discovery failed?)'}
            self._finish()
        elif (self.state == 'warm' and now - self.t_state >= self.warmup
              and time.time_ns() >= self.open_at_ns):
            if self.gc_freeze:
                gc.collect()
                gc.freeze()
            self.state, self.t_state = 'measure', now
            # only states published from now on count (an answer to an earlier one may
            # have waited for the collection above)
            self.opened_ns = time.time_ns()
            print('START', flush=True)
        elif self.state == 'measure' and now - self.t_state >= self.seconds:
            self.state = 'done'
            self.result = summary()
            self._finish()

    def _finish(self) -> None:
        print(json.dumps(self.result), flush=True)
        if not self.finished.done():
            self.finished.set_result(True)


class Ping(Node):
    """The sim's side of the floor: 1 kHz stamped state out, command back.

    The floor sends the actuator state alone; the contract floor (``--sensors``) the load
    cell, then the combined joint state (wrist_pitch, jaw, jaw_drum) that the echo answers.
    """

    def __init__(self, opts):
        super().__init__('bench_ping')
        self.period = opts.period
        self.prealloc = opts.prealloc
        capacity = int((opts.seconds + 5.0) / opts.period) + 1000
        self.window = _Window(self, opts.seconds, opts.warmup, capacity, opts.gc_freeze)
        group = _callback_group(opts.callback_groups)
        sub_group = _callback_group(opts.callback_groups)
        self.combined = opts.sensors
        # the floor: the actuator state; the contract floor: the combined state (after the load cell)
        self.pub = self.create_publisher(JointState, topics.INSTRUMENT_JS if self.combined
                                         else topics.ACTUATOR_JS, state_qos(opts.depth))
        self.sub = self.create_subscription(JointState, topics.SERVO_CURRENT, self.on_answer,
                                            state_qos(opts.depth), callback_group=sub_group)
        self.msg = _combined_state() if self.combined else _actuator_state()
        self.sensors = None
        self.sensors_same_sample = 0
        if opts.sensors:      # the contract's load cell, sent before the combined state
            self.sensors = (self.create_publisher(WrenchStamped, topics.MEASURED_FORCE,
                                                  state_qos(opts.depth)),
                            WrenchStamped())
        self.timer = self.create_timer(opts.period, self.on_tick, callback_group=group)

    def on_tick(self) -> None:
        w = self.window
        if w.measuring:
            w.record_tick(time.perf_counter_ns())
        msg = self.msg if self.prealloc else (_combined_state() if self.combined
                                              else _actuator_state())
        t = time.time_ns()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, 1_000_000_000)
        value = (t % 1_000_000) * 1e-6      # this period's value: the echo answers with it
        msg.position[0] = value
        if self.sensors is not None:
            pub, force = self.sensors
            force.header.stamp = msg.header.stamp
            msg.position[1] = force.wrench.force.z = value    # the jaw and the load cell
            msg.position[2] = value                           # the drum
            pub.publish(force)
        self.pub.publish(msg)
        if w.measuring:
            w.sent += 1
        w.advance(self.summary)

    def on_answer(self, msg: JointState) -> None:
        stamp = stamp_nanoseconds(msg.header.stamp)
        round_trip = time.time_ns() - stamp
        w = self.window
        w.saw_answer()
        if w.counts(stamp):
            w.record_answer(stamp, round_trip)
            if self.sensors is not None and msg.effort[0] == (stamp % 1_000_000) * 1e-6:
                self.sensors_same_sample += 1   # answered with the load cell of its own period

    def summary(self) -> dict:
        w = self.window
        out = w.answer_summary(self.period)
        out.update({'sent': w.sent, 'received': w.received})
        if self.sensors is not None:    # answers that used the load cell of their own period
            out['sensors_same_sample_fraction'] = (self.sensors_same_sample / w.received
                                                   if w.received else float('nan'))
        out['lost_fraction'] = 1.0 - w.received / w.sent if w.sent else float('nan')
        return out


class Echo(Node):
    """The controller's side of the floor: answer each state, its stamp carried.

    The floor answers the actuator state; the contract floor (``--sensors``) keeps the load
    cell's value and answers the combined state (the controller steps on it) with the jaw it
    carries and that load cell. ``--answer callback`` (the floor) answers in the subscription callback;
    ``--answer timer`` answers the newest state on its own 1 kHz timer, as the
    controller node does (the cost of an unsynchronised timer, measured bare).
    """

    def __init__(self, opts):
        super().__init__('bench_echo')
        self.prealloc = opts.prealloc
        self.pub = self.create_publisher(JointState, topics.SERVO_CURRENT, state_qos(opts.depth))
        self.combined = opts.sensors
        self.sub = self.create_subscription(JointState, topics.INSTRUMENT_JS if self.combined
                                            else topics.ACTUATOR_JS, self.on_state,
                                            state_qos(opts.depth),
                                            callback_group=_callback_group(opts.callback_groups))
        self.msg = _command()
        self.latest = None
        self.grip_force = 0.0   # N: the load cell's last value (--sensors)
        self.sensor_subs = ()
        if opts.sensors:
            self.sensor_subs = (
                self.create_subscription(WrenchStamped, topics.MEASURED_FORCE, self.on_force,
                                         state_qos(opts.depth),
                                         callback_group=_callback_group(opts.callback_groups)),)
        self.answer_on_timer = opts.answer == 'timer'
        if self.answer_on_timer:
            self.timer = self.create_timer(opts.period, self.on_tick)
        if opts.gc_freeze:
            self.freeze_timer = self.create_timer(2.0, self._freeze)

    def _freeze(self) -> None:
        gc.collect()
        gc.freeze()
        self.freeze_timer.cancel()

    def on_state(self, msg: JointState) -> None:
        if self.answer_on_timer:
            self.latest = msg
        else:
            self.answer(msg)

    def on_force(self, msg: WrenchStamped) -> None:
        self.grip_force = msg.wrench.force.z

    def on_tick(self) -> None:
        if self.latest is not None:
            self.answer(self.latest)

    def answer(self, msg: JointState) -> None:
        out = self.msg if self.prealloc else _command()
        out.header.stamp = msg.header.stamp
        # the contract floor: from the state's jaw and the load cell held (equal when both
        # are of the same period); the floor: from the actuator state
        out.effort[0] = (0.5 * (msg.position[1] + self.grip_force) if self.combined
                         else msg.position[0] * 0.5)
        self.pub.publish(out)


def _callback_group(kind: str):
    if kind == 'reentrant':
        return ReentrantCallbackGroup()
    if kind == 'separate':
        return MutuallyExclusiveCallbackGroup()
    return None      # the node's default group


def _actuator_state() -> JointState:
    msg = JointState()
    msg.name = [topics.DRUM_JOINT]
    msg.position = [0.0]
    msg.velocity = [0.0]
    msg.effort = [0.0]
    return msg


def _combined_state() -> JointState:
    """Build the contract's one state message a period: wrist_pitch, jaw, jaw_drum."""
    msg = JointState()
    msg.name = [topics.WRIST_JOINT, topics.JAW_JOINT, topics.DRUM_JOINT]
    msg.position = [0.0, 0.0, 0.0]
    msg.velocity = [0.0, 0.0, 0.0]
    msg.effort = [float('nan'), float('nan'), 0.0]
    return msg


def _command() -> JointState:
    msg = JointState()
    msg.name = [topics.DRUM_JOINT]
    msg.effort = [0.0]
    return msg


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m grip_force_ros.lab.bench.child')
    p.add_argument('role', choices=('ping', 'echo'))
    p.add_argument('--seconds', type=float, default=10.0, help='measurement window (s)')
    p.add_argument('--warmup', type=float, default=1.0, help='after the first answer (s)')
    p.add_argument('--period', type=float, default=1e-3, help='loop period (s)')
    p.add_argument('--executor', choices=('events', 'single', 'multi'), default='events')
    p.add_argument('--depth', type=int, default=1, help='QoS KEEP_LAST depth')
    p.add_argument('--gc-freeze', action='store_true', help='gc.freeze() after start-up')
    p.add_argument('--prealloc', action='store_true', help='reuse one message per publisher')
    p.add_argument('--answer', choices=('callback', 'timer'), default='callback',
                   help='echo: answer in the subscription callback or on a 1 kHz timer')
    p.add_argument('--sensors', action='store_true',
                   help="the contract's period: the load cell, then one combined joint state "
                        '(wrist_pitch, jaw, jaw_drum) that the echo answers')
    p.add_argument('--callback-groups', choices=('default', 'separate', 'reentrant'),
                   default='default')
    return p


def main(argv=None) -> int:
    opts = build_parser().parse_args(argv)
    rclpy.init()
    node = executor = None
    try:
        node = {'ping': Ping, 'echo': Echo}[opts.role](opts)
        executor = make_executor(opts.executor)
        executor.add_node(node)
        window = getattr(node, 'window', None)
        # EventsExecutor (rclpy 7.1.6) never runs a timer inside an unbounded
        # spin_until_future_complete(future): spin in bounded slices instead.
        while rclpy.ok() and (window is None or not window.finished.done()):
            executor.spin_until_future_complete(window.finished if window else Future(), timeout_sec=0.2)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close_node(executor, node)   # the executor first: see close_node
        shutdown_once()    # a SIGINT may shut the context down under try_shutdown
    return 0


if __name__ == '__main__':
    sys.exit(main())
