"""Time series of a run, read back from its rosbag2 (with ``rosbags``; no rclpy).

:func:`read_bag_series` returns, per topic, the sample times and the plain
values of :func:`grip_force_ros.demo.messages.values_of`; :func:`resample`
puts every signal on one uniform time grid for the analysis and the plot.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from grip_force_ros import topics
from grip_force_ros.demo.messages import RecordedTopics, diagnostic_summary, stamp_seconds


#: Largest median |header stamp - receive time| (s) for which the stamps are trusted.
STAMP_TOLERANCE = 2.0


class BagError(ValueError):
    """The bag cannot be read or lacks a topic the analysis needs."""


def read_bag_series(path: str | Path, recorded: RecordedTopics | None = None
                    ) -> tuple[dict[str, dict[str, np.ndarray]], list]:
    """Read a demo bag.

    Parameters
    ----------
    path : path
        The bag (directory or file).
    recorded : RecordedTopics, optional
        The interface profile the run used (default: crtk).

    Returns
    -------
    series : dict
        Topic (as in topics.py) -> {'t': times [s], <field>: values (SI)}.
        Times are the header stamps when a topic's stamps are on the
        recorder's clock (within :data:`STAMP_TOLERANCE` of the receive
        times: robust to a recorder that falls behind under load), else the
        receive times (a node stamping with its own simulated clock).
    diagnostics : list
        (time [s], list of status dicts) per /diagnostics message.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    recorded = recorded or RecordedTopics(topics.topic_set('crtk'))
    fields = recorded.fields
    wanted = {('/' + t.lstrip('/')): t for t in fields}
    rows: dict[str, dict[str, list]] = {t: {'t': [], 'stamp': [], **{f: [] for f in fields[t]}}
                                        for t in fields}
    diagnostics = []
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            for conn, stamp_ns, raw in reader.messages():
                msg = reader.deserialize(raw, conn.msgtype)
                t = stamp_ns * 1e-9
                if conn.topic == topics.DIAGNOSTICS:
                    diagnostics.append((t, diagnostic_summary(msg)))
                    continue
                short = wanted.get(conn.topic)
                if short is None:
                    continue
                row = rows[short]
                row['t'].append(t)
                row['stamp'].append(stamp_seconds(msg))
                for name, value in recorded.values(short, msg).items():
                    row[name].append(value)
    except Exception as exc:  # rosbags raises several types for unreadable bags
        raise BagError(f'{path}: cannot read rosbag2: {exc}') from exc
    series = {}
    for topic, row in rows.items():
        received = np.asarray(row.pop('t'), dtype=float)
        stamps = np.asarray(row.pop('stamp'), dtype=float)
        t = received
        if stamps.size and np.all(stamps > 0) and \
                np.median(np.abs(stamps - received)) < STAMP_TOLERANCE:
            t = stamps
        row['t'] = t
        order = np.argsort(t, kind='stable')
        series[topic] = {k: np.asarray(v, dtype=float)[order] for k, v in row.items()}
    return series, diagnostics


def resample(series: Mapping[str, Mapping[str, np.ndarray]], rate: float = 500.0,
             t0: float | None = None) -> dict[str, np.ndarray]:
    """Every field of every topic on one uniform grid (linear interpolation).

    Parameters
    ----------
    series : mapping
        As returned by :func:`read_bag_series`.
    rate : float
        Grid rate (Hz).
    t0 : float, optional
        Time origin (s) subtracted from the grid; default the first sample.

    Returns
    -------
    dict
        't' (s since ``t0``) and one array per field; a field whose topic has
        no samples is all NaN.
    """
    starts = [s['t'][0] for s in series.values() if s['t'].size]
    ends = [s['t'][-1] for s in series.values() if s['t'].size]
    if not starts:
        raise BagError('no samples on any topic')
    start, end = min(starts), max(ends)
    grid = np.arange(start, end, 1.0 / rate)
    out = {'t': grid - (start if t0 is None else t0)}
    for topic, s in series.items():
        for name, values in s.items():
            if name == 't':
                continue
            ok = np.isfinite(values)
            if ok.sum() >= 2:
                out[name] = np.interp(grid, s['t'][ok], values[ok], left=np.nan, right=np.nan)
            else:
                out[name] = np.full(grid.shape, np.nan)
    return out
