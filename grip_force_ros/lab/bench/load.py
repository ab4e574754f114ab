"""A bounded CPU load: N busy processes for T seconds, stopped for sure.

What a lab workstation does to the suite: another job keeps every core busy. ``stress
-c N`` would do, but it is not on every machine and it outlives a test run that dies;
this one is bounded three ways:

* each worker stops by itself at its deadline (``seconds``, checked at least every
  :data:`DUTY_PERIOD`), so a forgotten generator ends anyway;
* each worker stops when its parent is gone (Linux ``PR_SET_PDEATHSIG`` = SIGKILL,
  and the same check of ``getppid`` where that is not available),
  so it never outlives the process that started it, however that one ends;
* :meth:`LoadGenerator.stop` (or the end of a ``with`` block, or this process's exit)
  kills the workers at once.

Workers are plain Python busy loops at normal priority (they compete for the cores as
another user's job would), ``duty`` of every :data:`DUTY_PERIOD` busy, the rest asleep.

Used by ``grip-force load`` (``./dev load --seconds 600``), the suite's ``--with-load``
option (test/conftest.py) and ``grip-force loadcheck`` (:mod:`.loadcheck`). The disk and
memory pressure beside it is :mod:`.pressure` (``--kind disk``, ``--kind both``).
"""
from __future__ import annotations

import atexit
import os
import signal
import subprocess
import sys
import time

from grip_force_ros.lab.processes import end_with_parent

#: Longest a full-duty worker runs on without checking its deadline and its parent (s).
CHECK_PERIOD = 0.05
#: Period of the busy/sleep cycle of a worker below full duty (s; also its longest
#: time between two checks).
DUTY_PERIOD = 0.1
#: Bounds of a generator: workers, seconds.
MAX_WORKERS = 64
MAX_SECONDS = 24 * 3600.0


class LoadError(ValueError):
    """A load generator asked for more than its bounds, or with nonsense values."""


def worker(seconds: float, parent: int, duty: float = 1.0) -> int:
    """Run one busy worker until ``seconds`` have passed or ``parent`` is gone.

    Parameters
    ----------
    seconds : float
        Run time (s).
    parent : int
        Process id of the parent; the worker ends when its parent changes.
    duty : float
        Share of each :data:`DUTY_PERIOD` spent busy (0 < duty <= 1).

    Returns
    -------
    int
        Number of busy-loop iterations (a measure of the work done).
    """
    end_with_parent(signal.SIGKILL)
    deadline = time.monotonic() + seconds
    busy = CHECK_PERIOD if duty >= 1.0 else duty * DUTY_PERIOD
    rest = 0.0 if duty >= 1.0 else (1.0 - duty) * DUTY_PERIOD
    n = 0
    x = 1.0
    while True:
        now = time.monotonic()
        if now >= deadline or os.getppid() != parent:
            return n
        busy_end = now + busy
        while time.monotonic() < busy_end:
            for _ in range(2000):
                x = x * 1.0000001 + 1e-9   # floating-point work, no allocation
            n += 1
        if rest:
            time.sleep(rest)


class LoadGenerator:
    """``workers`` busy processes for ``seconds`` (see the module docstring).

    Parameters
    ----------
    workers : int, optional
        Busy processes (default: one per core, ``os.cpu_count()``).
    seconds : float
        Hard stop of every worker (s), counted from :meth:`start`.
    duty : float
        Busy share of each worker, 0 < duty <= 1 (1: a full core each, as ``stress -c``).

    Raises
    ------
    LoadError
        Workers or seconds beyond :data:`MAX_WORKERS` / :data:`MAX_SECONDS`, or not positive.
    """

    def __init__(self, workers: int | None = None, seconds: float = 600.0, duty: float = 1.0):
        workers = (os.cpu_count() or 1) if workers is None else int(workers)
        if not 1 <= workers <= MAX_WORKERS:
            raise LoadError(f'workers {workers} outside [1, {MAX_WORKERS}]')
        if not 0.0 < seconds <= MAX_SECONDS:
            raise LoadError(f'seconds {seconds!r} outside (0, {MAX_SECONDS:g}]')
        if not 0.0 < duty <= 1.0:
            raise LoadError(f'duty {duty!r} outside (0, 1]')
        self.workers = workers
        self.seconds = float(seconds)
        self.duty = float(duty)
        self.procs: list[subprocess.Popen] = []
        self.started = None          # time.monotonic() at start
        self.load_before = None      # 1-minute load average at start
        self._cpu0 = 0.0
        self.last_summary = None     # what :meth:`stop` returned last

    def start(self) -> 'LoadGenerator':
        """Start the workers (returns self)."""
        if self.procs:
            return self
        self.load_before = os.getloadavg()[0]
        self._cpu0 = _children_cpu()
        cmd = [sys.executable, '-m', 'grip_force_ros.lab.bench.load', '--worker',
               '--seconds', repr(self.seconds), '--parent', str(os.getpid()),
               '--duty', repr(self.duty)]
        for _ in range(self.workers):
            self.procs.append(subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        self.started = time.monotonic()
        atexit.register(self.stop)
        return self

    def running(self) -> int:
        """Count the workers still running."""
        return sum(p.poll() is None for p in self.procs)

    def stop(self) -> dict:
        """Kill the workers now; return what ran (see :meth:`summary`)."""
        for p in self.procs:
            if p.poll() is None:
                p.kill()
        for p in self.procs:
            p.wait()
        summary = self.summary()
        self.procs = []
        self.last_summary = summary
        try:
            atexit.unregister(self.stop)
        except Exception:  # noqa: BLE001 - nothing registered
            pass
        return summary

    def summary(self) -> dict:
        """Kind ('cpu'), workers, duty, the wall time so far (s), the CPU the finished workers used (s)."""
        wall = time.monotonic() - self.started if self.started is not None else 0.0
        return {'kind': 'cpu', 'workers': self.workers, 'duty': self.duty, 'seconds_limit': self.seconds,
                'wall_s': round(wall, 2), 'worker_cpu_s': round(_children_cpu() - self._cpu0, 2),
                'load_average_before': self.load_before,
                'load_average_now': round(os.getloadavg()[0], 2)}

    def __enter__(self) -> 'LoadGenerator':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _children_cpu() -> float:
    """User + system CPU time (s) of this process's finished (waited-for) children."""
    t = os.times()
    return t.children_user + t.children_system


def main(argv: list[str] | None = None) -> int:
    """Worker entry point (``python -m grip_force_ros.lab.bench.load --worker ...``)."""
    import argparse
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--worker', action='store_true', required=True)
    parser.add_argument('--seconds', type=float, required=True)
    parser.add_argument('--parent', type=int, required=True)
    parser.add_argument('--duty', type=float, default=1.0)
    args = parser.parse_args(argv)
    seconds = min(max(args.seconds, 0.0), MAX_SECONDS)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    worker(seconds, args.parent, min(max(args.duty, 1e-3), 1.0))
    return 0


if __name__ == '__main__':
    sys.exit(main())
