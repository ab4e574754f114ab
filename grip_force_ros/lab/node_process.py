"""A node process as the laboratory runs it: its teardown watched, native stacks included. No rclpy.

A node's own teardown limit (:func:`grip_force_ros.nodes.lifetime.run_node`) writes Python
stacks, which cannot tell a Fast DDS deadlock from a slow teardown. :func:`install` replaces
that guard by :func:`watch_own_teardown`: every thread's native stack (gdb) when the teardown
runs long, then the Python stacks and SIGKILL at the limit, counted in the time the process
runs. The process harness (:mod:`grip_force_ros.lab.processes`) starts nodes through
:func:`main` (``python -m grip_force_ros.lab.node_process <node> [args]``); the benchmarks'
own nodes call :func:`install` before ``run_node``.

Also here, for the harness: libc's ``prctl`` (:data:`PRCTL`) and the node's stack signal.
"""
from __future__ import annotations

import fcntl
import importlib
import os
import signal
import subprocess
import sys
import tempfile
from typing import Any, Callable, NamedTuple, Sequence

#: The signal on which a node run by ``run_node`` writes its threads' Python stacks
#: (``grip_force_ros.nodes.lifetime.STACK_DUMP_SIGNAL``, named here without rclpy).
STACK_DUMP_SIGNAL = signal.SIGUSR1
#: Time given to a process to write its stacks before it is killed (s).
STACK_DUMP_WAIT = 0.3
#: Fraction of the teardown limit after which a teardown still running has its native
#: stacks written to stderr. The process is stopped while gdb starts and reads (seconds on a
#: loaded machine), which delays a teardown that would have ended, so it comes late: 3 s of
#: 4 s, 3.8 times the slowest teardown measured on a loaded machine (0.79 s).
NATIVE_STACKS_AT = 0.75


def _load_prctl() -> Callable[..., int] | None:
    try:
        import ctypes
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # not Linux
        return None


#: libc's ``prctl``, looked up here, in the parent: a child between ``fork`` and ``exec`` of
#: a parent with threads (DDS has several) must not ``dlopen``, whose lock another thread
#: may have held at the fork.
PRCTL = _load_prctl()


_PR_SET_PTRACER = 0x59616d61  # prctl option, <linux/prctl.h> (Yama)

#: The watcher of :func:`watch_own_teardown`: plain ``sh`` and ``gdb``, outside this process,
#: because a teardown stuck in C below Python may hold the GIL (no Python thread runs then).
#: It leaves the scheduling class it inherits (SCHED_FIFO for the demo's nodes under load) for
#: SCHED_OTHER first: gdb reading stacks for seconds must not outrank the machine's other work.
#: It stops the process (SIGSTOP) while gdb starts and reads and continues it after, then gives
#: it the rest of its limit: the limit counts the time the process runs, not the time gdb held
#: it (a wall-clock limit, running on while gdb read for over a second, would end a slow
#: teardown the moment gdb let go). A process still tearing down at the limit gets
#: STACK_DUMP_SIGNAL (its Python stacks, ``faulthandler``), then SIGKILL. A lock (``flock`` on
#: the process's temporary file ``$3``, opened anew through ``/proc``: a lock of its own, not
#: the process's) makes each of the watcher's steps on the process and the process's own end
#: of the watch (:func:`stop_watch`) exclude each other: a teardown that ends just then is never
#: left stopped, and ``[ -ef ]`` (the same file) makes sure a pid reused meanwhile is not hit.
#: Arguments: delay before the stacks (s), pid, fd of the lock file, rest of the limit (s), the
#: limit (s, for the message), the stack signal's number, the time to write stacks (s).
_TEARDOWN_WATCH = r'''exec 1>&2
chrt -o -p 0 $$ >/dev/null 2>&1
sleep "$1"
exec 9<"/proc/$2/fd/$3" 2>/dev/null || exit 0
flock -n 9 || exit 0
kill -STOP "$2" 2>/dev/null || exit 0
echo "[teardown] pid $2 still tearing down after $1 s; stopped for its native stacks (gdb):"
if command -v gdb >/dev/null 2>&1; then
  timeout 120 gdb -p "$2" -batch -nx -iex "set auto-load python-scripts off" -ex "thread apply all bt"
else
  echo "[teardown] no gdb on this machine"
fi
kill -CONT "$2"
flock -u 9
sleep "$4"
flock -n 9 || exit 0
[ "/proc/$2/fd/$3" -ef /dev/fd/9 ] || exit 0
echo "[teardown] pid $2 still tearing down after $5 s of its own time; its Python stacks, then SIGKILL:"
kill -"$6" "$2" 2>/dev/null || exit 0
sleep "$7"
kill -KILL "$2" 2>/dev/null'''


class TeardownWatch(NamedTuple):
    """A running :func:`watch_own_teardown` watcher and the lock it shares with this process."""

    process: subprocess.Popen
    lock: Any          # this process's temporary file, which the watcher locks while it has it stopped


def watch_own_teardown(after: float, limit: float) -> TeardownWatch | None:
    """Start a watcher of this process's teardown: native stacks at ``after`` s, an end at ``limit``.

    For a teardown that may hang in the middleware: ``faulthandler`` shows the Python
    frame (``destroy_node``), not where in Fast DDS it waits. The watcher sleeps ``after``
    s, then, if this process still runs and :func:`stop_watch` has not begun, stops it,
    attaches gdb (where installed), writes every thread's native stack to the stderr it
    shares with this process (the node's log) and continues it. It then waits the rest of
    ``limit``; a teardown still running then has its Python stacks written
    (:data:`STACK_DUMP_SIGNAL`) and is killed (SIGKILL): the time gdb held the process does
    not count. End it with :func:`stop_watch` once the teardown has ended.

    Parameters
    ----------
    after : float
        Delay (s) before the native stacks are taken.
    limit : float
        Time (s) the teardown may run, not counting the time stopped for gdb; not less than
        ``after``.

    Returns
    -------
    TeardownWatch or None
        The watcher (its own session), None where it cannot be started (no ``sh``, no
        temporary file): the teardown then goes on without it.
    """
    lock = None
    try:
        lock = tempfile.TemporaryFile()
        watcher = subprocess.Popen(['sh', '-c', _TEARDOWN_WATCH, 'teardown-watch', f'{after:g}',
                                    str(os.getpid()), str(lock.fileno()), f'{max(limit - after, 0.0):g}',
                                    f'{limit:g}', str(int(STACK_DUMP_SIGNAL)), f'{STACK_DUMP_WAIT:g}'],
                                   stdin=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        if lock is not None:
            lock.close()
        return None
    if PRCTL is not None:   # Yama ptrace_scope 1 lets only ancestors trace: name the watcher
        PRCTL(_PR_SET_PTRACER, watcher.pid, 0, 0, 0)
    return TeardownWatch(watcher, lock)


def stop_watch(watch: TeardownWatch | None) -> None:
    """End a :func:`watch_own_teardown` watcher and its ``sleep`` (its process group).

    Takes the watcher's lock first: a watcher that has this process stopped for gdb holds it
    until it has continued the process (and one ending it at the limit, until it is killed).
    """
    if watch is None:
        return
    fcntl.flock(watch.lock.fileno(), fcntl.LOCK_EX)
    try:
        os.killpg(watch.process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    watch.process.wait()
    watch.lock.close()
    if PRCTL is not None:   # no tracer named any more (the pid may be reused)
        PRCTL(_PR_SET_PTRACER, 0, 0, 0, 0)


def watched_teardown(limit: float) -> Callable[[], None]:
    """Return a teardown guard for ``run_node``: :func:`watch_own_teardown` of ``limit`` (s).

    Native stacks at :data:`NATIVE_STACKS_AT` of ``limit``; where no watcher can start, the
    node's own limit. The returned callable ends the guard.
    """
    watch = watch_own_teardown(NATIVE_STACKS_AT * limit, limit)
    if watch is None:
        from grip_force_ros.nodes import lifetime
        return lifetime.limit_teardown(limit)
    return lambda: stop_watch(watch)


def install() -> None:
    """Make ``run_node`` in this process guard its teardown with :func:`watched_teardown`."""
    from grip_force_ros.nodes import lifetime
    lifetime.teardown_guard = watched_teardown


def main(argv: Sequence[str] | None = None) -> int:
    """Run node executable ``argv[0]`` with the rest of ``argv`` as its command line.

    ``argv[0]`` is ``controller``, ``sim_instrument`` or ``master``; its teardown is watched
    (:func:`install`).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        print('usage: python -m grip_force_ros.lab.node_process NODE [ARGS...]', file=sys.stderr)
        return 2
    node = importlib.import_module(f'grip_force_ros.nodes.{argv[0]}')
    install()
    sys.argv = argv           # as its console script: rclpy reads the ROS arguments there
    return node.main()


if __name__ == '__main__':
    sys.exit(main())
