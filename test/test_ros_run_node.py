"""run_node: a clean exit when the context shuts down under a callback, errors otherwise.

On SIGINT, rclpy shuts the context down while the executor may still run a queued
callback, whose publish then fails ("publisher's context is invalid"); or, the other
order, the callback's error comes just before the context is down. Neither is an error
exit of the node.
"""
from __future__ import annotations

import gc
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import weakref

import pytest
import rclpy
import rclpy.task
from rclpy.context import Context
from rclpy.node import Node
from sensor_msgs.msg import JointState

from grip_force_ros.nodes import lifetime
from grip_force_ros.nodes.lifetime import run_node

pytestmark = pytest.mark.ros


class _ShutsDownThenPublishes(Node):
    """Its timer shuts the context down (as the SIGINT handler does), then publishes."""

    def __init__(self):
        super().__init__('shutdown_race')
        self.pub = self.create_publisher(JointState, 'shutdown_race', 1)
        self.create_timer(0.01, self._tick)

    def _tick(self):
        rclpy.shutdown()
        self.pub.publish(JointState())


class _Fails(Node):
    """A callback error while the context is up."""

    def __init__(self):
        super().__init__('fails')
        self.create_timer(0.01, self._tick)

    def _tick(self):
        raise RuntimeError('a real fault')


def test_publish_failing_after_shutdown_is_a_clean_exit():
    assert run_node(_ShutsDownThenPublishes, 'shutdown_race', []) == 0


def test_an_error_while_running_is_not_swallowed():
    with pytest.raises(RuntimeError, match='a real fault'):
        run_node(_Fails, 'fails', [])
    rclpy.try_shutdown()


class _FailsThenShutsDown(Node):
    """A callback error just before the context goes down (launch's Ctrl-C on a loaded machine).

    The SIGINT handler wakes the executor, then shuts the context down: a queued callback
    may fail in between, with the context still up when ``run_node`` sees the error.
    """

    def __init__(self):
        super().__init__('fails_then_shuts_down')
        self.create_timer(0.01, self._tick)

    def _tick(self):
        threading.Timer(0.05, rclpy.try_shutdown).start()
        raise RuntimeError("Unable to convert call argument '0' to Python object")


def test_an_error_just_before_a_shutdown_is_a_clean_exit():
    assert run_node(_FailsThenShutsDown, 'fails_then_shuts_down', []) == 0


class _Finishes(Node):
    """A node that ends itself at once (its ``finished`` future done)."""

    def __init__(self):
        super().__init__('finishes')
        self.finished = rclpy.task.Future()
        self.finished.set_result(True)


def test_a_signal_shutting_the_context_down_inside_try_shutdown_is_a_clean_exit(monkeypatch):
    """rclpy's signal handler shuts the context down between try_shutdown's check and call.

    Seen in a fresh-clone CI run (``ros2 launch``'s Ctrl-C): the sim exited 1 with
    "rcl_shutdown already called on the given context". Replayed: the context goes down
    after the check, then the call fails as rcl's does.
    """
    real = rclpy.try_shutdown

    def raced(context=None):
        real(context=context)    # the signal handler's shutdown, after the check passed
        raise lifetime._RCLError('failed to shutdown: rcl_shutdown already called on the given context')
    monkeypatch.setattr(rclpy, 'try_shutdown', raced)
    assert run_node(_Finishes, 'finishes', []) == 0


def test_a_shutdown_error_with_the_context_still_up_is_raised(monkeypatch):
    def fails(context=None):
        raise lifetime._RCLError('failed to shutdown: something else')
    monkeypatch.setattr(rclpy, 'try_shutdown', fails)
    with pytest.raises(lifetime._RCLError, match='something else'):
        run_node(_Finishes, 'finishes', [])
    monkeypatch.undo()
    rclpy.try_shutdown()


class _RecordingExecutor:
    """The real executor, with its shutdown written to ``events``."""

    def __init__(self, executor, events):
        self._executor = executor
        self._events = events

    def __getattr__(self, name):
        return getattr(self._executor, name)

    def shutdown(self, *args, **kwargs):
        self._events.append('executor shutdown')
        return self._executor.shutdown(*args, **kwargs)

    def __del__(self):
        self._events.append('executor dropped')    # the real one goes with it (its only holder)


@pytest.mark.parametrize('kind', ['events', 'single'])
def test_the_executor_ends_before_the_node_is_destroyed(monkeypatch, kind):
    """The executor shuts down first: a node destroyed first leaves its handles to the
    EventsExecutor's destructor, which can hang the process at its stop."""
    events = []
    real_make = lifetime.make_executor
    monkeypatch.setattr(lifetime, 'make_executor',
                        lambda: _RecordingExecutor(real_make(kind=kind), events))

    class _FinishesAndRecords(_Finishes):
        def destroy_node(self):
            events.append('node destroyed')
            super().destroy_node()

    real_shutdown = rclpy.try_shutdown

    def recording_shutdown(context=None):
        events.append('context shut down')
        real_shutdown(context=context)
    monkeypatch.setattr(rclpy, 'try_shutdown', recording_shutdown)
    assert run_node(_FinishesAndRecords, 'finishes', []) == 0
    # The executor is dropped (its C++ destructor run) inside the teardown limit, before the
    # context goes down, not as run_node returns.
    assert events == ['executor shutdown', 'node destroyed', 'executor dropped', 'context shut down']
    assert not rclpy.ok()


class _SignalsItselfInsideItsTick(Node):
    """Its 1 kHz tick sends ``signum`` to its own process at the 50th step, then goes on.

    Python runs the handler at the tick's next line: inside the callback, where a Ctrl-C
    mostly lands in a node stepping at 1 kHz. rclpy's own handler raises KeyboardInterrupt
    there; the EventsExecutor then logs "[FATAL] Exception in 'timers' callback:" and queued
    callbacks publish into a dead context.
    """

    signum = signal.SIGINT
    made: list = []

    def __init__(self):
        super().__init__('signals_itself')
        self.ticks = 0
        self.finished_ticks: list[int] = []      # ticks that ran to their last line
        self.create_timer(0.001, self._tick)
        self.made.append(self)

    def _tick(self):
        self.ticks += 1
        if self.ticks == 50:
            os.kill(os.getpid(), self.signum)
        self.finished_ticks.append(self.ticks)


@pytest.mark.parametrize('kind', ['events', 'single'])
@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_inside_a_callback_ends_the_spin_after_that_callback(monkeypatch, kind, signum):
    real_make = lifetime.make_executor
    monkeypatch.setattr(lifetime, 'make_executor', lambda: real_make(kind=kind))
    monkeypatch.setattr(_SignalsItselfInsideItsTick, 'signum', signum)
    monkeypatch.setattr(_SignalsItselfInsideItsTick, 'made', [])
    before = {s: signal.getsignal(s) for s in lifetime.SignalStop.SIGNALS}
    assert run_node(_SignalsItselfInsideItsTick, 'signals_itself', []) == 0
    node = _SignalsItselfInsideItsTick.made[0]
    assert 50 in node.finished_ticks, 'the tick the signal came in was cut short'
    # The spin ends a few periods after the signal: the wake timer fires 1 ms later. 200
    # periods leave room for a loaded machine; a signal that never ends the spin runs on.
    assert node.ticks - 50 <= 200, node.ticks
    assert {s: signal.getsignal(s) for s in lifetime.SignalStop.SIGNALS} == before
    assert not rclpy.ok()


class _Graph:
    """A stand-in node for :func:`lifetime.leave_after`: who is up when (monotonic s)."""

    def __init__(self, namespace: str, up_until: dict):
        self.namespace, self.up_until, self.looks, self.lines = namespace, up_until, 0, []

    def get_namespace(self):
        return self.namespace

    def get_logger(self):
        return self

    def info(self, line):
        self.lines.append(('INFO', line))

    def warning(self, line):
        self.lines.append(('WARN', line))

    def get_node_names_and_namespaces(self):
        self.looks += 1
        now = time.monotonic()
        return [name_ns for name_ns, until in self.up_until.items() if now < until]


def test_a_stopping_node_waits_for_its_peers_to_leave_then_settles():
    start = time.monotonic()
    graph = _Graph('/psm1', {('master', '/psm1'): start + 0.3, ('controller', '/psm1'): start + 0.2,
                             ('master', '/'): float('inf')})     # another namespace: not a peer
    assert lifetime.leave_after(graph, ('controller', 'master'), timeout=10.0, settle=0.2) == ()
    # gone at 0.3 s, then the settle (0.2 s): no sooner; 10 s would be a wait for /master
    assert 0.5 <= time.monotonic() - start < 10.0
    assert [level for level, _ in graph.lines] == ['INFO'], graph.lines
    assert graph.lines[0][1].startswith('leaving after controller, master (waited '), graph.lines


def test_a_stopping_node_whose_peers_are_gone_still_settles():
    # gone a moment ago: the callback that took its leaving may still run
    graph = _Graph('/', {('sim_instrument', '/'): float('inf')})
    start = time.monotonic()
    assert lifetime.leave_after(graph, ('master',), timeout=10.0, settle=0.2) == ()
    assert graph.looks == 1                     # one look at the graph, then the settle
    assert 0.2 <= time.monotonic() - start < 10.0


def test_a_node_with_no_peers_to_leave_after_does_not_wait():
    graph = _Graph('/', {('master', '/'): float('inf')})
    assert lifetime.leave_after(graph, (), timeout=10.0, settle=10.0) == ()
    assert lifetime.leave_after(None, ('master',), timeout=10.0, settle=10.0) == ()
    assert graph.looks == 0 and graph.lines == []


def test_a_peer_still_up_at_the_timeout_is_left_behind_and_named():
    graph = _Graph('/', {('master', '/'): float('inf'), ('controller', '/'): 0.0})
    start = time.monotonic()
    assert lifetime.leave_after(graph, ('controller', 'master'), timeout=0.3) == ('master',)
    assert time.monotonic() - start >= 0.3
    assert len(graph.lines) == 1 and graph.lines[0][0] == 'WARN', graph.lines
    assert graph.lines[0][1].startswith('leaving with master still up after '), graph.lines


def test_the_peers_to_leave_after_come_from_the_environment():
    from grip_force_ros.nodes.lifetime import leave_after_environment, leave_after_peers
    env = leave_after_environment(('controller', 'master'))
    assert leave_after_peers(env) == ('controller', 'master')
    assert leave_after_peers({'GRIP_FORCE_LEAVE_AFTER': ' master, ,'}) == ('master',)
    assert leave_after_peers({}) == () == leave_after_peers(leave_after_environment(()))


class _SignalsItselfOnceItSeesItsPeer(Node):
    """Sends SIGINT to its own process once node ``leaves_first`` is in its graph."""

    def __init__(self):
        super().__init__('leaves_second')
        self.signalled = False
        self.create_timer(0.01, self._tick)

    def _tick(self):
        if not self.signalled and ('leaves_first', '/') in self.get_node_names_and_namespaces():
            self.signalled = True
            os.kill(os.getpid(), signal.SIGINT)


def test_a_node_stopped_by_a_signal_is_torn_down_after_its_peer_has_left(monkeypatch):
    """The real graph: a peer node (its own context, its own participant) that leaves 1 s after
    the signal; the stopping node's teardown starts after that, not at the signal."""
    monkeypatch.setenv('GRIP_FORCE_LEAVE_AFTER', 'leaves_first')
    peer_context = Context()
    rclpy.init(context=peer_context)
    peer = Node('leaves_first', context=peer_context)
    events = {}
    real_close = lifetime.close_node

    def recording_close(executor, *nodes):
        events['teardown'] = time.monotonic()
        real_close(executor, *nodes)
    monkeypatch.setattr(lifetime, 'close_node', recording_close)
    real_handle = lifetime.SignalStop._handle

    def handle_then_let_the_peer_leave_later(self, signum, frame):
        real_handle(self, signum, frame)
        if 'signal' not in events:
            events['signal'] = time.monotonic()
            threading.Timer(1.0, leave).start()

    def leave():
        peer.destroy_node()
        events['peer left'] = time.monotonic()
        rclpy.try_shutdown(context=peer_context)
    monkeypatch.setattr(lifetime.SignalStop, '_handle', handle_then_let_the_peer_leave_later)
    try:
        assert run_node(_SignalsItselfOnceItSeesItsPeer, 'leaves_second', []) == 0
    finally:
        if rclpy.ok(context=peer_context):
            peer.destroy_node()
            rclpy.try_shutdown(context=peer_context)
    assert events['peer left'] < events['teardown'], events
    assert events['teardown'] - events['signal'] >= 1.0 + lifetime.PEER_LEAVE_SETTLE, events


class _SignalsItselfWhileStarting(Node):
    def __init__(self):
        super().__init__('signals_while_starting')
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)                           # the handler runs within this call
        raise AssertionError('a signal before the spin did not interrupt the start')


def test_a_signal_before_the_spin_interrupts_the_start():
    assert run_node(_SignalsItselfWhileStarting, 'signals_while_starting', []) == 0
    assert not rclpy.ok()


class _SignalDiscardedWhileStarting(Node):
    """A SIGTERM handled inside a weakref callback while the node starts.

    Python discards what such a callback raises ("Exception ignored in"): the
    KeyboardInterrupt of the start phase is lost, as a starting Python can lose a parent-death
    SIGINT inside importlib's ``_get_module_lock`` callback. Should the node spin
    anyway, its own timer ends the spin after 1 s and says so.
    """

    spun: list[bool] = []

    def __init__(self):
        super().__init__('signal_discarded_while_starting')

        class Held:
            pass

        def when_collected(_ref):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(100_000):              # Python lines: the handler runs in here
                pass
        held = Held()
        self._ref = weakref.ref(held, when_collected)
        del held                                  # the callback runs now
        self.finished = rclpy.task.Future()
        self.create_timer(1.0, self._spun)

    def _spun(self):
        self.spun.append(True)
        self.finished.set_result(None)


def test_a_signal_whose_interrupt_python_discards_while_starting_still_stops_the_node(monkeypatch):
    discarded = []
    monkeypatch.setattr(sys, 'unraisablehook', lambda unraisable: discarded.append(unraisable.exc_type))
    monkeypatch.setattr(_SignalDiscardedWhileStarting, 'spun', [])
    assert run_node(_SignalDiscardedWhileStarting, 'signal_discarded_while_starting', []) == 0
    assert discarded == [KeyboardInterrupt], discarded     # the start's interrupt was lost...
    assert _SignalDiscardedWhileStarting.spun == [], 'the node spun after a stop was asked'
    assert not rclpy.ok()


def test_shutdown_once_shuts_a_given_context_down_once():
    """The in-process orchestrators (faults, harness) own contexts of their own."""
    context = Context()
    rclpy.init(context=context)
    lifetime.shutdown_once(context)
    assert not rclpy.ok(context=context)
    lifetime.shutdown_once(context)          # already down: nothing to do, no error


def test_a_runner_keeps_the_test_process_heap_out_of_full_collections():
    """A full collection of a large test process stalled in-process nodes (~250 ms each for
    ~450 000 objects, measured): the harness freezes the heap it starts with, and gives it back."""
    from grip_force_ros.lab.harness import RosRunner
    ballast = [[i] for i in range(200_000)]      # long-lived containers of a large process
    with RosRunner():
        assert gc.get_freeze_count() >= len(ballast)
    assert gc.get_freeze_count() == 0


#: A node process run by ``run_node`` with a short teardown limit: its node ends at once and
#: its ``destroy_node`` takes ``{destroy}`` s; then the process lives on ``{after}`` s. Its
#: teardown watched by the laboratory's watcher (``lab.node_process``) when ``{watched}``.
_TEARDOWN_SCRIPT = '''
import sys, time
import rclpy.task
from rclpy.node import Node
from grip_force_ros.lab import node_process
from grip_force_ros.nodes import lifetime


class Ends(Node):
    def __init__(self):
        super().__init__('teardown_limit')
        self.finished = rclpy.task.Future()
        self.finished.set_result(True)

    def destroy_node(self):
        time.sleep({destroy})
        super().destroy_node()


lifetime.TEARDOWN_LIMIT = 2.0
node_process.NATIVE_STACKS_AT = 0.1
if {watched}:
    node_process.install()
code = lifetime.run_node(Ends, 'teardown_limit', [])
time.sleep({after})
print('ended with', code, flush=True)
sys.exit(code)
'''


def _run_teardown(destroy: float, after: float, env: dict | None = None, watched: bool = True):
    """Run the script; its result, the time it took (s) and its pid."""
    started = time.monotonic()
    script = _TEARDOWN_SCRIPT.format(destroy=destroy, after=after, watched=watched)
    proc = subprocess.Popen([sys.executable, '-c', script],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    done = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    return done, time.monotonic() - started, proc.pid


def _watchers_of(pid: int) -> list[str]:
    """Command lines of teardown watchers (``watch_own_teardown``) still watching ``pid``."""
    found = subprocess.run(['pgrep', '-af', f'teardown-watch [0-9.]+ {pid} [0-9]+ '],
                           capture_output=True, text=True)
    return found.stdout.splitlines()


def test_a_teardown_past_its_limit_leaves_its_python_stacks_and_exits_1():
    """The product's own guard (no laboratory watcher): 60 s in ``destroy_node``, limit 2 s."""
    done, took, pid = _run_teardown(destroy=60.0, after=0.0, watched=False)
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    assert took < 60.0                        # not waited out: ended by the limit
    assert 'Timeout' in done.stderr and 'in destroy_node' in done.stderr, done.stderr
    assert '[teardown]' not in done.stderr and 'ended with' not in done.stdout
    assert _watchers_of(pid) == []


def test_a_watched_teardown_that_does_not_end_leaves_its_stacks_and_is_killed():
    """A teardown stuck past the limit leaves every thread's stack and is killed.

    Here: 60 s in ``destroy_node``, limit 2 s. The native stacks (gdb) come first, which say
    where in the middleware a real teardown waits (a Python stack alone cannot tell a Fast
    DDS deadlock from a slow teardown), then Python's (faulthandler) at the limit; not a
    node deaf to SIGINT and SIGTERM that ``ros2 launch`` SIGKILLs with nothing in its log."""
    done, took, pid = _run_teardown(destroy=60.0, after=0.0)
    assert done.returncode == -signal.SIGKILL, (done.returncode, done.stdout, done.stderr)
    assert took < 60.0                        # not waited out: ended by the limit
    assert f'[teardown] pid {pid} still tearing down after 2 s of its own time' in done.stderr, done.stderr
    assert 'in destroy_node' in done.stderr, done.stderr     # where it was stuck
    assert 'ended with' not in done.stdout
    assert f'[teardown] pid {pid} still tearing down after 0.2 s; stopped' in done.stderr, done.stderr
    if shutil.which('gdb'):                   # every thread's native frames, numbered by gdb
        assert re.search(r'^Thread 1 .*\n#0 ', done.stderr, re.M), done.stderr
    else:
        assert '[teardown] no gdb on this machine' in done.stderr, done.stderr


def test_the_time_stopped_for_native_stacks_does_not_count_against_the_limit(tmp_path):
    """gdb can hold a slow teardown (e.g. in Fast DDS's ``destroy_participant``) for over a
    second; a wall-clock limit, running on meanwhile, would end it once gdb let go. Here a
    gdb that takes 3 s (a stand-in on PATH) holds a teardown of 1 s (limit 2 s, stacks at
    0.2 s): the teardown gets the rest of its limit after the stop and ends cleanly."""
    slow_gdb = tmp_path / 'gdb'
    slow_gdb.write_text('#!/bin/sh\necho "[slow gdb] reading"\nsleep 3\n')
    slow_gdb.chmod(0o755)
    env = dict(os.environ, PATH=f'{tmp_path}{os.pathsep}{os.environ["PATH"]}')
    done, took, pid = _run_teardown(destroy=1.0, after=0.0, env=env)
    assert done.returncode == 0, (done.returncode, done.stdout, done.stderr)
    assert 'ended with 0' in done.stdout
    assert f'[teardown] pid {pid} still tearing down after 0.2 s; stopped' in done.stderr, done.stderr
    assert '[slow gdb] reading' in done.stderr, done.stderr
    assert 'of its own time' not in done.stderr and 'Timeout' not in done.stderr, done.stderr
    assert took >= 3.0                        # it was held for the stand-in's 3 s
    assert _watchers_of(pid) == []


def test_the_teardown_watcher_leaves_the_nodes_scheduling_class():
    """A node run SCHED_FIFO (the demo's under load) must not hand that class to the watcher
    and its gdb. Checked from a SCHED_BATCH parent, which needs no privilege: the watcher
    runs SCHED_OTHER (without ``chrt -o`` in its script it stays SCHED_BATCH)."""
    from grip_force_ros.lab.node_process import stop_watch, watch_own_teardown
    from grip_force_ros.lab.processes import wait_until

    parent = os.sched_getscheduler(0), os.sched_getparam(0)
    os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    try:
        watch = watch_own_teardown(60.0, 60.0)
    finally:
        os.sched_setscheduler(0, *parent)
    assert watch is not None
    pid = watch.process.pid
    try:
        assert wait_until(lambda: os.sched_getscheduler(pid) == os.SCHED_OTHER, 30.0, 0.05), \
            os.sched_getscheduler(pid)
        assert len(_watchers_of(os.getpid())) == 1          # the helper sees a live one
    finally:
        stop_watch(watch)
    assert watch.process.returncode is not None and _watchers_of(os.getpid()) == []


def test_a_teardown_goes_on_without_its_watcher_where_none_can_start(monkeypatch):
    """No temporary file (a full /tmp) or no ``sh``: no watcher, and no exception out of the
    teardown's ``finally`` (which would skip the node's destruction)."""
    from grip_force_ros.lab import node_process

    def no_file():
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr(node_process.tempfile, 'TemporaryFile', no_file)
    assert node_process.watch_own_teardown(60.0, 60.0) is None
    end_guard = node_process.watched_teardown(60.0)      # the node's own limit instead
    end_guard()
    monkeypatch.undo()
    monkeypatch.setenv('PATH', '/nonexistent')
    assert node_process.watch_own_teardown(60.0, 60.0) is None
    node_process.stop_watch(None)


@pytest.mark.parametrize('watched', [True, False])
def test_a_teardown_within_the_limit_leaves_no_timer_behind(watched):
    """``run_node`` also runs inside test processes: the limit must not outlive the teardown,
    nor must the watcher of its native stacks (nor its ``sleep``)."""
    done, _, pid = _run_teardown(destroy=0.0, after=2.5, watched=watched)
    assert done.returncode == 0, (done.returncode, done.stdout, done.stderr)
    assert 'ended with 0' in done.stdout
    assert 'Timeout' not in done.stderr, done.stderr
    assert '[teardown]' not in done.stderr, done.stderr     # alive 2.5 s past the 2 s limit
    assert _watchers_of(pid) == []


def test_the_laboratory_knows_the_nodes_stack_signal():
    """The process harness asks a hung node for its stacks with the signal ``run_node`` catches."""
    from grip_force_ros.lab import node_process
    assert node_process.STACK_DUMP_SIGNAL == lifetime.STACK_DUMP_SIGNAL
