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


#: The sensors a control step uses, by the controller's record column (product_controller.COLUMNS).
FULL_PATH_INPUTS = {'actuator': 'actuator_ns', 'jaw': 'jaw_ns', 'load_cell': 'load_cell_ns'}


def full_path(answered_ns, round_trip_ns, steps: dict, period_s: float) -> dict:
    """Sensing-to-actuation latency: from the sample of every input a step used to its command.

    The sim knows when each command arrived (``answered + round trip``, its clock); the
    controller noted, per command, the sample stamps (the sim's measurement times) of the
    inputs its step used. Joined on the answered actuator-state stamp.

    Parameters
    ----------
    answered_ns, round_trip_ns : array_like of int
        The sim's answers of one window: stamp of the actuator state answered, and
        arrival minus that stamp (ns).
    steps : dict of array_like of int
        The controller's steps (ns): ``answered_ns``, ``step_ns`` (its clock at the step)
        and the sample stamp of each input of :data:`FULL_PATH_INPUTS` (0: none).
    period_s : float
        Sample period of the sim (s): an input is of the same sample as the actuator
        state when their stamps are less than half a period apart.

    Returns
    -------
    dict
        ``samples`` (answers joined to a step), ``matched_fraction`` (of the answers),
        ``full_path`` (:func:`latency_summary` of arrival minus the oldest input's
        stamp, ms), and per input ``inputs[name]``: ``to_command`` (arrival minus its
        stamp), ``age_at_step`` (step time minus its stamp), ``same_sample_fraction``
        (the step used the sample of the state it answers), ``used`` (steps that had one).
        The full path is never shorter than the round trip (the actuator state is an input).
    """
    answered = np.asarray(answered_ns, np.int64)
    arrival = answered + np.asarray(round_trip_ns, np.int64)
    keys, first = np.unique(np.asarray(steps['answered_ns'], np.int64), return_index=True)
    at = np.clip(np.searchsorted(keys, answered), 0, max(keys.size - 1, 0))
    matched = (keys[at] == answered) if keys.size else np.zeros(answered.shape, bool)
    rows = first[at[matched]]
    arrival, answered = arrival[matched], answered[matched]
    step = np.asarray(steps['step_ns'], np.int64)[rows]
    oldest = answered.copy()              # the actuator state answered: exact, from the sim
    inputs = {}
    for name, column in FULL_PATH_INPUTS.items():
        stamp = np.asarray(steps[column], np.int64)[rows]
        used = stamp > 0
        oldest = np.where(used, np.minimum(oldest, stamp), oldest)
        same = np.abs(stamp[used] - answered[used]) < 0.5 * period_s * 1e9
        inputs[name] = {'to_command': latency_summary(arrival[used] - stamp[used]),
                        'age_at_step': latency_summary(step[used] - stamp[used]),
                        'same_sample_fraction': float(same.mean()) if same.size else float('nan'),
                        'used': int(used.sum())}
    return {'samples': int(answered.size),
            'matched_fraction': float(matched.mean()) if matched.size else float('nan'),
            'full_path': latency_summary(arrival - oldest), 'inputs': inputs}
