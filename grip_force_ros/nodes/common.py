"""What the three nodes share: QoS, message packing and checking, the main loop.

QoS (documented in docs/ros_interface.md). Every profile of the package is named
here; nothing else constructs a ``QoSProfile``:

* state and command topics (1 kHz and the master stream): publishers
  RELIABLE, VOLATILE, KEEP_LAST 10 (a recorder that lags a little still gets
  every sample on loopback), :data:`STATE_PUB_QOS`; the controller and the sim
  subscribe with KEEP_LAST 1 (:data:`STATE_SUB_QOS`), because only the newest
  sample of a state matters to a loop.
* force topics (estimated, target, measured): as state topics.
* ``/diagnostics``: RELIABLE, KEEP_LAST 10, as diagnostic_aggregator expects
  (:data:`DIAGNOSTICS_QOS`).
* recorders and monitors (the demo's bag recorder, the fault probe, the soak
  monitor): KEEP_LAST 1000, deep enough to miss nothing (:data:`RECORD_QOS`), or
  :func:`matching_qos` for whatever the publishers offer.
* the benchmark's ping-pong floor: :func:`state_qos` at the depth under test.
"""
from __future__ import annotations

import faulthandler
import gc
import math
import signal
import sys
import time
from typing import Callable, Iterable, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.task import Future
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState

from grip_force_ros.nodes import realtime
from grip_force_ros.nodes.lifetime import STACK_DUMP_SIGNAL, wait_until  # noqa: F401 (re-exported)
from grip_force_ros.nodes.lifetime import leave_after_peers, stop_watch, watch_own_teardown


def state_qos(depth: int) -> QoSProfile:
    """RELIABLE, VOLATILE, KEEP_LAST ``depth`` (messages): the package's state/command QoS."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


#: Publishers of state, command and force topics (the master, the sim, the controller, the probe).
STATE_PUB_QOS = state_qos(10)
#: Subscriptions of a loop: only the newest sample matters.
STATE_SUB_QOS = state_qos(1)
#: ``/diagnostics`` publishers.
DIAGNOSTICS_QOS = state_qos(10)
#: Subscriptions that record or check every message (recorder, fault probe, soak monitor).
RECORD_QOS = state_qos(1000)


def matching_qos(offered: Iterable[QoSProfile]) -> QoSProfile:
    """Build a recording QoS (KEEP_LAST 1000) that matches every offered profile.

    RELIABLE only if every publisher offers it (else BEST_EFFORT), TRANSIENT_LOCAL
    only if every publisher offers it (else VOLATILE).
    """
    offered = list(offered)
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    transient = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                      for q in offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORD_QOS.depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient
                      else DurabilityPolicy.VOLATILE)


_RCLError = _rclpy_impl.RCLError


class InputRejected(ValueError):
    """A received message is malformed; ``str()`` is the reason for /diagnostics."""


def joint_state(stamp, names: Sequence[str], position: Sequence[float] = (),
                velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> JointState:
    """Build a JointState (SI: rad, rad/s; effort in the unit the topic documents)."""
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = list(names)
    msg.position = [float(v) for v in position]
    msg.velocity = [float(v) for v in velocity]
    msg.effort = [float(v) for v in effort]
    return msg


def read_joints(msg: JointState, joints: Sequence[str], fields: Sequence[str],
                others: bool = False) -> dict[str, tuple]:
    """Extract ``fields`` of ``joints`` from a JointState, checking everything.

    Parameters
    ----------
    msg : JointState
        The received message.
    joints : sequence of str
        Joint names that must all be present (other names are an error too:
        a message for another device on the wrong topic must not be used).
    fields : sequence of str
        Any of 'position', 'velocity', 'effort' that must be present and finite
        (for the wanted joints).
    others : bool
        Other joints are normal (a dVRK arm's ``measured_js`` holds all its joints): they
        are not an error and their values are not checked.

    Returns
    -------
    dict
        joint name -> tuple of the requested fields, in the order given.

    Raises
    ------
    InputRejected
        Why the message cannot be used (names, lengths, non-finite values).
    """
    names = list(msg.name)
    if len(set(names)) != len(names):
        raise InputRejected(f'duplicate joint names {names}')
    unknown = [n for n in names if n not in joints]
    if unknown and not others:
        raise InputRejected(f'unknown joint name(s) {unknown}, expected {list(joints)}')
    missing = [n for n in joints if n not in names]
    if missing:
        raise InputRejected(f'missing joint(s) {missing}')
    arrays = {}
    for field in fields:
        values = getattr(msg, field)
        if len(values) != len(names):
            raise InputRejected(f'{field} has {len(values)} values for {len(names)} joints')
        arrays[field] = values
    out = {}
    for i, name in enumerate(names):
        if others and name not in joints:
            continue
        row = []
        for field in fields:
            v = float(arrays[field][i])
            if not math.isfinite(v):
                raise InputRejected(f'{field} of {name!r} is {v}')
            row.append(v)
        out[name] = tuple(row)
    return out


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_nanoseconds(stamp) -> int:
    """builtin_interfaces/Time as integer nanoseconds (exact, for matching stamps)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def make_executor(context=None, kind: str = 'events'):
    """Make an executor: 'events' (rclpy.experimental.EventsExecutor) or 'single'.

    The nodes' own processes (:func:`run_node`) spin the EventsExecutor; 'single' is for a
    caller that spins nodes of its own in a thread (the laboratory's harness).
    """
    if kind == 'single':
        return SingleThreadedExecutor(context=context)
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # pragma: no cover - older rclpy
        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)


#: How long after a callback error the context may still go down for the error to be read as
#: a signal's shutdown racing the callback (s). The SIGINT handler shuts the context down
#: moments after it wakes the executor, so the error may come first (launch's Ctrl-C, the
#: EventsExecutor's "Unable to convert call argument '0' to Python object").
SHUTDOWN_RACE_WAIT = 2.0


def freeze_heap() -> None:
    """Collect once, then leave every object alive now out of later full collections.

    For nodes run inside a large process (a test process, the fault check): they share its
    garbage collector, and a full collection scans the whole heap while the nodes wait. In a
    process that had collected this suite (~450 000 objects) the automatic full collections
    that building probe-like records set off took ~250 ms each (9 of 9); with the heap frozen
    first, 0-4 ms (17 of them): an in-process controller stalled by 125 ms is beyond every
    watchdog. The node
    processes do not need it: no collection at all in 20 s of their steady 1 kHz running
    (BENCHMARKS.md). :func:`unfreeze_heap` gives the objects back to the collector.
    """
    gc.collect()
    gc.freeze()


def unfreeze_heap() -> None:
    """Undo :func:`freeze_heap`: the frozen objects are collected again."""
    gc.unfreeze()


#: Time a node's teardown (executor, node, context) may run before every thread's stack goes
#: to stderr and the process is ended (s; time stopped for gdb's native stacks does not count,
#: :func:`~grip_force_ros.nodes.lifetime.watch_own_teardown`). A teardown stuck in the
#: middleware is deaf to every signal rclpy handles: Fast DDS has an open deadlock of a
#: participant's own threads (eProsima/Fast-DDS#6502), and its ``set_listener(nullptr)``, the
#: first step of rmw_fastrtps's ``destroy_participant``, spins for good when it starts while a
#: discovery callback of that participant runs (eProsima/Fast-DDS#6513). The limit ends the
#: process before this package's runners signal it again (SIGTERM 5 s after SIGINT) and before
#: ``ros2 launch`` does (15 s), so the stacks reach the log.
TEARDOWN_LIMIT = 4.0
#: Fraction of :data:`TEARDOWN_LIMIT` after which a teardown still running has its native
#: stacks written to stderr (gdb; :func:`~grip_force_ros.nodes.lifetime.watch_own_teardown`).
#: A Python stack alone cannot tell a Fast DDS deadlock from a slow teardown. The process is
#: stopped while gdb starts and reads (seconds on a loaded machine), which delays a teardown
#: that would have ended, so it comes late: 3 s, 3.8 times the slowest teardown measured on a
#: loaded machine (0.79 s).
NATIVE_STACKS_AT = 0.75


def shutdown_follows(wait: float = SHUTDOWN_RACE_WAIT, poll: float = 0.01) -> bool:
    """Whether the default context is, or within ``wait`` s goes, down (s; polled every ``poll`` s)."""
    return wait_until(lambda: not rclpy.ok(), wait, poll)


class SignalStop:
    """SIGINT and SIGTERM ask a node process to stop; they do not interrupt a callback.

    With rclpy's own handlers (``rclpy.init``'s default), a Ctrl-C shuts the context down from
    rclpy's signal thread and raises KeyboardInterrupt in the main thread at its next Python
    line, which, in a node stepping at 1 kHz, is mostly inside a timer callback: the
    EventsExecutor logged ``[FATAL] Exception in 'timers' callback:`` (an empty message)
    there, and callbacks already queued then published into a dead context. This handler only
    records the request and resets a stopped one-shot timer (the EventsExecutor of Jazzy takes
    no guard condition; a timer reset from inside a callback fires 0.6 ms later), whose
    callback completes the spin's future: the callback running then ends, the spin returns,
    and the teardown (executor, node, context) runs in that order. Python runs a signal handler
    between two lines of the main thread; while the executor waits in C++ with no callback
    due, that is when the spin's slice (:data:`SPIN_SLICE`) ends.

    Phases: before the spin, a signal raises KeyboardInterrupt (a start that hangs can still
    be interrupted) and asks the stop too, so the spin never starts: Python discards an
    exception raised inside a weakref callback or finaliser ("Exception ignored in"), and an
    import's ``_get_module_lock`` callback is where a signal came during start-up in 27 of
    7200 trials. During the spin, it asks the stop;
    after it (the teardown, bounded by :data:`TEARDOWN_LIMIT`), it is noted and ignored.
    :meth:`restore` puts the previous handlers back (``run_node`` runs inside test processes
    too).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.requested = False          # a signal asked the stop
        self.phase = 'starting'         # 'starting', 'spinning', 'stopping'
        self._wake: Callable[[], None] | None = None
        self._previous = {signum: signal.signal(signum, self._handle) for signum in self.SIGNALS}

    def spin_until_stopped(self, executor, node, finished: Future) -> None:
        """Spin ``executor`` until ``finished`` is done, the context is down or a signal came."""
        def complete():
            wake.cancel()
            if not finished.done():
                finished.set_result(None)
        wake = node.create_timer(WAKE_DELAY, complete, autostart=False)
        self._wake = wake.reset
        self.phase = 'spinning'
        try:
            # EventsExecutor (Jazzy) never returns from spin() or from spin_until_future_complete
            # without a timeout once the context is down: spin in slices.
            while rclpy.ok() and not finished.done() and not self.requested:
                executor.spin_until_future_complete(finished, timeout_sec=SPIN_SLICE)
        finally:
            self.phase = 'stopping'
            self._wake = None

    def restore(self) -> None:
        """Put back the handlers found at construction."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _handle(self, signum, frame) -> None:
        self.requested = True
        if self.phase == 'starting':
            raise KeyboardInterrupt
        if self._wake is not None:
            self._wake()


#: Longest a spin waits in C++ before the main thread runs Python again (s): the latest a
#: signal is handled by a node with no callback due (:class:`SignalStop`).
SPIN_SLICE = 0.5
#: Period of :class:`SignalStop`'s wake timer (s): how soon after a signal the spin ends.
WAKE_DELAY = 0.001


def run_node(make_node: Callable[[], 'rclpy.node.Node'], node_name: str,
             args: list[str] | None = None) -> int:
    """Run the main loop of an executable node (ros2/demos Jazzy style).

    Before the spin, the node's 'realtime' parameters are applied to the process
    (:func:`~grip_force_ros.nodes.realtime.prepare`: memory locked, stack and heap
    pre-faulted, CPU affinity; one INFO line says what). Returns the process exit code: 0 on
    a normal end or Ctrl-C, 2 when the parameters are refused (the reason goes to stderr).
    """
    # Every thread's stack to stderr (the node's log) on STACK_DUMP_SIGNAL: what a process
    # that has to be killed because it did not stop was doing (NodeProcess.stop asks).
    faulthandler.register(STACK_DUMP_SIGNAL, all_threads=True)
    try:
        # SIGINT and SIGTERM are this process's (SignalStop), not rclpy's.
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except _RCLError as exc:   # e.g. an unparsable --params-file: a clear line, no traceback
        print(f'[{node_name}] refusing to start: {exc}', file=sys.stderr)
        return 2
    node = executor = finished = None
    stop = SignalStop()
    try:
        try:
            node = make_node()
            realtime.prepare(node)    # memory locked, stack and heap pre-faulted, CPU affinity
        except ValueError as exc:   # ParameterError and every domain error: one clear line
            print(f'[{node_name}] refusing to start: {exc}', file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        # A node may end itself by completing its ``finished`` Future.
        finished = getattr(node, 'finished', None) or Future()
        stop.spin_until_stopped(executor, node, finished)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (_RCLError, RuntimeError):
        # A context shut down under the executor (not by a signal since SignalStop; by
        # another thread of the process): a callback already queued may then fail to
        # publish ("publisher's context is invalid"), or the EventsExecutor (rclpy 7.1.x)
        # may fail to hand it its arguments, even just before the context is down. That is
        # the shutdown racing the callback, not a fault; an error with the context still up
        # SHUTDOWN_RACE_WAIT later is.
        if not shutdown_follows():
            raise
    finally:
        # Stopped by a signal, which may have reached its peers at the same moment (``ros2
        # launch``'s Ctrl-C): they leave first, in a fixed order, so that no participant is
        # deleted while another one's leaving reaches it. A node that ended itself waits for none.
        if stop.requested:
            try:
                leave_after(node, leave_after_peers())
            except Exception as exc:  # noqa: BLE001 - the teardown below must run whatever
                print(f'[{node_name}] not waiting for peers to leave: {exc!r}', file=sys.stderr)
        # A teardown that never ends (a process deaf to SIGINT and SIGTERM, killed by whoever
        # started it, with nothing in its log) ends here instead: its native stacks (where in
        # the middleware it waits), then its Python stacks and SIGKILL at the limit, counted
        # in the time it runs (the watcher). Without a watcher, faulthandler's limit in wall
        # time: Python stacks, then exit code 1.
        watcher = watch_own_teardown(NATIVE_STACKS_AT * TEARDOWN_LIMIT, TEARDOWN_LIMIT)
        if watcher is None:
            faulthandler.dump_traceback_later(TEARDOWN_LIMIT, exit=True)
        try:
            realtime.finish(node)     # the loop's queued log lines
            close_node(executor, node)
            # Dropped here, inside the limit, not as the function returns: the EventsExecutor's
            # C++ destructor runs now, where a hang is still watched.
            executor = node = finished = None
            shutdown_once()
        finally:
            faulthandler.cancel_dump_traceback_later()
            stop_watch(watcher)
            stop.restore()
    return 0


#: Longest a node's stop waits for the peers it leaves after (s; ``LEAVE_AFTER_ENV``) before its
#: own teardown starts anyway. The sim waits for the controller, which waits for the master:
#: two teardowns in a row, each 0.23 s (p50), 0.78 s (p99), 1.09 s (max) from signal to exit
#: on a loaded machine, and a settle. With
#: the teardown's own limit after it (:data:`TEARDOWN_LIMIT`) a stop still ends before ``ros2
#: launch``'s SIGKILL (10 s after SIGINT; its SIGTERM at 5 s is ignored while stopping).
PEER_LEAVE_WAIT = 3.0
#: Time (s) after the last of those peers has left the graph, for the discovery callback that
#: took its leaving to end (the graph is updated inside it); as ``ProcessGroup.settle``.
PEER_LEAVE_SETTLE = 0.1
#: Interval (s) at which the graph is looked at while waiting.
PEER_LEAVE_POLL = 0.01


def wait_for_peers_to_leave(node, peers: Sequence[str], timeout: float = PEER_LEAVE_WAIT,
                            settle: float = PEER_LEAVE_SETTLE,
                            poll: float = PEER_LEAVE_POLL) -> tuple[str, ...]:
    """Wait until no node named in ``peers`` (in ``node``'s namespace) is in the ROS graph.

    Fast DDS 2.14's ``set_listener(nullptr)``, the first step of rmw_fastrtps's
    ``destroy_participant``, spins for good when it starts while a discovery callback of that
    participant runs (eProsima/Fast-DDS#6513, open), and a stop of several nodes at once
    brings exactly that callback: another participant leaving. ``ProcessGroup`` stops its
    nodes one after another; ``ros2 launch`` sends SIGINT to all at once. So a node
    launched with :data:`~grip_force_ros.nodes.lifetime.LEAVE_AFTER_ENV` stops after the
    nodes it names: in the package's launch files the master leaves first, then the
    controller, then the sim (the reverse start order of the demo). The pause ``settle`` follows
    even when no peer is in the graph any more at the first look: one that left a moment before
    may still be in the callback that took its leaving (the master, stopped at the same moment,
    is mostly gone before the controller looks). A peer still there
    after ``timeout`` s (not stopping, or stuck) is left behind, and its name returned.

    Parameters
    ----------
    node : rclpy.node.Node or None
        The stopping node, its executor already ended (None: nothing to wait for).
    peers : sequence of str
        Plain node names, resolved in ``node``'s namespace.
    timeout : float
        Longest wait (s) for the peers to leave.
    settle : float
        Pause (s) once none of the peers is in the graph.
    poll : float
        Interval (s) between looks at the graph.

    Returns
    -------
    tuple of str
        The peers still in the graph at ``timeout`` (empty when none is there any more).
    """
    if node is None or not peers:
        return ()
    namespace = node.get_namespace()

    def present() -> tuple[str, ...]:
        try:
            graph = set(node.get_node_names_and_namespaces())
        except (_RCLError, RuntimeError):     # the context is already down: nobody to wait for
            return ()
        return tuple(name for name in peers if (name, namespace) in graph)

    if not wait_until(lambda: not present(), timeout, poll):
        return present()
    time.sleep(settle)
    return ()


def leave_after(node, peers: Sequence[str]) -> None:
    """Wait for ``peers`` to leave (:func:`wait_for_peers_to_leave`) and log how it went.

    One line in the node's log: INFO with the time waited, or WARN naming the peers still up.
    """
    if node is None or not peers:
        return
    started = time.monotonic()
    still_up = wait_for_peers_to_leave(node, peers)
    waited = time.monotonic() - started
    if still_up:
        node.get_logger().warning(f'leaving with {", ".join(still_up)} still up after '
                                  f'{waited:.2f} s')
    else:
        node.get_logger().info(f'leaving after {", ".join(peers)} (waited {waited:.2f} s)')


def close_node(executor, *nodes) -> None:
    """End ``executor`` first, then destroy each of ``nodes`` (None entries are skipped).

    The other order left a node's handles to be finalised inside the EventsExecutor's C++
    destructor, when the executor is dropped after the node was destroyed: the sim's main
    thread hung there (``rclpy/event_handler.py`` ``__exit__``, the releasing of a QoS event
    handle), never returning and deaf to signals, in 2 of 14 runs on a loaded machine.
    Shut down, the executor has released every handle while the node still owns them, and the
    node's own ``destroy_node`` finalises them in Python, as in any executor-less teardown.
    """
    if executor is not None:
        executor.shutdown()
    for node in nodes:
        if node is not None:
            node.destroy_node()


def shutdown_once(context=None) -> None:
    """Shut ``context`` (default: the default context) down unless it is, or is just being.

    ``rclpy.try_shutdown`` checks ``ok()`` and then shuts down; rclpy's signal handler shuts
    the context down from its own thread without that check's lock, so a SIGINT between the
    two makes ``try_shutdown`` fail with "rcl_shutdown already called on the given context"
    (a fresh-clone CI run: ``ros2 launch``'s Ctrl-C, the sim exited 1). The context is then
    down, which is what was asked; an error with the context still up is raised.
    """
    try:
        rclpy.try_shutdown(context=context)
    except _RCLError:
        if rclpy.ok(context=context):
            raise
