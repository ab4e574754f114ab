"""Speed and memory of the diagnosis on a long log (numpy only, no rclpy).

The log (default 1 h at 1 kHz, the CSV contract of :mod:`grip_force_ros.logs`)
is built once by :func:`grip_force_ros.diagnosis.bench.build_long_log` (simulated
minutes with an unmodelled effect, stitched with continuous time) and cached in
``<tmp>/grip_force_bench/``. Two child processes then time, on a warm page cache:

* ``load``: :func:`grip_force_ros.logs.read_log` (the whole log at full rate);
* ``diagnose``: :func:`grip_force_ros.diagnosis.engine.diagnose` on the path (what
  ``grip-force diagnose`` runs: streamed, decimated, fitted);

each reporting its wall time and peak resident memory (``ru_maxrss``, its own
process only). The figure of merit is ``load_ratio = diagnose / load`` (goal <= 5).

Child entry: ``python -m grip_force_ros.bench.diagnosis_speed load|diagnose PATH``.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Bumped when the generator changes, so a cached log is rebuilt.
LOG_VERSION = 1


def cache_dir() -> Path:
    """Where the generated logs are kept between runs."""
    return Path(tempfile.gettempdir()) / 'grip_force_bench'


def ensure_log(minutes: float, directory: Path | None = None) -> tuple[Path, float]:
    """Return the cached ``minutes`` long 1 kHz CSV log, built if missing.

    Returns
    -------
    path : Path
    build_seconds : float
        Time spent building it now (0 when it was cached).
    """
    from grip_force_ros.diagnosis.bench import build_long_log

    directory = Path(directory) if directory is not None else cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f'log_{minutes:g}min_v{LOG_VERSION}.csv'
    if path.exists():
        return path, 0.0
    t0 = time.perf_counter()
    partial = directory / f'.{path.name}.{os.getpid()}.partial'
    build_long_log(partial, minutes)
    partial.replace(path)        # atomic: a concurrent run never reads half a log
    return path, time.perf_counter() - t0


def _rss_mb() -> float:
    """Peak resident memory of this process so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _child(task: str, path: str) -> dict:
    """Run one task here and return its figures (called in a child process)."""
    from grip_force_ros.diagnosis.engine import diagnose
    from grip_force_ros.logs import read_log
    before = _rss_mb()
    t0 = time.perf_counter()
    if task == 'load':
        log = read_log(path)
        extra = {'rows': int(log['t'].size), 'columns': len(log)}
    else:
        result = diagnose([path])
        extra = {'verdict': result['verdict']['effect']}
    seconds = time.perf_counter() - t0
    return {'task': task, 'seconds': seconds, 'rss_before_mb': before, 'peak_rss_mb': _rss_mb(),
            **extra}


def _run_child(task: str, path: Path, timeout: float) -> dict:
    proc = subprocess.run([sys.executable, '-m', __name__, task, str(path)], capture_output=True,
                          text=True, timeout=timeout)
    lines = [line for line in proc.stdout.splitlines() if line.startswith('{')]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f'diagnosis bench child {task!r} failed ({proc.returncode}):\n'
                           + proc.stderr[-2000:])
    return json.loads(lines[-1])


def warm_page_cache(path: Path) -> None:
    """Read the file once so both timings start from the same (cached) state."""
    with open(path, 'rb') as fh:
        while fh.read(1 << 24):
            pass


def run_diagnosis_speed(minutes: float = 60.0, directory: Path | None = None,
                        timeout: float = 1800.0) -> dict:
    """Measure the ``diagnosis`` section of the bench.

    Parameters
    ----------
    minutes : float
        Length of the log at 1 kHz (min).
    directory : Path, optional
        Cache directory of the generated log (default :func:`cache_dir`).
    timeout : float
        Longest wait for each child (s).

    Returns
    -------
    dict
        ``load_ratio`` (-), ``load_s``, ``diagnose_s`` (s), ``rows``, ``file_mb``,
        ``load_peak_mb``, ``diagnose_peak_mb`` (peak RSS of each child, MB),
        ``diagnose_added_mb`` (peak minus the child's RSS before the work),
        ``build_s`` (0 when cached), ``verdict``, ``path``.
    """
    path, build_s = ensure_log(minutes, directory)
    warm_page_cache(path)
    load = _run_child('load', path, timeout)
    diag = _run_child('diagnose', path, timeout)
    return {'load_ratio': diag['seconds'] / load['seconds'],
            'load_s': load['seconds'], 'diagnose_s': diag['seconds'],
            'minutes': minutes, 'rows': load['rows'], 'file_mb': path.stat().st_size / 1e6,
            'load_peak_mb': load['peak_rss_mb'], 'diagnose_peak_mb': diag['peak_rss_mb'],
            'diagnose_added_mb': diag['peak_rss_mb'] - diag['rss_before_mb'],
            'build_s': build_s, 'verdict': diag['verdict'], 'path': str(path),
            'goals': {'load_ratio': 5.0}}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2 or argv[0] not in ('load', 'diagnose'):
        print('usage: python -m grip_force_ros.bench.diagnosis_speed load|diagnose PATH', file=sys.stderr)
        return 2
    print(json.dumps(_child(argv[0], argv[1])), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
