"""Speed and memory of the diagnosis on a long log (numpy only, no rclpy).

The log (default 1 h at 1 kHz, the CSV contract of :mod:`grip_force_ros.logs`)
is built once by :func:`build_long_log` (simulated minutes with an unmodelled
effect, stitched with continuous time) and cached in ``<tmp>/grip_force_bench/``.
Two child processes then time, on a warm page cache:

* ``load``: :func:`grip_force_ros.logs.read_log` (the whole log at full rate);
* ``diagnose``: :func:`grip_force_ros.lab.diagnosis.engine.diagnose` on the path (what
  ``grip-force diagnose`` runs: streamed, decimated, fitted);

each reporting its wall time and peak resident memory (``ru_maxrss``, its own
process only). The figure of merit is ``load_ratio = diagnose / load`` (goal <= 5).

Child entry: ``python -m grip_force_ros.lab.bench.diagnosis_speed --child load|diagnose PATH``.

In one process, as a report (:func:`report`; the figures of docs/diagnosis.md)::

    python -m grip_force_ros.lab.bench.diagnosis_speed [--minutes 60] [--dir /tmp/gf_bench] [--bag]

builds the log as CSV (and a rosbag2 with ``--bag``) in ``--dir``, then prints rows,
file size, time to load (``read_log``), time to diagnose (streamed and decimated, then
the engine) and their ratio, and the peak memory after each step (RSS, MB).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

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
    from grip_force_ros.lab.diagnosis.engine import diagnose
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
    proc = subprocess.run([sys.executable, '-m', __name__, '--child', task, str(path)], capture_output=True,
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


def build_long_log(path: Path, minutes: float, *, bag: bool = False) -> Path:
    """Write a ``minutes`` long 1 kHz log built from simulated minutes; returns the path.

    Six simulated minutes (the blind check's generator with ``viscoelastic_creep``,
    different seeds), repeated with continuous time stamps. CSV by default; a rosbag2
    (MCAP) directory with ``bag``.
    """
    from grip_force_ros.lab.diagnosis.blind import BlindCase, generate_log
    from grip_force_ros.logs import write_bag
    from grip_force_ros.logs.csvlog import _format_column

    path.parent.mkdir(parents=True, exist_ok=True)
    pieces = max(1, int(round(minutes)))
    unique = min(pieces, 6)                 # six simulated minutes, repeated with new time stamps
    minute_logs = [generate_log(BlindCase((('viscoelastic_creep', 0.3),), 500 + i), duration=60.0)
                   for i in range(unique)]
    names = list(minute_logs[0])
    if bag:
        whole = {k: np.concatenate([minute_logs[i % unique][k] for i in range(pieces)]) for k in names}
        whole['t'] = np.arange(whole['t'].size) * 1e-3 + 1e-3
        return write_bag(path, whole, overwrite=True)
    with open(path, 'w') as fh:
        fh.write(','.join(names) + '\n')
        offset = 0.0
        for i in range(pieces):
            part = dict(minute_logs[i % unique])
            part['t'] = part['t'] + offset
            offset = float(part['t'][-1])
            cols = [_format_column(part[k], k) for k in names]
            line = cols[0]
            for col in cols[1:]:
                line = np.char.add(np.char.add(line, ','), col)
            fh.write('\n'.join(line.tolist()) + '\n')
    return path


def report(minutes: float = 60.0, directory: str | Path = '/tmp/gf_bench', bag: bool = False) -> None:
    """Build the log in ``directory`` and print load and diagnosis time and memory, in this process.

    Parameters
    ----------
    minutes : float
        Length of the log at 1 kHz (min).
    directory : path
        Where the CSV (``long.csv``) and the bag (``long_bag``) are written.
    bag : bool
        Also time a rosbag2 (MCAP) of the same log.
    """
    from grip_force_ros.lab.diagnosis import run_diagnosis
    from grip_force_ros.lab.diagnosis.frame import load_decimated
    from grip_force_ros.logs import read_log

    out = Path(directory)
    t0 = time.perf_counter()
    paths = [build_long_log(out / 'long.csv', minutes)]
    if bag:
        paths.append(build_long_log(out / 'long_bag', minutes, bag=True))
    print(f'built in {time.perf_counter() - t0:.0f} s')
    for path in paths:
        size = (sum(f.stat().st_size for f in path.iterdir()) if path.is_dir() else path.stat().st_size)
        base_mb = _rss_mb()
        t0 = time.perf_counter()
        log = read_log(path)
        load_s = time.perf_counter() - t0
        rows = log['t'].size
        load_peak = _rss_mb()
        del log
        t0 = time.perf_counter()
        decimated = load_decimated(path, 200.0)
        d = run_diagnosis([decimated])
        diag_s = time.perf_counter() - t0
        print(f'{path.name}: {rows} rows, {size / 1e6:.0f} MB; load (read_log, full rate) {load_s:.1f} s; '
              f'diagnose (stream + engine) {diag_s:.1f} s; ratio {diag_s / load_s:.2f} (goal <= 5); '
              f"verdict {d.result['verdict']['effect']}; peak RSS before {base_mb:.0f} MB, after load "
              f'{load_peak:.0f} MB, after diagnose {_rss_mb():.0f} MB (pid {os.getpid()})')


def main(argv: list[str] | None = None) -> int:
    """Print the report (:func:`report`), or with ``--child TASK PATH`` one timed task as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=60.0)
    parser.add_argument('--dir', default='/tmp/gf_bench')
    parser.add_argument('--bag', action='store_true', help='also time a rosbag2 (MCAP) of the log')
    parser.add_argument('--child', nargs=2, metavar=('TASK', 'PATH'),
                        help='load|diagnose PATH: time one task here, print its JSON (used by the bench)')
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if args.child:
        task, path = args.child
        if task not in ('load', 'diagnose'):
            parser.error('--child TASK is load or diagnose')
        print(json.dumps(_child(task, path)), flush=True)
        return 0
    report(args.minutes, args.dir, args.bag)
    return 0


if __name__ == '__main__':
    sys.exit(main())
