"""Real-time hygiene of a 1 kHz node process, as ros2_control's realtime_tools does it.

The ROS 2 real-time working group's guidance for a loop process, in what it means for a
Python process (docs/ros_interface.md, "Real-time settings", gives what each measure
bought, measured):

* :func:`lock_memory`: ``mlockall(MCL_CURRENT | MCL_FUTURE)``, so that no page of the
  process (its code, the interpreter, the middleware's libraries, its heap) is paged out
  and read back from disk while the loop waits; where not permitted the reason is returned.
* :func:`prefault`: the heap glibc hands out (``malloc``: the middleware, numpy buffers,
  Python objects above 512 B) grown and touched before the loop starts, and kept
  (``mallopt``: no trimming, no ``mmap`` per allocation), and the main thread's C stack,
  where the executor runs the callbacks, grown and touched. Python's own small-object
  arenas are ``mmap``-ed by the interpreter itself and not affected; with the memory locked
  (``MCL_FUTURE``) every new page is faulted in when it is mapped, not when first used.
* :func:`set_affinity`: every thread of the process pinned to the given CPUs.
* :class:`LoopLog`: a log line from the loop's callbacks goes through a bounded queue that
  never blocks; a background thread hands it to the node's logger (rclpy's logger costs
  ~250 µs a call, throttled or not: it looks up its caller's source line first).

:func:`prepare` applies what the node's 'realtime' parameters ask (params/realtime.py) and
says in one INFO line what was applied; ``run_node`` calls it right before the spin, and
:func:`finish` at its teardown. Nothing here is needed by, or imports, the laboratory.
"""
from __future__ import annotations

import ctypes
import errno
import os
import resource
import sys
import threading
import time
import weakref
from collections import deque
from typing import Any, Iterable

#: ``mlockall`` flags (<sys/mman.h>): the pages mapped now, and every page mapped later.
MCL_CURRENT = 1
MCL_FUTURE = 2
#: ``mallopt`` parameters (<malloc.h>): the free memory at the top of the heap above which
#: glibc gives it back to the kernel, and the number of allocations it may ``mmap``.
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: Linux capability that exempts a process from RLIMIT_MEMLOCK (<linux/capability.h>).
CAP_IPC_LOCK = 14
#: A finite RLIMIT_MEMLOCK must be at least this many times what the process maps now: with
#: ``MCL_FUTURE``, a mapping past the limit fails, and an allocation of the running node
#: would fail with it.
LOCK_HEADROOM = 2.0
#: Stack the loop's callbacks may use, touched before the spin (bytes); a callback's C stack
#: (the executor, the middleware's callback, the interpreter) measured ~2 KiB per nested
#: Python call entered from C.
STACK_BYTES = 512 * 1024
#: Heap grown, touched and kept before the spin (bytes): far above what a period allocates.
HEAP_BYTES = 16 * 1024 * 1024
#: Longest nesting used to touch the stack (calls entered from C; each counts twice against
#: Python's recursion limit, 1000 by default, which bounds it further).
STACK_DEPTH_MAX = 800

_WHAT_TO_DO = ('raise the limit of locked memory (ulimit -l unlimited, or memlock in '
               '/etc/security/limits.conf, or LimitMEMLOCK=infinity in a systemd unit) or '
               'grant the process CAP_IPC_LOCK')
_LEVELS = ('debug', 'info', 'warning', 'error', 'fatal')


class RealtimeError(ValueError):
    """A real-time setting cannot be applied as given (e.g. a CPU id the machine lacks)."""


def _libc() -> ctypes.CDLL:
    """Return the C library of this process (its ``mlockall``, ``mallopt``, ``malloc``, ``free``)."""
    return ctypes.CDLL(None, use_errno=True)


def _status(field: str) -> str | None:
    """Return one field of /proc/self/status (e.g. 'VmRSS') as text; None where there is none."""
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith(field + ':'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return None


def _status_bytes(field: str) -> int:
    """Return a ``kB`` field of /proc/self/status in bytes (0 where there is none)."""
    text = _status(field)
    return int(text.split()[0]) * 1024 if text else 0


def has_lock_privilege() -> bool:
    """Tell whether this process holds CAP_IPC_LOCK (RLIMIT_MEMLOCK does not apply to it)."""
    text = _status('CapEff')
    return bool(text) and bool(int(text, 16) >> CAP_IPC_LOCK & 1)


def lock_memory() -> str | None:
    """Lock every page of the process, mapped now and later, in RAM (``mlockall``).

    Buys: no major page fault on the loop's path; a page of the interpreter, of the
    middleware's libraries or of the heap is never evicted and read back from disk while
    the loop waits for it (on a busy disk, tens of ms). The process's
    resident memory grows to what it maps (thread stacks included).

    Not attempted where RLIMIT_MEMLOCK is finite and below :data:`LOCK_HEADROOM` times what
    the process maps, without CAP_IPC_LOCK: the lock could succeed now and make a later
    allocation of the running node fail. A limit of 0 is tried, for the kernel's own word.

    Returns
    -------
    str or None
        None when locked; else why not (the errno text where ``mlockall`` failed, the limit
        and the mapped size (KiB, MiB) otherwise) and what to do.
    """
    soft, _hard = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    if soft not in (0, resource.RLIM_INFINITY) and not has_lock_privilege():
        mapped = _status_bytes('VmSize')
        if soft < LOCK_HEADROOM * mapped:
            return (f'RLIMIT_MEMLOCK is {soft // 1024} KiB, below {LOCK_HEADROOM:g} x the '
                    f'{mapped / 2 ** 20:.0f} MiB this process maps, and no CAP_IPC_LOCK; '
                    + _WHAT_TO_DO)
    libc = _libc()
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        return (f'mlockall failed: {os.strerror(err)} ({errno.errorcode.get(err, err)}; '
                f'RLIMIT_MEMLOCK {_limit_text(soft)}); ' + _WHAT_TO_DO)
    return None


def _limit_text(limit: int) -> str:
    return 'unlimited' if limit == resource.RLIM_INFINITY else f'{limit // 1024} KiB'


def keep_heap() -> bool:
    """Make glibc keep the heap it has: no trimming, no ``mmap`` per large allocation.

    Buys: memory freed by the loop is reused from the heap instead of going back to the
    kernel and being faulted in again at the next allocation (``mallopt(M_TRIM_THRESHOLD,
    -1)``, ``mallopt(M_MMAP_MAX, 0)``, as the ROS 2 real-time guidance does). The heap does
    not shrink after a peak.

    Returns
    -------
    bool
        Whether glibc took both settings (False on a C library without ``mallopt``).
    """
    try:
        mallopt = _libc().mallopt
    except AttributeError:      # not glibc
        return False
    return bool(mallopt(M_TRIM_THRESHOLD, -1)) and bool(mallopt(M_MMAP_MAX, 0))


_DESCENT = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int)


def _descend_py(depth: int) -> int:
    return 0 if depth <= 0 else _descend(depth - 1) + 1


#: Each level is a Python call entered from C (a ctypes callback): it uses C stack, which
#: a plain Python call (3.11) does not.
_descend = _DESCENT(_descend_py)


def _python_depth() -> int:
    """Return the number of Python frames on the calling thread's stack."""
    frame, depth = sys._getframe(1), 0
    while frame is not None:
        frame, depth = frame.f_back, depth + 1
    return depth


def prefault(stack_bytes: int = STACK_BYTES, heap_bytes: int = HEAP_BYTES) -> dict[str, int]:
    """Grow and touch the stack and the heap the loop will use, before it starts.

    Buys: the first periods of the loop do not pay the page faults of a stack or heap
    growing under them (a minor fault each 4 KiB page; with the memory locked they come
    when the memory is mapped, here). The heap part first makes glibc keep what it has
    (:func:`keep_heap`), then allocates ``heap_bytes``, writes every page and frees it back
    to the heap. The stack part nests calls on the calling thread (the executor's, in
    ``run_node``) until its stack has grown by ``stack_bytes`` (or :data:`STACK_DEPTH_MAX`
    calls).

    Parameters
    ----------
    stack_bytes : int
        Stack to touch below the current depth (bytes); 0: none.
    heap_bytes : int
        Heap to grow, touch and keep (bytes); 0: none.

    Returns
    -------
    dict
        ``stack_bytes``: how much the main thread's stack grew (bytes, /proc VmStk; 0 off
        the main thread or where it had grown before), ``heap_bytes``: the heap touched
        (bytes), ``heap_kept``: whether glibc keeps it (:func:`keep_heap`).
    """
    if stack_bytes < 0 or heap_bytes < 0:
        raise RealtimeError(f'prefault: sizes must be >= 0 bytes, got stack {stack_bytes}, '
                            f'heap {heap_bytes}')
    kept = keep_heap() if heap_bytes else False
    touched = 0
    if heap_bytes:
        libc = _libc()
        libc.malloc.restype = ctypes.c_void_p
        libc.malloc.argtypes = (ctypes.c_size_t,)
        libc.free.argtypes = (ctypes.c_void_p,)
        block = libc.malloc(heap_bytes)
        if block:
            ctypes.memset(block, 0, heap_bytes)
            libc.free(block)
            touched = heap_bytes
    before = _status_bytes('VmStk')
    # each level counts twice against the recursion limit (the callback and its function)
    cap = min(STACK_DEPTH_MAX, (sys.getrecursionlimit() - _python_depth()) // 2 - 50)
    depth = min(cap, max(64, stack_bytes // 2048))
    while stack_bytes and depth > 0:
        _descend(depth)
        if _status_bytes('VmStk') - before >= stack_bytes or depth >= cap:
            break
        depth = min(cap, 2 * depth)
    return {'stack_bytes': max(0, _status_bytes('VmStk') - before), 'heap_bytes': touched,
            'heap_kept': kept}


def set_affinity(cpus: Iterable[int]) -> frozenset[int] | None:
    """Pin every thread of this process to ``cpus`` (``sched_setaffinity``).

    Buys: the loop's process stays on CPUs the user keeps for it (no migration, no other
    process's cache), e.g. the controller alone on one core. Threads started later inherit
    the mask of the thread that starts them, all pinned here.

    Parameters
    ----------
    cpus : iterable of int
        CPU ids (0-based); empty: no pinning, nothing changes.

    Returns
    -------
    frozenset of int or None
        The CPUs the process now runs on; None when ``cpus`` is empty.

    Raises
    ------
    RealtimeError
        An id that is not an integer, negative, or one this process may not run on (not
        on the machine, or outside its cpuset), naming the CPUs it may run on.
    """
    wanted = list(cpus)
    if not wanted:
        return None
    bad = [c for c in wanted if isinstance(c, bool) or not isinstance(c, int) or c < 0]
    if bad:
        raise RealtimeError(f'cpu_affinity: {bad} are not CPU ids (integers >= 0)')
    allowed = _allowed_cpus()
    missing = sorted(set(wanted) - allowed)
    if missing:
        raise RealtimeError(f'cpu_affinity: CPU {missing} not available to this process; it '
                            f'may run on {sorted(allowed)}')
    for tid in _threads():
        try:
            os.sched_setaffinity(tid, wanted)
        except ProcessLookupError:      # the thread ended meanwhile
            continue
        except OSError as exc:
            raise RealtimeError(f'cpu_affinity {wanted}: {exc.strerror}') from None
    return frozenset(os.sched_getaffinity(0))


def _allowed_cpus() -> set[int]:
    """Return the CPU ids this process may run on (/proc Cpus_allowed_list; else its mask)."""
    text = _status('Cpus_allowed_list')
    if not text:
        return set(os.sched_getaffinity(0))
    out: set[int] = set()
    for part in text.split(','):
        first, _, last = part.partition('-')
        out.update(range(int(first), int(last or first) + 1))
    return out


def _threads() -> list[int]:
    """Return the thread ids of this process (/proc/self/task; else the calling thread, 0)."""
    try:
        return [int(t) for t in os.listdir('/proc/self/task')]
    except OSError:
        return [0]


def page_faults() -> tuple[int, int]:
    """Return the page faults of this process so far: (minor, major) (counts, ``getrusage``)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_minflt, usage.ru_majflt


class LoopLog:
    """A log for the loop's callbacks: :meth:`put` never blocks; a thread does the logging.

    Buys: the rclpy logger's work (~250 µs a call on this machine, throttled or not: the
    call-site lookup, /rosout, the write) leaves the loop's callback; :meth:`put` costs
    ~1 µs, a throttled or dropped line less. A burst of lines is cut at ``capacity``
    instead of stalling the loop. Lines are delivered in the order put, within ``poll`` s;
    the thread yields the interpreter lock between two lines. rclpy holds that lock while
    its logger writes, so a write that blocks (a full stderr pipe nobody reads) still holds
    up the loop's Python for that long: give the node's output to a reader that keeps up (a
    file, ``ros2 launch``).

    Parameters
    ----------
    logger : object
        Anything with ``debug``/``info``/``warning``/``error``/``fatal(text)``: the node's
        ``get_logger()``.
    capacity : int
        Lines the queue holds (lines); a line put while it is full is dropped and counted.
    poll : float
        Interval at which the thread hands the lines to ``logger`` (s).
    drop_report_interval : float
        Dropped lines are reported as one warning at most this often (s).
    """

    def __init__(self, logger, capacity: int = 256, poll: float = 0.02,
                 drop_report_interval: float = 1.0):
        if capacity < 1 or poll <= 0.0:
            raise RealtimeError(f'LoopLog: capacity {capacity} lines must be >= 1 and poll '
                                f'{poll} s > 0')
        self.logger = logger
        self.capacity = capacity
        self.dropped = 0                  # lines put while the queue was full
        self._reported = 0                # of them, already reported
        self._report_at = 0.0             # monotonic s of the last drop report
        self._drop_interval = drop_report_interval
        self._lines: deque[tuple[str, str]] = deque()
        self._last_put: dict[Any, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=_serve, args=(weakref.ref(self), self._stop, poll),
                                        name='loop-log', daemon=True)
        self._thread.start()

    def put(self, level: str, text: str, throttle: float = 0.0) -> bool:
        """Queue one line; never blocks, never raises for a full queue.

        Parameters
        ----------
        level : str
            'debug', 'info', 'warning', 'error' or 'fatal'.
        text : str
            The line.
        throttle : float
            At most one line per this interval from the calling line of code (s), as
            rclpy's ``throttle_duration_sec``; 0: every line.

        Returns
        -------
        bool
            Whether the line was queued (False: throttled, or dropped with the queue full).
        """
        if level not in _LEVELS:
            raise RealtimeError(f'LoopLog: level {level!r} is not one of {list(_LEVELS)}')
        if throttle > 0.0:
            caller = sys._getframe(1)
            site = (caller.f_code, caller.f_lineno)
            now = time.monotonic()
            last = self._last_put.get(site)
            if last is not None and now - last < throttle:
                return False
            self._last_put[site] = now
        if len(self._lines) >= self.capacity:
            self.dropped += 1
            return False
        self._lines.append((level, text))
        return True

    def flush(self) -> None:
        """Hand every queued line to the logger, and report lines dropped since the last report."""
        while True:
            try:
                level, text = self._lines.popleft()
            except IndexError:
                break
            getattr(self.logger, level)(text)
            time.sleep(0)     # the interpreter lock to the loop between two lines
        dropped = self.dropped
        now = time.monotonic()
        if dropped > self._reported and (now - self._report_at >= self._drop_interval
                                         or self._stop.is_set()):
            self.logger.warning(f'{dropped - self._reported} log line(s) of the loop dropped '
                                f'(queue of {self.capacity} full); {dropped} in all')
            self._reported, self._report_at = dropped, now

    def close(self, timeout: float = 0.5) -> None:
        """Stop the thread after it has logged what is queued (waits at most ``timeout`` s)."""
        self._stop.set()
        self._thread.join(timeout)
        if not self._thread.is_alive():
            self.flush()


def _serve(ref, stop: threading.Event, poll: float) -> None:
    """Thread of a :class:`LoopLog`: flush every ``poll`` s until stopped or the log is gone."""
    while not stop.wait(poll):
        log = ref()
        if log is None:
            return
        try:
            log.flush()
        except Exception as exc:  # noqa: BLE001 - a failing logger must not end the thread
            print(f'loop log: {exc!r}', file=sys.stderr)
        del log


_ATTRIBUTE = '_realtime_loop_log'


def loop_log(node) -> LoopLog:
    """Return the :class:`LoopLog` of ``node`` (its logger), made at the first call."""
    log = getattr(node, _ATTRIBUTE, None)
    if log is None:
        log = LoopLog(node.get_logger())
        setattr(node, _ATTRIBUTE, log)
    return log


def prepare(node) -> str | None:
    """Apply ``node``'s 'realtime' parameters to this process; one INFO line says what.

    In this order: the CPU affinity (``cpu_affinity``), then with ``lock_memory`` the
    heap kept, the memory locked (a WARN line with the reason where not permitted; the
    node goes on unlocked) and the stack and heap pre-faulted; then the node's
    :class:`LoopLog` is started. A node that does not declare the group is left alone.

    Parameters
    ----------
    node : rclpy.node.Node
        The node about to spin in this process, from the process's main thread.

    Returns
    -------
    str or None
        The INFO line logged; None for a node without the 'realtime' parameters.

    Raises
    ------
    RealtimeError
        ``cpu_affinity`` names a CPU this process may not run on.
    """
    if not node.has_parameter('lock_memory'):
        return None
    log = node.get_logger()
    started = time.monotonic()
    cpus = set_affinity(tuple(node.get_parameter('cpu_affinity').value))
    parts = [f'CPUs {sorted(cpus)}' if cpus is not None else 'no CPU affinity']
    if node.get_parameter('lock_memory').value:
        rss = _status_bytes('VmRSS')
        why = lock_memory()
        done = prefault()
        if why is None:
            parts.append(f'memory locked (RSS {rss / 2 ** 20:.0f} -> '
                         f'{_status_bytes("VmRSS") / 2 ** 20:.0f} MiB)')
        else:
            log.warning(f'memory not locked: {why}')
            parts.append('memory not locked (see the warning)')
        parts.append(f"pre-faulted {done['stack_bytes'] // 1024} KiB of stack and "
                     f"{done['heap_bytes'] // 2 ** 20} MiB of heap"
                     + (', heap kept' if done['heap_kept'] else ''))
    else:
        parts.append('memory not locked (lock_memory false)')
    loop_log(node)
    line = f'real-time: {", ".join(parts)} ({time.monotonic() - started:.2f} s)'
    log.info(line)
    return line


def finish(node) -> None:
    """Stop ``node``'s :class:`LoopLog` (if it has one) after it has logged what is queued."""
    log = getattr(node, _ATTRIBUTE, None)
    if log is not None:
        log.close()
