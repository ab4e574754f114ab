"""Benchmark: diagnose a long log (default 1 h at 1 kHz) against the time to merely load it.

    python -m grip_force_ros.diagnosis.bench [--minutes 60] [--dir /tmp/gf_bench] [--bag]

Builds the log from simulated minutes (the blind check's generator, different seeds,
stitched with continuous time), writes it as CSV (and a rosbag2 with --bag), then
prints: rows, file size, time to load (``read_log``), time to diagnose (streamed,
``grip-force diagnose`` path) and their ratio (goal <= 5), and the peak memory of each
step (RSS, MB). Figures go to stdout; nothing is asserted.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np


def _peak_mb() -> float:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def build_long_log(path: Path, minutes: float, *, bag: bool = False) -> Path:
    """Write a ``minutes`` long 1 kHz log built from simulated minutes; returns the path."""
    from grip_force_ros.diagnosis.blind import BlindCase, generate_log
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=60.0)
    parser.add_argument('--dir', default='/tmp/gf_bench')
    parser.add_argument('--bag', action='store_true', help='also time a rosbag2 (MCAP) of the log')
    args = parser.parse_args(argv)
    from grip_force_ros.diagnosis import run_diagnosis
    from grip_force_ros.diagnosis.frame import load_decimated
    from grip_force_ros.logs import read_log

    out = Path(args.dir)
    t0 = time.perf_counter()
    paths = [build_long_log(out / 'long.csv', args.minutes)]
    if args.bag:
        paths.append(build_long_log(out / 'long_bag', args.minutes, bag=True))
    print(f'built in {time.perf_counter() - t0:.0f} s')
    for path in paths:
        size = (sum(f.stat().st_size for f in path.iterdir()) if path.is_dir() else path.stat().st_size)
        base_mb = _peak_mb()
        t0 = time.perf_counter()
        log = read_log(path)
        load_s = time.perf_counter() - t0
        rows = log['t'].size
        load_peak = _peak_mb()
        del log
        t0 = time.perf_counter()
        decimated = load_decimated(path, 200.0)
        d = run_diagnosis([decimated])
        diag_s = time.perf_counter() - t0
        print(f'{path.name}: {rows} rows, {size / 1e6:.0f} MB; load (read_log, full rate) {load_s:.1f} s; '
              f'diagnose (stream + engine) {diag_s:.1f} s; ratio {diag_s / load_s:.2f} (goal <= 5); '
              f"verdict {d.result['verdict']['effect']}; peak RSS before {base_mb:.0f} MB, after load "
              f'{load_peak:.0f} MB, after diagnose {_peak_mb():.0f} MB (pid {os.getpid()})')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
