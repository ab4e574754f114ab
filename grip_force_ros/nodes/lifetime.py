"""How a node process runs and stops: :func:`run_node` (ros2/demos style) and its teardown.

* SIGINT or SIGTERM asks the spin to stop (:class:`SignalStop`): the callback running ends,
  the spin returns, the teardown runs. Before the spin a signal interrupts the start; during
  the teardown it is ignored. Exit code 0 then, 2 when the node refuses its parameters.
* The teardown (executor, node, context: :func:`close_node`, :func:`shutdown_once`) may take
  :data:`TEARDOWN_LIMIT` s; past it every thread's Python stack goes to stderr and the
  process exits 1 (:data:`teardown_guard`), before ``ros2 launch`` kills it (10 s after SIGINT).
* :data:`STACK_DUMP_SIGNAL` writes every thread's Python stack to stderr at any time.
* A node launched with :data:`LEAVE_AFTER_ENV` stops after the peers it names (:func:`leave_after`).
"""
from __future__ import annotations

import faulthandler
import os
import signal
import sys
import time
from typing import Callable, Mapping, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from grip_force_ros.nodes import realtime
from grip_force_ros.nodes.common import make_executor

_RCLError = _rclpy_impl.RCLError
#: Signal on which a node writes every thread's Python stack to stderr (``faulthandler``).
STACK_DUMP_SIGNAL = signal.SIGUSR1
#: Time a node's teardown may take (s): with :data:`PEER_LEAVE_WAIT` before it, under 10 s.
TEARDOWN_LIMIT = 4.0
#: Time (s) within which the context going down makes a callback's error a shutdown's race.
SHUTDOWN_RACE_WAIT = 2.0
#: Longest a spin waits in C++ before a signal is looked at (s); the wake timer's delay (s).
SPIN_SLICE, WAKE_DELAY = 0.5, 0.001
#: Environment variable: the node names (comma-separated) a node leaves after on a signal.
LEAVE_AFTER_ENV = 'GRIP_FORCE_LEAVE_AFTER'
#: Longest wait for those peers (s), and the pause once they are gone (s).
PEER_LEAVE_WAIT, PEER_LEAVE_SETTLE = 3.0, 0.1


def limit_teardown(limit: float) -> Callable[[], None]:
    """Python stacks and exit code 1 after ``limit`` s (wall time); returns what cancels it."""
    faulthandler.dump_traceback_later(limit, exit=True)
    return faulthandler.cancel_dump_traceback_later


#: Called with :data:`TEARDOWN_LIMIT` as the teardown starts; returns what ends the guard.
teardown_guard: Callable[[float], Callable[[], None]] = limit_teardown


def leave_after_environment(peers: Sequence[str]) -> dict[str, str]:
    """Return the environment entry that makes a node stop after ``peers`` (node names)."""
    return {LEAVE_AFTER_ENV: ','.join(peers)}


def leave_after_peers(env: Mapping[str, str] | None = None) -> tuple[str, ...]:
    """Return the node names in :data:`LEAVE_AFTER_ENV` of ``env`` (default ``os.environ``)."""
    names = (os.environ if env is None else env).get(LEAVE_AFTER_ENV, '').split(',')
    return tuple(name.strip() for name in names if name.strip())


def leave_after(node, peers: Sequence[str], timeout: float = PEER_LEAVE_WAIT,
                settle: float = PEER_LEAVE_SETTLE) -> tuple[str, ...]:
    """Wait up to ``timeout`` s for ``peers`` (in ``node``'s namespace) to leave, then ``settle`` s.

    Why: Fast DDS's participant deletion spins for good inside a discovery callback, which a
    peer's leaving brings (eProsima/Fast-DDS#6513). Logs a line; returns the peers still up.
    """
    if node is None or not peers:
        return ()
    namespace, started = node.get_namespace(), time.monotonic()

    def present() -> tuple[str, ...]:
        try:
            graph = set(node.get_node_names_and_namespaces())
        except (_RCLError, RuntimeError):     # the context is already down: nobody to wait for
            return ()
        return tuple(name for name in peers if (name, namespace) in graph)

    while (still_up := present()) and time.monotonic() < started + timeout:
        time.sleep(0.01)
    if still_up:
        node.get_logger().warning(f'leaving with {", ".join(still_up)} still up after '
                                  f'{time.monotonic() - started:.2f} s')
        return still_up
    time.sleep(settle)
    node.get_logger().info(f'leaving after {", ".join(peers)} (waited {time.monotonic() - started:.2f} s)')
    return ()


class SignalStop:
    """SIGINT and SIGTERM ask the spin to stop; they never raise inside a callback.

    While spinning, a signal resets :attr:`wake`, a stopped one-shot timer that ends the spin
    (rclpy's own handler raises KeyboardInterrupt wherever the main thread is: mostly inside a
    1 kHz callback). Before the spin it raises KeyboardInterrupt; after it, it is ignored.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested, self.phase, self.wake = False, 'starting', None
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}

    def restore(self) -> None:
        """Put back the handlers found at construction."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum, frame) -> None:
        self.requested = True
        if self.phase == 'starting':
            raise KeyboardInterrupt
        if self.phase == 'spinning':
            self.wake.reset()


def run_node(make_node: Callable[[], 'rclpy.node.Node'], node_name: str,
             args: list[str] | None = None) -> int:
    """Run node ``make_node()`` until it finishes (its ``finished`` Future) or a signal; exit code."""
    faulthandler.register(STACK_DUMP_SIGNAL, all_threads=True)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _RCLError as exc:   # e.g. an unparsable --params-file: a clear line, no traceback
        print(f'[{node_name}] refusing to start: {exc}', file=sys.stderr)
        return 2
    node = executor = finished = None
    stop = SignalStop()

    def wake():
        stop.wake.cancel()
        if not finished.done():
            finished.set_result(None)
    try:
        try:
            node = make_node()
            realtime.prepare(node)    # memory locked, stack and heap pre-faulted, CPU affinity
        except ValueError as exc:     # ParameterError and every domain error: one clear line
            print(f'[{node_name}] refusing to start: {exc}', file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        finished = getattr(node, 'finished', None) or Future()
        stop.wake, stop.phase = node.create_timer(WAKE_DELAY, wake, autostart=False), 'spinning'
        # In slices: Jazzy's EventsExecutor never returns from a spin once the context is down.
        while rclpy.ok() and not finished.done() and not stop.requested:
            executor.spin_until_future_complete(finished, timeout_sec=SPIN_SLICE)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (_RCLError, RuntimeError):   # a context shut down under a queued callback: no fault
        deadline = time.monotonic() + SHUTDOWN_RACE_WAIT
        while rclpy.ok() and time.monotonic() < deadline:
            time.sleep(0.01)
        if rclpy.ok():
            raise
    finally:
        stop.phase = 'stopping'
        if stop.requested:      # a signal may have reached the peers too (launch's Ctrl-C)
            try:
                leave_after(node, leave_after_peers())
            except Exception as exc:  # noqa: BLE001 - the teardown below must run whatever
                print(f'[{node_name}] not waiting for peers to leave: {exc!r}', file=sys.stderr)
        end_guard = teardown_guard(TEARDOWN_LIMIT)
        try:
            realtime.finish(node)     # the loop's queued log lines
            close_node(executor, node)
            executor = node = finished = stop.wake = None   # the executor's destructor, guarded
            shutdown_once()
        finally:
            end_guard()
            stop.restore()
    return 0


def close_node(executor, *nodes) -> None:
    """Shut ``executor`` down, then destroy each of ``nodes`` (None entries are skipped)."""
    if executor is not None:    # first: a node destroyed first leaves its handles to its destructor
        executor.shutdown()
    for node in nodes:
        if node is not None:
            node.destroy_node()


def shutdown_once(context=None) -> None:
    """Shut ``context`` (default: the default one) down unless it is, or is just being, down."""
    try:
        rclpy.try_shutdown(context=context)
    except _RCLError:           # a signal handler's shutdown came between the check and the call
        if rclpy.ok(context=context):
            raise
