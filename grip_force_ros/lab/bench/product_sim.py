r"""The product's measuring end: the shipped sim node, recording its loop for one window.

``grip-force bench`` measures the product as it measures the floor: the process
that publishes the state measures the round trip on its own clock. Here that
process is the shipped :class:`~grip_force_ros.nodes.sim_instrument.SimInstrumentNode`
(the same plant, timer and topics; nothing is overridden on the loop's path). The
controller stamps each command with the actuator state it answers (its shipped
convention), so the sim's :class:`~grip_force_ros.sim.loop_latency.LoopLatency`
already sees every round trip; this module only keeps all of them for the window
and prints the bench protocol of :mod:`.child` (``START``, then one JSON line).

Run by :func:`grip_force_ros.lab.bench.loop.run_product`::

    python -m grip_force_ros.lab.bench.product_sim --seconds 20 --warmup 2 \
        --ros-args --params-file config/paper_needle_driver.yaml
"""
from __future__ import annotations

import argparse
import functools
import sys
import time

import numpy as np
from rclpy.utilities import remove_ros_args

from grip_force_ros.lab import node_process
from grip_force_ros.lab.bench.child import _Window
from grip_force_ros.nodes.lifetime import run_node
from grip_force_ros.nodes.sim_instrument import SimInstrumentNode
from grip_force_ros.sim.loop_latency import LoopLatency


class _RecordingLoopLatency(LoopLatency):
    """:class:`LoopLatency` that also keeps the answers of a measurement window."""

    def __init__(self, window: _Window, **kwargs):
        super().__init__(**kwargs)
        self.window = window
        self.other_in_window = 0    # commands answering no fresh state (e.g. timer fallback)

    def command_received(self, stamp_ns: int, arrival_ns: int) -> int | None:
        round_trip = super().command_received(stamp_ns, arrival_ns)
        w = self.window
        w.saw_answer()
        if not w.counts(stamp_ns):
            return round_trip
        if round_trip is None:
            self.other_in_window += 1
        else:
            w.record_answer(stamp_ns, round_trip)
        return round_trip


class BenchSim(SimInstrumentNode):
    """The shipped sim node, with its loop's round trips kept for one measurement window."""

    def __init__(self, opts, **kwargs):
        super().__init__(**kwargs)
        self.period = 1.0 / self._param.params.publish_rate
        capacity = int((opts.seconds + 5.0) / self.period) + 1000
        self.window = _Window(self, opts.seconds, opts.warmup, capacity, gc_freeze=False,
                              open_at_ns=opts.open_at_ns)
        self.finished = self.window.finished          # run_node stops when the window is over
        self.loop = _RecordingLoopLatency(self.window)
        self._record_path = opts.record
        self._bench_timer = self.create_timer(0.05, lambda: self.window.advance(self.summary))

    def _tick(self) -> None:
        w = self.window
        if w.measuring:
            w.record_tick(time.perf_counter_ns())
            w.sent += 1
        super()._tick()

    def summary(self) -> dict:
        w = self.window
        out = w.answer_summary(self.period)
        out.update({'states': w.sent, 'answered': w.n_latencies,
                    'other_commands': self.loop.other_in_window,
                    'period_s': self.period})
        if self._record_path:          # every answer of the window, for the full path
            np.savez(self._record_path, answered_ns=w.answered[:w.n_latencies],
                     round_trip_ns=w.latencies[:w.n_latencies])
        return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m grip_force_ros.lab.bench.product_sim')
    p.add_argument('--seconds', type=float, default=10.0, help='measurement window (s)')
    p.add_argument('--warmup', type=float, default=2.0, help='after the first answer (s)')
    p.add_argument('--record', default=None, help='.npz of every answer of the window (stamp, round trip)')
    p.add_argument('--open-at-ns', type=int, default=0,
                   help='wall clock (ns) before which the window does not open (0: after the '
                        'warm-up); the arms of a two-arm run share one window')
    return p


def main(argv=None) -> int:
    argv = list(sys.argv if argv is None else argv)
    opts = build_parser().parse_args(remove_ros_args(argv)[1:])
    node_process.install()      # its teardown watched, as the harness's nodes
    return run_node(functools.partial(BenchSim, opts), 'sim_instrument', argv)


if __name__ == '__main__':
    sys.exit(main())
