"""A bounded disk-and-memory pressure: fsync writers, a page-cache evictor, a memory hog.

What a freshly started machine does to the loop: its disk is busy (``top``
shows 100 % I/O wait) and a node that waits for a page of its own code or of a shared
library to come back from disk stalls, real-time priority or not. This generator makes
that happen on purpose, beside the CPU load of :mod:`.load`:

* **writers** (``writers`` processes): each writes one file of ``file_mb`` MB in a
  temporary directory in 1 MB chunks, ``fsync`` every ``fsync_mb`` MB and at the end of
  the file, then rewrites it from its start, over and over, at most ``rate_mb_s`` MB/s
  each (:data:`DEFAULT_RATE_MB_S`; None: as fast as the disk takes them, which on a VM
  whose virtual disk absorbs GB/s makes each writer a core of kernel copying, a CPU load);
* **an evictor** (``evict_rate`` files a second, 0 = none): drops the package's own
  files (the ``grip_force_ros`` tree, the venv's ``rclpy`` and every shared library of
  its site-packages and its ``lib``) from the page cache with
  ``posix_fadvise(POSIX_FADV_DONTNEED)``, file after file, in a loop, so the nodes'
  next page faults go to the busy disk; pages mapped by a running process are not
  dropped (the kernel keeps them), the rest are. With ``drop_caches=True`` (asked for
  explicitly, and only where ``/proc/sys/vm/drop_caches`` is writable) it also writes
  ``1`` there (the whole page cache) at most every :data:`DROP_CACHES_PERIOD`;
* **a memory hog** (``memory_mb`` MB, 0 = none): allocates and touches that much memory
  for :data:`MEMORY_HOLD` s, releases it for :data:`MEMORY_REST` s, and again.

Bounded the ways :class:`~.load.LoadGenerator` is, and in size:

* every child stops by itself at its deadline (``seconds``) and when its parent is gone
  (Linux ``PR_SET_PDEATHSIG`` = SIGTERM, and a check of ``getppid`` between two chunks);
* the files on disk never exceed ``writers * file_mb`` MB (one file per writer), at most
  :data:`MAX_TOTAL_MB` and half the free space of the file system; memory at most
  :data:`MAX_MEMORY_MB` and half of what the machine has available;
* every child removes its own files when it ends, however it ends short of SIGKILL (its
  deadline, SIGTERM or SIGINT, its parent's death, an exception);
  :meth:`DiskPressure.stop` (or the end of a ``with`` block, or this process's exit)
  stops the children, SIGKILLs any that did not end within :data:`STOP_GRACE`, and
  removes the directory whatever is left in it.

Each child reports what it did (bytes written, fsyncs, files evicted, bytes touched, its
run time) as one JSON line on its stdout when it ends; :meth:`DiskPressure.stop` returns
their sum as a dict (:meth:`DiskPressure.summary`).

Used by ``grip-force load --kind disk`` (``./dev load --kind disk --seconds 600``), the
suite's ``--with-load --load-kind disk`` (test/conftest.py), ``grip-force loadcheck --kind
disk``, ``grip-force bench --pressure disk`` and ``grip-force demo --pressure disk``;
:func:`make_pressure` builds the generator of a kind (``cpu``, ``disk``, ``both``,
``none``) for them.
"""
from __future__ import annotations

import atexit
import json
import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

from grip_force_ros.lab.bench.load import MAX_SECONDS, LoadError, LoadGenerator
from grip_force_ros.lab.processes import end_with_parent

#: Size of one write (bytes).
CHUNK = 1 << 20
#: Bytes in one MB of the options (the writers' file size, the memory, the rates).
MB = 1 << 20
#: Bounds of a generator: writers, one writer's file (MB), every writer's files (MB),
#: the memory hog (MB), the evictor's rate (files/s).
MAX_WRITERS = 16
MAX_FILE_MB = 4096
MAX_TOTAL_MB = 8192
MAX_MEMORY_MB = 16384
MAX_EVICT_RATE = 100_000.0
#: Most files the evictor takes in (the package tree, rclpy and the shared libraries).
MAX_EVICT_FILES = 20_000
#: Shortest time between two writes of ``1`` to /proc/sys/vm/drop_caches (s).
DROP_CACHES_PERIOD = 5.0
#: The memory hog holds its memory this long, then rests this long (s).
MEMORY_HOLD = 2.0
MEMORY_REST = 1.0
#: Longest sleep of a child between two checks of its deadline, its parent and a stop (s).
TICK = 0.05
#: How long :meth:`DiskPressure.stop` lets a child clean up after SIGTERM before SIGKILL (s).
STOP_GRACE = 10.0
#: Longest :meth:`DiskPressure.start` waits for its children to be ready (s).
READY_TIMEOUT = 15.0
#: A child's first line to its parent: its stop handlers are in place.
READY = 'ready'
#: Name prefix of the generator's temporary directory.
DIR_PREFIX = 'grip_force_pressure-'
#: The page size the memory hog touches at (bytes).
PAGE = os.sysconf('SC_PAGE_SIZE') if hasattr(os, 'sysconf') else 4096
DROP_CACHES = Path('/proc/sys/vm/drop_caches')
KINDS = ('cpu', 'disk', 'both', 'none')


class PressureError(LoadError):
    """A pressure generator asked for more than its bounds, or with nonsense values."""


# ---------------------------------------------------------------- the children
class _Child:
    """A child's stop condition: its deadline, its parent, SIGTERM/SIGINT."""

    def __init__(self, seconds: float, parent: int):
        self.started = time.monotonic()
        self.deadline = self.started + seconds
        self.parent = parent
        self.signalled = None
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        end_with_parent(signal.SIGTERM)     # after the handler: the signal becomes a clean stop

    def _on_signal(self, signum, _frame) -> None:
        self.signalled = signal.Signals(signum).name

    def parent_alive(self) -> bool:
        """Tell whether the process that started this child still is its parent."""
        return os.getppid() == self.parent

    def done(self) -> bool:
        """Tell whether the child should end now (deadline, signal or parent gone)."""
        return (self.signalled is not None or time.monotonic() >= self.deadline
                or not self.parent_alive())

    def why(self) -> str:
        """Say why the child ended."""
        if self.signalled is not None:
            return self.signalled
        if not self.parent_alive():
            return 'parent gone'
        return 'deadline' if time.monotonic() >= self.deadline else 'error'

    def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` (s) or until :meth:`done`, whichever comes first."""
        end = time.monotonic() + seconds
        while not self.done():
            left = end - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, TICK))


def write_loop(child: _Child, directory: Path, file_bytes: int, fsync_bytes: int,
               rate_bytes_s: float | None) -> dict:
    """Write, fsync and rewrite one file of ``file_bytes`` in ``directory`` until ``child`` is done.

    Parameters
    ----------
    child : _Child
        The stop condition.
    directory : Path
        The writer's own directory (created, and removed when it ends).
    file_bytes : int
        Size of the file (bytes); the file never grows beyond it.
    fsync_bytes : int
        Bytes written between two ``fsync`` (bytes); one more at the end of each pass.
    rate_bytes_s : float or None
        Most bytes written a second (bytes/s); None: as fast as the disk takes them.

    Returns
    -------
    dict
        ``bytes_written`` (bytes), ``fsyncs``, ``passes`` (whole files written),
        ``largest_file_bytes`` (bytes).
    """
    out = {'bytes_written': 0, 'fsyncs': 0, 'passes': 0, 'largest_file_bytes': 0}
    data = os.urandom(CHUNK)        # incompressible, so the storage cannot skip it
    directory.mkdir(parents=True, exist_ok=True)
    fd = os.open(directory / 'data.bin', os.O_WRONLY | os.O_CREAT, 0o600)
    begun = time.monotonic()
    try:
        while not child.done():
            os.lseek(fd, 0, os.SEEK_SET)
            pos = unsynced = 0
            while pos < file_bytes and not child.done():
                n = os.write(fd, data[:min(CHUNK, file_bytes - pos)])
                pos += n
                unsynced += n
                out['bytes_written'] += n
                out['largest_file_bytes'] = max(out['largest_file_bytes'], pos)
                if unsynced >= fsync_bytes:
                    os.fsync(fd)
                    out['fsyncs'] += 1
                    unsynced = 0
                if rate_bytes_s:
                    ahead = out['bytes_written'] / rate_bytes_s - (time.monotonic() - begun)
                    if ahead > 0:
                        child.sleep(ahead)
            if unsynced:
                os.fsync(fd)
                out['fsyncs'] += 1
            if pos >= file_bytes:
                out['passes'] += 1
    finally:
        os.close(fd)
    return out


def evict_targets(limit: int = MAX_EVICT_FILES) -> list[Path]:
    """List the files the evictor drops from the page cache, at most ``limit`` of them.

    The ``grip_force_ros`` package tree, the ``rclpy`` package of this interpreter (found
    without importing it) and every shared library (``*.so*``) of its site-packages and of
    its prefix's ``lib`` folder (where the venv keeps librcl and the DDS libraries).
    """
    import importlib.util

    roots: list[tuple[Path, str]] = [(Path(__file__).resolve().parents[2], '*')]
    spec = importlib.util.find_spec('rclpy')
    if spec is not None and spec.submodule_search_locations:
        roots += [(Path(p), '*') for p in spec.submodule_search_locations]
    for key in ('purelib', 'platlib'):
        roots.append((Path(sysconfig.get_paths()[key]), '*.so*'))
    files: list[Path] = []
    seen: set = set()
    for root, pattern in roots:
        if root.is_dir():
            files += _files_under(root.rglob(pattern), seen, limit - len(files))
    lib = Path(sys.prefix) / 'lib'
    if lib.is_dir():
        files += _files_under(lib.glob('*.so*'), seen, limit - len(files))
    return files


def _files_under(paths, seen: set, room: int) -> list[Path]:
    out = []
    for path in paths:
        if len(out) >= room:
            break
        try:
            real = path.resolve()
            if real in seen or not real.is_file():
                continue
        except OSError:
            continue
        seen.add(real)
        out.append(real)
    return out


def _drop_caches() -> str | None:
    """Write ``1`` to /proc/sys/vm/drop_caches; None when done, else why not."""
    try:
        with open(DROP_CACHES, 'w') as fh:
            fh.write('1\n')
        return None
    except OSError as exc:
        return f'{type(exc).__name__}: {exc.strerror or exc}'


def evict_loop(child: _Child, rate: float, drop_caches: bool = False,
               targets: list[Path] | None = None) -> dict:
    """Drop ``targets`` from the page cache at ``rate`` files a second until ``child`` is done.

    Parameters
    ----------
    child : _Child
        The stop condition.
    rate : float
        Files evicted a second (1/s).
    drop_caches : bool
        Also write ``1`` to /proc/sys/vm/drop_caches, at most every :data:`DROP_CACHES_PERIOD`,
        where it is writable (the first refusal ends the attempts).
    targets : list of Path, optional
        Default :func:`evict_targets`.

    Returns
    -------
    dict
        ``files_evicted``, ``bytes_evicted`` (bytes: the sizes of the files advised),
        ``evict_refused`` (files that could not be opened or advised), ``evict_targets``,
        ``evict_passes`` (whole passes over the targets), ``drop_caches`` (writes done),
        ``drop_caches_refused`` (why not, or None).
    """
    targets = evict_targets() if targets is None else targets
    out = {'files_evicted': 0, 'bytes_evicted': 0, 'evict_refused': 0,
           'evict_targets': len(targets), 'evict_passes': 0, 'drop_caches': 0,
           'drop_caches_refused': None}
    if not targets and not drop_caches:
        child.sleep(child.deadline - time.monotonic())
        return out
    batch = max(1, int(round(rate * TICK)))
    period = batch / rate
    next_batch = time.monotonic()
    last_drop = -float('inf')
    k = 0
    while not child.done():
        if drop_caches and out['drop_caches_refused'] is None \
                and time.monotonic() - last_drop >= DROP_CACHES_PERIOD:
            out['drop_caches_refused'] = _drop_caches()
            out['drop_caches'] += out['drop_caches_refused'] is None
            last_drop = time.monotonic()
        for _ in range(batch if targets else 0):
            path = targets[k]
            k = (k + 1) % len(targets)
            out['evict_passes'] += k == 0
            try:
                fd = os.open(path, os.O_RDONLY | getattr(os, 'O_NOATIME', 0))
            except OSError:
                try:
                    fd = os.open(path, os.O_RDONLY)
                except OSError:
                    out['evict_refused'] += 1
                    continue
            try:
                os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
                out['files_evicted'] += 1
                out['bytes_evicted'] += os.fstat(fd).st_size
            except OSError:
                out['evict_refused'] += 1
            finally:
                os.close(fd)
        next_batch += period
        child.sleep(next_batch - time.monotonic())
        next_batch = max(next_batch, time.monotonic() - period)   # no burst after a stall
    return out


def memory_loop(child: _Child, memory_bytes: int, hold: float = MEMORY_HOLD,
                rest: float = MEMORY_REST) -> dict:
    """Allocate and touch ``memory_bytes``, hold, release, rest, until ``child`` is done.

    Parameters
    ----------
    child : _Child
        The stop condition.
    memory_bytes : int
        Memory allocated and touched at once (bytes), in blocks of 64 MB at most.
    hold, rest : float
        How long the memory is held, then left free (s).

    Returns
    -------
    dict
        ``memory_touched_bytes`` (bytes, over every cycle), ``memory_cycles``,
        ``memory_peak_bytes`` (bytes held at once).
    """
    block = min(64 * MB, max(PAGE, memory_bytes))
    ones = b'\x01' * len(range(0, block, PAGE))
    out = {'memory_touched_bytes': 0, 'memory_cycles': 0, 'memory_peak_bytes': 0}
    while not child.done():
        held: list = []
        size = 0
        while size < memory_bytes and not child.done():
            n = min(block, memory_bytes - size)
            block_buf = bytearray(n)
            block_buf[::PAGE] = ones[:len(range(0, n, PAGE))]     # one write a page: resident
            held.append(block_buf)
            del block_buf
            size += n
            out['memory_touched_bytes'] += n
        out['memory_peak_bytes'] = max(out['memory_peak_bytes'], size)
        child.sleep(hold)
        held.clear()        # every block freed (each is its own mapping: back to the system)
        out['memory_cycles'] += 1
        child.sleep(rest)
    return out


def child_main(role: str, seconds: float, parent: int, directory: Path, options: dict) -> dict:
    """Run one child of the generator (``role``: writer, evictor or memory), return its report.

    The child's own directory (``directory``) is removed when it ends, and the
    generator's directory (its parent folder) too when it is empty by then (the last
    child out removes it: nothing is left when the generator's parent was killed).
    """
    child = _Child(seconds, parent)
    _say(READY)         # its signal handlers are in place: a stop from now on cleans up
    report = {'role': role, 'pid': os.getpid()}
    try:
        if child.done():
            result = {}
        elif role == 'writer':
            result = write_loop(child, directory, int(options['file_bytes']),
                                int(options['fsync_bytes']), options.get('rate_bytes_s'))
        elif role == 'evictor':
            result = evict_loop(child, float(options['rate']), bool(options.get('drop_caches')),
                                targets=None if options.get('evict_files', True) else [])
        elif role == 'memory':
            result = memory_loop(child, int(options['memory_bytes']))
        else:
            raise PressureError(f'unknown role {role!r}')
        report.update(result)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, then cleaned up
        report['error'] = f'{type(exc).__name__}: {exc}'
    finally:
        shutil.rmtree(directory, ignore_errors=True)
        try:
            directory.parent.rmdir()
        except OSError:
            pass
    report['ended_by'] = child.why() if 'error' not in report else 'error'
    report['seconds'] = round(time.monotonic() - child.started, 3)
    return report


# ---------------------------------------------------------------- the generator
def _available_memory_bytes() -> int | None:
    try:
        with open('/proc/meminfo') as fh:
            for line in fh:
                if line.startswith('MemAvailable:'):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


#: Default cap of each writer (MB/s): a disk kept busy with fsyncs, not the CPU. Measured on
#: this package's 2-core VM: two unbounded writers wrote 4.6 GB/s (331 GB in 71 s, 557
#: fsyncs/s) into a virtual disk with a host cache, two cores of kernel copying.
DEFAULT_RATE_MB_S = 64.0


class DiskPressure:
    """Writers that fsync, a page-cache evictor, a memory hog (see the module docstring).

    Parameters
    ----------
    writers : int
        Writer processes (0 = none).
    seconds : float
        Hard stop of every child (s), counted from :meth:`start`.
    file_mb : float
        Size of each writer's file (MB), rewritten in a loop.
    fsync_mb : float
        MB written between two ``fsync`` of a writer (MB).
    rate_mb_s : float or None
        Most MB each writer writes a second (MB/s; default :data:`DEFAULT_RATE_MB_S`);
        None: as fast as the disk takes them.
    evict_rate : float
        Files the evictor drops from the page cache a second (1/s; 0 = no evictor).
    drop_caches : bool
        The evictor also writes ``1`` to /proc/sys/vm/drop_caches where that is writable
        (the whole machine's page cache: only when asked).
    memory_mb : float
        Memory the hog allocates, touches and releases in a loop (MB; 0 = no hog).
    directory : str or Path, optional
        Where the generator's temporary directory goes (default: the system's temporary
        folder, ``$TMPDIR``).

    Raises
    ------
    PressureError
        A value beyond :data:`MAX_WRITERS`, :data:`MAX_FILE_MB`, :data:`MAX_TOTAL_MB`,
        :data:`MAX_MEMORY_MB`, :data:`MAX_EVICT_RATE`, :data:`~.load.MAX_SECONDS`, more
        than half the free disk space or half the available memory, or nothing to do.
    """

    kind = 'disk'

    def __init__(self, writers: int = 2, seconds: float = 600.0, file_mb: float = 256.0,
                 fsync_mb: float = 8.0, rate_mb_s: float | None = DEFAULT_RATE_MB_S,
                 evict_rate: float = 500.0,
                 drop_caches: bool = False, memory_mb: float = 0.0,
                 directory: str | Path | None = None):
        writers = int(writers)
        if not 0 <= writers <= MAX_WRITERS:
            raise PressureError(f'writers {writers} outside [0, {MAX_WRITERS}]')
        if not 0.0 < seconds <= MAX_SECONDS:
            raise PressureError(f'seconds {seconds!r} outside (0, {MAX_SECONDS:g}]')
        if writers and not 0.0 < file_mb <= MAX_FILE_MB:
            raise PressureError(f'file_mb {file_mb!r} outside (0, {MAX_FILE_MB}]')
        if writers * file_mb > MAX_TOTAL_MB:
            raise PressureError(f'{writers} writers x {file_mb:g} MB > {MAX_TOTAL_MB} MB')
        if not fsync_mb > 0.0:
            raise PressureError(f'fsync_mb {fsync_mb!r} must be > 0')
        if rate_mb_s is not None and not rate_mb_s > 0.0:
            raise PressureError(f'rate_mb_s {rate_mb_s!r} must be > 0')
        if not 0.0 <= evict_rate <= MAX_EVICT_RATE:
            raise PressureError(f'evict_rate {evict_rate!r} outside [0, {MAX_EVICT_RATE:g}]')
        if not 0.0 <= memory_mb <= MAX_MEMORY_MB:
            raise PressureError(f'memory_mb {memory_mb!r} outside [0, {MAX_MEMORY_MB}]')
        if not (writers or evict_rate or memory_mb or drop_caches):
            raise PressureError('nothing to do: no writer, no evictor, no memory')
        available = _available_memory_bytes()
        if memory_mb and available is not None and memory_mb * MB > available / 2:
            raise PressureError(f'memory_mb {memory_mb:g} > half the available memory '
                                f'({available / MB / 2:.0f} MB)')
        self.base = Path(directory) if directory is not None else Path(tempfile.gettempdir())
        if writers:
            free = shutil.disk_usage(self.base).free
            if writers * file_mb * MB > free / 2:
                raise PressureError(f'{writers} x {file_mb:g} MB > half the free space of '
                                    f'{self.base} ({free / MB / 2:.0f} MB)')
        self.writers = writers
        self.seconds = float(seconds)
        self.file_mb = float(file_mb)
        self.fsync_mb = float(fsync_mb)
        self.rate_mb_s = rate_mb_s
        self.evict_rate = float(evict_rate)
        self.drop_caches = bool(drop_caches)
        self.memory_mb = float(memory_mb)
        self.directory: Path | None = None
        self.procs: list[tuple[str, subprocess.Popen]] = []
        self.reports: list[dict] = []
        self.started = None
        self.wall = None
        self.load_before = None
        self.last_summary: dict | None = None
        self.not_ready: list[str] = []

    @property
    def bytes_limit(self) -> int:
        """Most bytes the writers' files hold at once (bytes)."""
        return self.writers * int(self.file_mb * MB)

    def _roles(self) -> list[tuple[str, dict]]:
        roles = [('writer', {'file_bytes': int(self.file_mb * MB),
                             'fsync_bytes': max(1, int(self.fsync_mb * MB)),
                             'rate_bytes_s': self.rate_mb_s * MB if self.rate_mb_s else None})
                 for _ in range(self.writers)]
        if self.evict_rate or self.drop_caches:
            roles.append(('evictor', {'rate': self.evict_rate or 1.0, 'drop_caches': self.drop_caches,
                                      'evict_files': bool(self.evict_rate)}))
        if self.memory_mb:
            roles.append(('memory', {'memory_bytes': int(self.memory_mb * MB)}))
        return roles

    def start(self) -> 'DiskPressure':
        """Start the children (returns self)."""
        if self.procs:
            return self
        self.reports = []
        self.load_before = os.getloadavg()[0]
        self.directory = Path(tempfile.mkdtemp(prefix=DIR_PREFIX, dir=self.base))
        atexit.register(self.stop)
        for k, (role, options) in enumerate(self._roles()):
            cmd = [sys.executable, '-m', 'grip_force_ros.lab.bench.pressure', '--role', role,
                   '--seconds', repr(self.seconds), '--parent', str(os.getpid()),
                   '--dir', str(self.directory / f'{role}{k}'), '--options', json.dumps(options)]
            self.procs.append((role, subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                                                      stdout=subprocess.PIPE,
                                                      stderr=subprocess.DEVNULL)))
        self.not_ready = self._wait_ready()
        self.started = time.monotonic()
        self.wall = None
        return self

    def _wait_ready(self) -> list[str]:
        """Wait for every child's :data:`READY` line (at most :data:`READY_TIMEOUT`).

        Returns the roles of the children that did not say it in time (they run on; a
        stop before their handlers are in place ends them with nothing to clean up).
        """
        import select
        waiting = {p.stdout.fileno(): (role, p) for role, p in self.procs}
        end = time.monotonic() + READY_TIMEOUT
        while waiting and time.monotonic() < end:
            ready, _, _ = select.select(list(waiting), [], [], max(0.0, end - time.monotonic()))
            for fd in ready:
                waiting.pop(fd)[1].stdout.readline()   # READY, or nothing: it ended (its stop reports it)
        return [role for role, _ in waiting.values()]

    def running(self) -> int:
        """Count the children still running."""
        return sum(p.poll() is None for _, p in self.procs)

    def stop(self) -> dict:
        """Stop the children, remove every file; return what ran (see :meth:`summary`)."""
        if not self.procs:          # never started, or stopped already
            return self.last_summary if self.last_summary is not None else self.summary()
        for _, p in self.procs:
            if p.poll() is None:
                try:
                    p.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
        end = time.monotonic() + STOP_GRACE
        for role, p in self.procs:
            try:
                out, _ = p.communicate(timeout=max(0.1, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                out, _ = p.communicate()
            self.reports.append(_report(role, p, out))
        if self.started is not None:
            self.wall = time.monotonic() - self.started
        if self.directory is not None:
            shutil.rmtree(self.directory, ignore_errors=True)
        summary = self.summary()
        self.procs = []
        try:
            atexit.unregister(self.stop)
        except Exception:  # noqa: BLE001 - nothing registered
            pass
        self.last_summary = summary
        return summary

    def summary(self) -> dict:
        """Sum up what ran over the children (their reports come in at :meth:`stop`).

        Returns
        -------
        dict
            ``kind`` ('disk'); the bounds (``writers``, ``file_mb``, ``bytes_limit`` [bytes],
            ``evict_rate`` [1/s], ``memory_mb``, ``seconds_limit`` [s]); ``wall_s`` (s);
            ``bytes_written`` (bytes), ``fsyncs``, ``passes``, ``largest_file_bytes``
            (bytes), ``files_evicted``, ``bytes_evicted`` (bytes), ``evict_refused``,
            ``evict_targets``, ``drop_caches``, ``drop_caches_refused``,
            ``memory_touched_bytes`` (bytes), ``memory_cycles``; ``children`` (each child's
            report: role, seconds, why it ended); ``not_ready`` (the roles of children not
            ready within :data:`READY_TIMEOUT` of the start); ``directory`` and ``cleaned``
            (whether it is gone); the 1-minute load average before and now.
        """
        if self.wall is not None:
            wall = self.wall
        else:
            wall = time.monotonic() - self.started if self.started is not None else 0.0
        total = {'bytes_written': 0, 'fsyncs': 0, 'passes': 0, 'largest_file_bytes': 0,
                 'files_evicted': 0, 'bytes_evicted': 0, 'evict_refused': 0, 'evict_targets': 0,
                 'evict_passes': 0, 'drop_caches': 0, 'drop_caches_refused': None,
                 'memory_touched_bytes': 0, 'memory_cycles': 0, 'memory_peak_bytes': 0}
        for r in self.reports:
            for key, value in r.items():
                if key not in total or value is None:
                    continue
                if key in ('largest_file_bytes', 'memory_peak_bytes'):
                    total[key] = max(total[key], value)
                elif key == 'drop_caches_refused':
                    total[key] = value
                else:
                    total[key] += value
        return {'kind': self.kind, 'writers': self.writers, 'file_mb': self.file_mb,
                'fsync_mb': self.fsync_mb, 'rate_mb_s': self.rate_mb_s,
                'bytes_limit': self.bytes_limit, 'evict_rate': self.evict_rate,
                'drop_caches_asked': self.drop_caches, 'memory_mb': self.memory_mb,
                'seconds_limit': self.seconds, 'wall_s': round(wall, 2), **total,
                'children': [{k: r.get(k) for k in ('role', 'seconds', 'ended_by', 'error')
                              if r.get(k) is not None} for r in self.reports],
                'not_ready': list(self.not_ready),
                'directory': str(self.directory) if self.directory is not None else None,
                'cleaned': self.directory is None or not self.directory.exists(),
                'load_average_before': self.load_before,
                'load_average_now': round(os.getloadavg()[0], 2)}

    def __enter__(self) -> 'DiskPressure':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _report(role: str, proc: subprocess.Popen, out: bytes | None) -> dict:
    """Read a child's JSON report from its stdout (its last line)."""
    lines = (out or b'').decode(errors='replace').strip().splitlines()
    try:
        report = json.loads(lines[-1])
    except (IndexError, ValueError):
        report = {'role': role, 'error': f'no report (exit code {proc.returncode})'}
    return report


class _NoPressure:
    """The ``none`` kind: a generator that runs nothing."""

    kind = 'none'

    def __init__(self):
        self.last_summary = {'kind': 'none'}

    def start(self) -> '_NoPressure':
        return self

    def running(self) -> int:
        return 0

    def stop(self) -> dict:
        return self.last_summary

    def summary(self) -> dict:
        return self.last_summary

    def __enter__(self) -> '_NoPressure':
        return self

    def __exit__(self, *exc) -> None:
        pass


class PressureSet:
    """Several generators started and stopped together (the ``both`` kind: CPU and disk).

    Parameters
    ----------
    generators : dict
        Name ('cpu', 'disk') -> generator with ``start``, ``running``, ``stop``.
    """

    def __init__(self, generators: dict):
        self.generators = dict(generators)
        self.kind = '+'.join(self.generators) if len(self.generators) != 2 else 'both'
        self.last_summary: dict | None = None

    def start(self) -> 'PressureSet':
        """Start every generator (returns self); stop those started when one fails."""
        started = []
        try:
            for g in self.generators.values():
                g.start()
                started.append(g)
        except BaseException:
            for g in started:
                g.stop()
            raise
        return self

    def running(self) -> int:
        """Count the child processes still running, over every generator."""
        return sum(g.running() for g in self.generators.values())

    def stop(self) -> dict:
        """Stop every generator; their summaries under their names, with ``kind``."""
        summary: dict = {'kind': self.kind}
        for name, g in self.generators.items():
            summary[name] = g.stop()
        self.last_summary = summary
        return summary

    def __enter__(self) -> 'PressureSet':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def make_pressure(kind: str, seconds: float = 600.0, workers: int | None = None,
                  duty: float = 1.0, **disk_options):
    """Build the generator of one kind of pressure (not started).

    Parameters
    ----------
    kind : str
        'cpu' (a :class:`~.load.LoadGenerator`), 'disk' (a :class:`DiskPressure`), 'both'
        (the two, a :class:`PressureSet`) or 'none' (a generator that runs nothing).
    seconds : float
        Hard stop of every child (s).
    workers, duty
        Of the CPU load (default: one busy process per core, full duty).
    **disk_options
        Of :class:`DiskPressure` (``writers``, ``file_mb``, ``evict_rate``, ``memory_mb``, ...).

    Returns
    -------
    object
        A context manager with ``start()``, ``running()``, ``stop() -> dict`` and, after
        :meth:`stop`, ``last_summary`` (for :class:`~.load.LoadGenerator`: the return of
        its ``stop``).

    Raises
    ------
    PressureError
        An unknown kind; :class:`~.load.LoadError` or :class:`PressureError` for values
        beyond the bounds.
    """
    if kind not in KINDS:
        raise PressureError(f'unknown pressure kind {kind!r}; choose from {", ".join(KINDS)}')
    if kind == 'none':
        return _NoPressure()
    if kind == 'cpu':
        return LoadGenerator(workers, seconds=seconds, duty=duty)
    disk = DiskPressure(seconds=seconds, **disk_options)
    if kind == 'disk':
        return disk
    return PressureSet({'cpu': LoadGenerator(workers, seconds=seconds, duty=duty), 'disk': disk})


def describe(generator) -> str:
    """Say in one line what a generator of :func:`make_pressure` runs."""
    if isinstance(generator, PressureSet):
        return '; '.join(describe(g) for g in generator.generators.values())
    if isinstance(generator, LoadGenerator):
        return f'cpu: {generator.workers} busy process(es) at duty {generator.duty:g}'
    if isinstance(generator, DiskPressure):
        parts = []
        if generator.writers:
            rate = f', at most {generator.rate_mb_s:g} MB/s each' if generator.rate_mb_s else ''
            parts.append(f'{generator.writers} writer(s) of {generator.file_mb:g} MB with fsync '
                         f'every {generator.fsync_mb:g} MB{rate}')
        if generator.evict_rate:
            parts.append(f'evicting {generator.evict_rate:g} files/s of the package from the '
                         'page cache')
        if generator.drop_caches:
            parts.append('drop_caches where writable')
        if generator.memory_mb:
            parts.append(f'{generator.memory_mb:g} MB of memory touched and released')
        return 'disk: ' + ', '.join(parts)
    return 'no pressure'


def main(argv: list[str] | None = None) -> int:
    """Child entry point (``python -m grip_force_ros.lab.bench.pressure --role ...``)."""
    import argparse
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--role', choices=('writer', 'evictor', 'memory'), required=True)
    parser.add_argument('--seconds', type=float, required=True)
    parser.add_argument('--parent', type=int, required=True)
    parser.add_argument('--dir', type=Path, required=True)
    parser.add_argument('--options', default='{}')
    args = parser.parse_args(argv)
    seconds = min(max(args.seconds, 0.0), MAX_SECONDS)
    options = json.loads(args.options)
    report = child_main(args.role, seconds, args.parent, args.dir, options)
    _say(json.dumps(report))
    return 0


def _say(line: str) -> None:
    """Write one line to the parent (stdout, unbuffered); nothing when nobody reads it."""
    try:
        os.write(1, (line + '\n').encode())
    except OSError:     # the parent is gone
        pass


if __name__ == '__main__':
    sys.exit(main())
