"""Time series of a run, read back from its rosbag2 (with ``rosbags``; no rclpy).

:func:`read_bag_series` returns, per topic, the sample times and the plain
values of :func:`grip_force_ros.lab.demo.messages.values_of`; :func:`resample`
puts every signal on one uniform time grid for the analysis and the plot.

Every sample is placed at its header stamp: the one clock of the samples (the nodes
stamp with the system clock when they sample or compute). The time a message reached
the recorder is not a sample time: a stalled process, or a recorder that fell behind,
delivers late, and a trace placed at its receive times is shifted against the others
(the master's trace seconds off the jaw and force traces). On the
stamps, a stall shows as what it was: a gap in the stalled process's samples.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, MutableMapping

import numpy as np

from grip_force_ros import topics
from grip_force_ros.lab.demo.messages import RecordedTopics, diagnostic_summary, stamp_seconds


#: Tolerance (s) of the test that a topic's header stamps are on the recorder's clock: no
#: message is received before it was stamped, nor stamped before the recording began (the
#: recorder subscribes before the nodes start; VOLATILE durability), each by more than this.
#: Delivery only adds delay, as long as it may be (a stalled process, a recorder behind):
#: a late message does not fail the test. Stamps on another clock (a driver's own, a
#: simulated time from 0) fail it.
STAMP_TOLERANCE = 2.0
#: Clock of a topic whose samples are placed at their header stamps.
CLOCK_STAMP = 'header stamp'
#: Clock of a topic placed at its receive times because its messages carry no stamp.
CLOCK_UNSTAMPED = 'receive time: the messages carry no header stamp'
#: Smallest gap (s) between two samples of a topic that :func:`resample` shows as a gap
#: (``max_gap``): the longest silence :func:`grip_force_ros.lab.demo.analysis.run_problems`
#: lets pass.
SHOWN_GAP = 0.1


class BagError(ValueError):
    """The bag cannot be read or lacks a topic the analysis needs."""


def sample_clock(stamps: np.ndarray, received: np.ndarray, start: float | None = None
                 ) -> tuple[np.ndarray, str]:
    """Return the sample times of one topic, and which clock they are on.

    Parameters
    ----------
    stamps : ndarray
        Header stamps (s; 0 for a message without a stamp).
    received : ndarray
        Receive times of the same messages (s, the recorder's system clock).
    start : float, optional
        When the recording began (s, its first receive time over every topic); default
        this topic's first receive time.

    Returns
    -------
    times : ndarray
        The stamps (s) when every message has one and they are on the recorder's clock
        (none later than its receive time or earlier than ``start``, by more than
        :data:`STAMP_TOLERANCE`), else the receive times (s).
    clock : str
        :data:`CLOCK_STAMP`, :data:`CLOCK_UNSTAMPED`, or why the stamps were not used.
    """
    if not stamps.size:
        return received, CLOCK_STAMP
    if not np.all(stamps > 0):
        return received, CLOCK_UNSTAMPED
    start = float(np.min(received)) if start is None else start
    ahead = float(np.max(stamps - received))
    before = start - float(np.min(stamps))
    if ahead <= STAMP_TOLERANCE and before <= STAMP_TOLERANCE:
        return stamps, CLOCK_STAMP
    why = (f'stamped up to {ahead:.3f} s after being received' if ahead > STAMP_TOLERANCE
           else f'stamped up to {before:.3f} s before the recording began')
    return received, f'receive time: the header stamps are on another clock ({why})'


def read_bag_series(path: str | Path, recorded: RecordedTopics | None = None,
                    clocks: MutableMapping[str, str] | None = None, namespace: str = ''
                    ) -> tuple[dict[str, dict[str, np.ndarray]], list]:
    """Read a demo bag.

    Parameters
    ----------
    path : path
        The bag (directory or file).
    recorded : RecordedTopics, optional
        The interface profile the run used (default: crtk).
    clocks : mutable mapping, optional
        Filled with topic -> the clock its times are on (:func:`sample_clock`; the
        /diagnostics topic included).
    namespace : str
        ROS namespace the bag's topics are under ('' : the root): one arm of a several-arm
        demo (``PSM1``: ``/PSM1/instrument/measured_js``, ``/PSM1/diagnostics``). The
        series keep the names in the root.

    Returns
    -------
    series : dict
        Topic (as in topics.py) -> {'t': times [s], <field>: values (SI)}, sorted by time.
        Times are the header stamps (:func:`sample_clock`): late delivery (a stalled
        process, a recorder behind under load) does not move a sample. Only a topic
        without stamps, or with stamps on another clock, is on its receive times.
    diagnostics : list
        (time [s], list of status dicts) per /diagnostics message, in time order; times
        on the same rule (the controller and the sim stamp their /diagnostics).
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    recorded = recorded or RecordedTopics(topics.topic_set('crtk'))
    fields = recorded.fields
    prefix = '/' + namespace.strip('/') if namespace.strip('/') else ''
    wanted = {(prefix + '/' + t.lstrip('/')): t for t in fields}
    diagnostics_topic = prefix + topics.DIAGNOSTICS
    rows: dict[str, dict[str, list]] = {t: {'t': [], 'stamp': [], **{f: [] for f in fields[t]}}
                                        for t in fields}
    diagnostics = []
    diagnostic_received, diagnostic_stamps = [], []
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            for conn, stamp_ns, raw in reader.messages():
                msg = reader.deserialize(raw, conn.msgtype)
                t = stamp_ns * 1e-9
                if conn.topic == diagnostics_topic:
                    diagnostics.append(diagnostic_summary(msg))
                    diagnostic_received.append(t)
                    diagnostic_stamps.append(stamp_seconds(msg))
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
    clocks = {} if clocks is None else clocks
    firsts = [row['t'][0] for row in rows.values() if row['t']] + diagnostic_received[:1]
    start = min(firsts) if firsts else None      # the recording's first message (s)
    series = {}
    for topic, row in rows.items():
        received = np.asarray(row.pop('t'), dtype=float)
        stamps = np.asarray(row.pop('stamp'), dtype=float)
        row['t'], clocks[topic] = sample_clock(stamps, received, start)
        order = np.argsort(row['t'], kind='stable')
        series[topic] = {k: np.asarray(v, dtype=float)[order] for k, v in row.items()}
    t, clocks[topics.DIAGNOSTICS] = sample_clock(np.asarray(diagnostic_stamps, dtype=float),
                                                 np.asarray(diagnostic_received, dtype=float),
                                                 start)
    order = np.argsort(t, kind='stable')
    return series, [(float(t[i]), diagnostics[i]) for i in order]


def resample(series: Mapping[str, Mapping[str, np.ndarray]], rate: float = 500.0,
             t0: float | None = None, max_gap: float | None = None) -> dict[str, np.ndarray]:
    """Every field of every topic on one uniform grid (linear interpolation).

    Parameters
    ----------
    series : mapping
        As returned by :func:`read_bag_series`.
    rate : float
        Grid rate (Hz).
    t0 : float, optional
        Time origin (s) subtracted from the grid; default the first sample.
    max_gap : float, optional
        Show silences (s): between two samples of a topic farther apart than this and
        than five of the topic's median sample intervals, its fields are NaN instead of
        a line drawn across (the figure's data, :data:`SHOWN_GAP`). Default None:
        interpolate across every gap (the analysis' data).

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
        silent = None if max_gap is None else _silent(s['t'], grid, max_gap)
        for name, values in s.items():
            if name == 't':
                continue
            ok = np.isfinite(values)
            if ok.sum() >= 2:
                out[name] = np.interp(grid, s['t'][ok], values[ok], left=np.nan, right=np.nan)
                if silent is not None:
                    out[name][silent] = np.nan
            else:
                out[name] = np.full(grid.shape, np.nan)
    return out


def _silent(t: np.ndarray, grid: np.ndarray, max_gap: float) -> np.ndarray:
    """Return which points of ``grid`` (s) fall inside a gap of the sample times ``t`` (s).

    A gap: two consecutive samples farther apart than ``max_gap`` (s) and than five
    median sample intervals.
    """
    silent = np.zeros(grid.shape, dtype=bool)
    if t.size < 2:
        return silent
    steps = np.diff(t)
    limit = max(max_gap, 5.0 * float(np.median(steps)))
    for i in np.flatnonzero(steps > limit):
        silent |= (grid > t[i]) & (grid < t[i + 1])
    return silent
