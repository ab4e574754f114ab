"""Child processes of the bench: their protocol lines and CPU time; an exclusive ROS domain.

A :class:`Child` is a :class:`~grip_force_ros.lab.processes.NodeProcess` (the
package's one way to start and stop a node process) whose stdout the bench reads.
No rclpy in this module (the parent never joins the DDS domain it measures).
"""
from __future__ import annotations

import os
import queue
import threading
import time
from typing import Sequence

import psutil

from grip_force_ros.lab.processes import NodeProcess, ProcessError, held_domains, realtime, reserve_domains


class BenchError(RuntimeError):
    """A bench part could not run (a child died, discovery failed, no free domain)."""


#: ROS domains the bench picks from when ROS_DOMAIN_ID is not set (Fast DDS: 0..232).
DEFAULT_DOMAINS = range(200, 233)


class DomainLock:
    """An exclusive ROS_DOMAIN_ID for one bench run.

    Held through :func:`grip_force_ros.lab.processes.reserve_domains` (a lock file
    per domain, the package's one way to hold a domain), so bench runs, test suites
    and demos on one machine never share a domain. When the environment sets
    ``ROS_DOMAIN_ID`` that domain is the only candidate (the user's choice, e.g. a CI
    job's own domain; a test suite's, which this process already holds, is used as
    it is); otherwise the first free one of ``candidates``.
    """

    def __init__(self, candidates: Sequence[int] | None = None):
        if candidates is None:
            env = os.environ.get('ROS_DOMAIN_ID')
            candidates = [int(env)] if env not in (None, '') else list(DEFAULT_DOMAINS)
        self.candidates = list(candidates)
        self.domain_id: int | None = None
        self._reservation = None

    def __enter__(self) -> int:
        own = [d for d in self.candidates if d in held_domains()]
        if len(self.candidates) == 1 and own:      # this process's own domain (a test's)
            self.domain_id = own[0]
            return self.domain_id
        try:
            self._reservation = reserve_domains(1, candidates=self.candidates)
        except ProcessError:
            raise BenchError(f'no free ROS domain among {self.candidates} '
                             '(other runs hold them, or their DDS ports are bound)') from None
        self.domain_id = self._reservation.domain_id
        return self.domain_id

    def __exit__(self, *exc) -> None:
        if self._reservation is not None:
            self._reservation.release()
            self._reservation = None


class Child(NodeProcess):
    """One child process whose stdout lines are read in the background, with its CPU time.

    Parameters
    ----------
    name : str
        Label for reports and errors.
    cmd : list of str
        Command line.
    env : dict
        Environment (see :func:`grip_force_ros.lab.processes.ros_environment`).
    rt_priority : int
        0, or the SCHED_FIFO priority of the child (:func:`realtime`).
    """

    def __init__(self, name: str, cmd: list[str], env: dict, rt_priority: int = 0):
        super().__init__(name, command=cmd, env=env, pipe=True,
                         preexec_fn=realtime(rt_priority) if rt_priority else None)
        self.lines: queue.Queue = queue.Queue()
        self.tail: list[str] = []
        self.ps = psutil.Process(self.pid)
        self._cpu0: float | None = None
        self._t0 = 0.0
        self.cpu_percent = float('nan')
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.popen.stdout:
            line = line.rstrip('\n')
            self.tail = (self.tail + [line])[-20:]
            self.lines.put(line)
        self.lines.put(None)

    def wait_line(self, accept, timeout: float) -> str:
        """Return the first stdout line for which ``accept(line)`` is true (BenchError on timeout/exit)."""
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise BenchError(f'{self.name}: timed out after {timeout:.0f} s; last output:\n'
                                 + '\n'.join(self.tail))
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                continue
            if line is None:
                raise BenchError(f'{self.name} exited (code {self.popen.wait()}); last output:\n'
                                 + '\n'.join(self.tail))
            if accept(line):
                return line

    def cpu_seconds(self) -> float:
        """User + system CPU time of the process so far (s)."""
        t = self.ps.cpu_times()
        return t.user + t.system

    def cpu_start(self) -> None:
        """Open the CPU measurement window."""
        self._cpu0, self._t0 = self.cpu_seconds(), time.monotonic()

    def cpu_stop(self) -> float:
        """Close the window: CPU used as a percentage of one core."""
        if self._cpu0 is not None and self.alive():
            wall = time.monotonic() - self._t0
            self.cpu_percent = 100.0 * (self.cpu_seconds() - self._cpu0) / wall if wall > 0 else float('nan')
        return self.cpu_percent


def stop_all(children: Sequence[Child]) -> None:
    """Stop children in reverse start order."""
    for child in reversed(list(children)):
        child.stop()
