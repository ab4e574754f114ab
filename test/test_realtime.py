"""Real-time hygiene of the node processes (grip_force_ros/nodes/realtime.py).

Plain pytest for the mechanism (the loop's log queue, memory locking, pre-faulting, CPU
affinity); what changes the process (a lock, an affinity) runs in a child process. One
in-process node test checks that the 'realtime' parameters are declared with descriptors.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from grip_force_ros.nodes import realtime
from grip_force_ros.nodes.realtime import LoopLog, RealtimeError, set_affinity
from grip_force_ros.params import SPECS, ParameterError, make_params

ROOT = Path(__file__).resolve().parents[1]
#: prctl(2) option that drops a capability from the bounding set (<linux/prctl.h>).
PR_CAPBSET_DROP = 24


class _Recorder:
    """A logger stand-in that keeps (level, text), optionally blocked until released."""

    def __init__(self, blocked: bool = False):
        self.lines: list[tuple[str, str]] = []
        self.release = threading.Event()
        if not blocked:
            self.release.set()

    def _log(self, level, text):
        self.release.wait(10.0)
        self.lines.append((level, text))

    def debug(self, text):
        self._log('debug', text)

    def info(self, text):
        self._log('info', text)

    def warning(self, text):
        self._log('warning', text)

    def error(self, text):
        self._log('error', text)

    def fatal(self, text):
        self._log('fatal', text)


def _wait(predicate, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


# ---------------------------------------------------------------- LoopLog
def test_loop_log_delivers_in_order():
    rec = _Recorder()
    log = LoopLog(rec, capacity=100, poll=0.005)
    try:
        for i in range(50):
            assert log.put('info' if i % 2 else 'warning', f'line {i}')
        assert _wait(lambda: len(rec.lines) == 50)
        assert rec.lines == [('info' if i % 2 else 'warning', f'line {i}') for i in range(50)]
        assert log.dropped == 0
    finally:
        log.close()


def test_loop_log_never_blocks_and_counts_what_it_drops():
    rec = _Recorder(blocked=True)          # the logger's write hangs
    log = LoopLog(rec, capacity=10, poll=0.005, drop_report_interval=0.0)
    try:
        assert log.put('warning', 'first')
        assert _wait(lambda: not log._lines)   # the thread took it and hangs in the logger
        started = time.perf_counter()
        queued = [log.put('warning', f'line {i}') for i in range(1000)]
        elapsed = time.perf_counter() - started
        assert elapsed < 0.5, f'1000 puts took {elapsed:.3f} s with the logger blocked'
        assert sum(queued) == 10 and queued[:10] == [True] * 10 and not any(queued[10:])
        assert log.dropped == 990
    finally:
        rec.release.set()
        log.close(timeout=5.0)
    texts = [t for _, t in rec.lines]
    assert texts[:11] == ['first'] + [f'line {i}' for i in range(10)]
    assert any('990 log line(s) of the loop dropped' in t and '990 in all' in t for t in texts)


def test_loop_log_throttles_per_call_site_and_checks_levels():
    rec = _Recorder()
    log = LoopLog(rec, poll=0.005)
    try:
        results = [log.put('warning', f'rejected {i}', throttle=10.0) for i in range(5)]
        assert results == [True, False, False, False, False]
        assert log.put('warning', 'another site', throttle=10.0)   # its own line of code
        assert log.dropped == 0                                    # throttled is not dropped
        with pytest.raises(RealtimeError):
            log.put('loud', 'x')
    finally:
        log.close()
    assert [t for _, t in rec.lines] == ['rejected 0', 'another site']


def test_loop_log_thread_ends_with_its_log():
    log = LoopLog(_Recorder(), poll=0.005)
    thread = log._thread
    del log
    thread.join(2.0)
    assert not thread.is_alive()


# ---------------------------------------------------------------- lock_memory, prefault
def _child(code: str, memlock_bytes: int | None = None, drop_lock_privilege: bool = False):
    """Run ``code`` in a child Python (RLIMIT_MEMLOCK set, CAP_IPC_LOCK dropped) -> its JSON."""
    def setup():
        if drop_lock_privilege and os.geteuid() == 0:
            import ctypes
            # root's capabilities after exec are its bounding set's: drop CAP_IPC_LOCK there
            ctypes.CDLL(None).prctl(PR_CAPBSET_DROP, realtime.CAP_IPC_LOCK, 0, 0, 0)
        if memlock_bytes is not None:
            resource.setrlimit(resource.RLIMIT_MEMLOCK, (memlock_bytes, memlock_bytes))
    run = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, preexec_fn=setup)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout.splitlines()[-1])


_LOCK = ('import json; from grip_force_ros.nodes import realtime as r; '
         'print(json.dumps([r.has_lock_privilege(), r.lock_memory()]))')


@pytest.mark.parametrize('limit', [0, 64 * 1024])
def test_lock_memory_says_why_when_not_permitted(limit):
    privileged, why = _child(_LOCK, memlock_bytes=limit, drop_lock_privilege=True)
    if privileged:
        pytest.skip('CAP_IPC_LOCK could not be dropped here')
    assert isinstance(why, str)
    assert 'ulimit -l' in why and 'CAP_IPC_LOCK' in why
    if limit == 0:       # the kernel's own word
        assert 'mlockall failed' in why and os.strerror(1) in why and 'EPERM' in why
    else:                # not attempted: a later allocation could fail
        assert 'RLIMIT_MEMLOCK is 64 KiB' in why


def test_lock_memory_and_prefault_where_permitted():
    soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if soft != resource.RLIM_INFINITY and not realtime.has_lock_privilege():
        pytest.skip('no CAP_IPC_LOCK and a finite RLIMIT_MEMLOCK here')
    code = ('import json; from grip_force_ros.nodes import realtime as r; '
            'why = r.lock_memory(); done = r.prefault(256 * 1024, 4 * 2 ** 20); '
            'locked = r._status_bytes("VmLck"); '
            'print(json.dumps([why, done, locked]))')
    why, done, locked = _child(code)
    assert why is None
    assert locked > 0
    assert done['heap_bytes'] == 4 * 2 ** 20 and done['heap_kept']
    assert done['stack_bytes'] >= 256 * 1024


def test_prefault_refuses_negative_sizes():
    with pytest.raises(RealtimeError):
        realtime.prefault(-1, 0)
    assert issubclass(RealtimeError, ValueError)


# ---------------------------------------------------------------- set_affinity
def test_set_affinity_validates_ids():
    assert set_affinity([]) is None                       # empty: nothing changes
    for bad in ([-1], [True], ['0'], [1.0]):
        with pytest.raises(RealtimeError, match='not CPU ids'):
            set_affinity(bad)
    with pytest.raises(RealtimeError, match='not available to this process'):
        set_affinity([100000])


def test_set_affinity_pins_every_thread():
    cpu = min(os.sched_getaffinity(0))
    code = ('import json, os, threading; from grip_force_ros.nodes import realtime as r; '
            'stop = threading.Event(); t = threading.Thread(target=stop.wait); t.start(); '
            f'got = r.set_affinity([{cpu}]); '
            'masks = [sorted(os.sched_getaffinity(int(tid))) '
            "for tid in os.listdir('/proc/self/task')]; stop.set(); t.join(); "
            'print(json.dumps([sorted(got), masks]))')
    got, masks = _child(code)
    assert got == [cpu]
    assert len(masks) >= 2 and all(m == [cpu] for m in masks)


# ---------------------------------------------------------------- parameters
def test_schema_declares_the_realtime_group_once():
    assert SPECS['lock_memory'].group == SPECS['cpu_affinity'].group == 'realtime'
    assert SPECS['lock_memory'].default is True and SPECS['cpu_affinity'].default == ()
    assert SPECS['lock_memory'].read_only and SPECS['cpu_affinity'].read_only
    assert make_params({'cpu_affinity': [0, 1]}).cpu_affinity == (0, 1)
    assert make_params({}).cpu_affinity == ()
    for bad in ([-1], [True], ['0'], [0.5], '0,1'):
        with pytest.raises(ParameterError, match='cpu_affinity'):
            make_params({'cpu_affinity': bad})


def test_the_1khz_nodes_declare_the_group():
    from grip_force_ros.nodes import controller, sim_instrument
    assert 'realtime' in controller.GROUPS and 'realtime' in sim_instrument.GROUPS


@pytest.mark.ros
def test_node_declares_realtime_parameters_with_descriptors():
    from rcl_interfaces.msg import ParameterType

    from grip_force_ros.lab.harness import RosRunner
    from grip_force_ros.nodes.master import MasterNode
    ros = RosRunner()
    ros.start()
    try:
        plain = ros.add(MasterNode)
        lock, cpus = plain.describe_parameters(['lock_memory', 'cpu_affinity'])
        assert lock.type == ParameterType.PARAMETER_BOOL and lock.read_only
        assert cpus.type == ParameterType.PARAMETER_INTEGER_ARRAY and cpus.read_only
        assert cpus.integer_range == [] and 'each element' in cpus.additional_constraints
        assert 'ulimit -l' in lock.description
        assert plain.get_parameter('lock_memory').value is True
        assert list(plain.get_parameter('cpu_affinity').value) == []
        assert plain.get_parameter('cpu_affinity').type_.name == 'INTEGER_ARRAY'
        allowed = sorted(os.sched_getaffinity(0))
        pinned = ros.add(MasterNode, lock_memory=False, cpu_affinity=allowed)
        assert list(pinned.get_parameter('cpu_affinity').value) == allowed
        # what run_node does before the spin (here nothing changes: all CPUs, no lock)
        line = realtime.prepare(pinned)
        assert line.startswith('real-time: CPUs') and 'lock_memory false' in line
        realtime.finish(pinned)
    finally:
        ros.stop()
