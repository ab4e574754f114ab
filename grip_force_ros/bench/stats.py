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
    """Periods in which a periodic callback did not run.

    A gap between consecutive ticks of ``k`` periods (rounded) counts ``k - 1``
    missed periods; a late tick that still lands in its period (gap < 1.5
    periods) is not missed, only jitter.

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
        over 1.5 periods.
    """
    ticks = np.asarray(tick_times_ns, dtype=np.int64)
    period_ns = period_s * 1e9
    if ticks.size < 2:
        return {'ticks': int(ticks.size), 'expected': 0, 'missed': 0, 'missed_fraction': float('nan'),
                'late_fraction': float('nan'), 'interval_p99_ms': float('nan'),
                'interval_max_ms': float('nan')}
    gaps = np.diff(ticks).astype(float)
    periods = np.rint(gaps / period_ns)
    missed = int(np.maximum(periods - 1.0, 0.0).sum())
    expected = int(round((ticks[-1] - ticks[0]) / period_ns))
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
