"""Run nodes inside this process, for tests, benchmarks and fault checks.

:class:`RosRunner`: nodes share one rclpy context and one executor spinning in
a background thread, so a test can reach into a node (e.g. wrap
``controller.step`` to record every period). The spinning thread returns to
Python every :data:`SPIN_SLICE` seconds: the EventsExecutor holds the GIL while
it waits, and the test thread needs it too.

Nodes as separate processes (their own interpreter each, what a 1 kHz plant
next to a 1 kHz controller needs on a small machine):
:class:`grip_force_ros.lab.processes.NodeProcess`.
"""
from __future__ import annotations

import gc
import threading
from typing import Any, Callable

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future

from grip_force_ros.lab.processes import wait_until
from grip_force_ros.nodes.common import make_executor
from grip_force_ros.nodes.lifetime import close_node, shutdown_once

#: Longest time the spinning thread stays inside the executor before yielding (s).
SPIN_SLICE = 0.01


def freeze_heap() -> None:
    """Collect once, then leave every object alive now out of later full collections.

    For nodes run inside a large process (a test process, the fault check): they share its
    garbage collector, and a full collection scans the whole heap while the nodes wait. In a
    process that had collected this suite (~450 000 objects) the automatic full collections
    that building probe-like records set off took ~250 ms each (9 of 9); with the heap frozen
    first, 0-4 ms (17 of them): an in-process controller stalled by 125 ms is beyond every
    watchdog. The node processes do not need it: no collection at all in 20 s of their steady
    1 kHz running (BENCHMARKS.md). :func:`unfreeze_heap` gives the objects back to the collector.
    """
    gc.collect()
    gc.freeze()


def unfreeze_heap() -> None:
    """Undo :func:`freeze_heap`: the frozen objects are collected again."""
    gc.unfreeze()


class RosRunner:
    """Nodes in this process on their own rclpy context, spun in a background thread.

    >>> with RosRunner() as ros:                        # doctest: +SKIP
    ...     ctl = ros.add(ControllerNode, force_sensor_enabled=True)
    ...     ros.start()
    ...     ros.wait_for(lambda: ctl.last_output is not None, 2.0)
    """

    def __init__(self, executor_kind: str = 'events'):
        freeze_heap()     # a full collection of a test process's heap stalls the nodes here
        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = make_executor(self.context, executor_kind)
        self.nodes: list[Node] = []
        self._stop = Future()
        self._thread: threading.Thread | None = None
        self.spin_error: BaseException | None = None

    def add(self, node_cls: Callable[..., Node], **overrides: Any) -> Node:
        """Create a node with parameter overrides and add it to the executor."""
        node = node_cls(context=self.context,
                        parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def plain_node(self, name: str) -> Node:
        """Create a bare node (for probes, publishers, parameter clients) on this context."""
        node = Node(name, context=self.context)
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._spin, name='ros-spin', daemon=True)
            self._thread.start()

    def _spin(self) -> None:
        try:
            while not self._stop.done() and self.context.ok():
                self.executor.spin_until_future_complete(self._stop, timeout_sec=SPIN_SLICE)
        except BaseException as exc:  # reported by the test, not swallowed
            self.spin_error = exc

    @staticmethod
    def wait_for(predicate: Callable[[], bool], timeout: float, poll: float = 0.01) -> bool:
        """Poll ``predicate`` until true or ``timeout`` s passed; returns its last value."""
        return wait_until(predicate, timeout, poll)

    def stop(self) -> None:
        if not self._stop.done():
            self._stop.set_result(True)
        if self._thread is not None:
            self._thread.join(5.0)
        close_node(self.executor, *self.nodes)   # the executor first: see close_node
        self.nodes = []
        shutdown_once(self.context)
        unfreeze_heap()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
