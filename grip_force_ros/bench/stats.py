"""Latency and period statistics of the bench (numpy only, no rclpy)."""
from __future__ import annotations

import numpy as np


def latency_summary(latencies_ns) -> dict:
    """p50, p99 and max of round-trip latencies.

    Parameters
    ----------
    latencies_ns : array_like of int
        Round-trip latencies (ns).

    Returns
    -------
    dict
        ``{"samples": n, "p50_ms", "p99_ms", "max_ms", "mean_ms"}`` (ms); the
        figures are NaN when there is no sample.
    """
    lat = np.asarray(latencies_ns, dtype=float) * 1e-6          # ms
    if lat.size == 0:
        nan = float('nan')
        return {'samples': 0, 'p50_ms': nan, 'p99_ms': nan, 'max_ms': nan, 'mean_ms': nan}
    p50, p99 = np.percentile(lat, [50.0, 99.0])
    return {'samples': int(lat.size), 'p50_ms': float(p50), 'p99_ms': float(p99),
            'max_ms': float(lat.max()), 'mean_ms': float(lat.mean())}


def missed_periods(tick_times_ns, period_s: float) -> dict:
    """Periods in which a periodic event (a timer tick, an answered state) did not happen.

    Missed = periods in the span of the ticks minus the ticks there are: a
    period is missed when it has no tick at all. A late tick is not missed, only
    jitter, even when it comes more than half a period late (an rcl timer runs a
    late callback, then the next one on time; counting the gaps rounded to whole
    periods would call that a miss): lateness is what the latency figures and
    ``late_fraction`` show.

    Parameters
    ----------
    tick_times_ns : array_like of int
        Times the callback ran (ns, any monotonic clock), rising.
    period_s : float
        Nominal period (s).

    Returns
    -------
    dict
        ``{"ticks", "expected", "missed", "missed_fraction", "late_fraction",
        "interval_p99_ms", "interval_max_ms"}``; ``expected`` is the number of
        periods in the span of the ticks, ``late_fraction`` the share of gaps
        over 1.5 periods (late or missed).
    """
    ticks = np.asarray(tick_times_ns, dtype=np.int64)
    period_ns = period_s * 1e9
    if ticks.size < 2:
        return {'ticks': int(ticks.size), 'expected': 0, 'missed': 0, 'missed_fraction': float('nan'),
                'late_fraction': float('nan'), 'interval_p99_ms': float('nan'),
                'interval_max_ms': float('nan')}
    gaps = np.diff(ticks).astype(float)
    expected = int(round((ticks[-1] - ticks[0]) / period_ns))
    missed = max(expected - gaps.size, 0)
    return {'ticks': int(ticks.size), 'expected': expected, 'missed': missed,
            'missed_fraction': missed / expected if expected else float('nan'),
            'late_fraction': float(np.mean(gaps > 1.5 * period_ns)),
            'interval_p99_ms': float(np.percentile(gaps, 99.0) * 1e-6),
            'interval_max_ms': float(gaps.max() * 1e-6)}


def ratio(numerator: float, denominator: float) -> float:
    """``numerator / denominator``, NaN when either is missing or the denominator is 0."""
    try:
        if denominator and numerator == numerator and denominator == denominator:
            return float(numerator) / float(denominator)
    except TypeError:
        pass
    return float('nan')
