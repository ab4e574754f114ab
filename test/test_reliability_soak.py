"""The soak's statistics (ROS-free; the soak itself is a benchmark: ``grip-force soak``)."""
import types

import numpy as np
import pytest

from grip_force_ros.lab.faults.soak import _period_stats, _Recorder


def test_period_stats_count_missed_periods():
    rng = np.random.default_rng(0)
    intervals = 1e-3 + 1e-5 * rng.standard_normal(10_000)
    intervals[[10, 500, 9000]] = [1.6e-3, 5e-3, 0.3]      # three late periods
    intervals[42] = 1.4e-3                                # late, but under 1.5 periods
    stats = _period_stats(intervals, 1e-3)
    assert stats['periods'] == 10_000
    assert stats['missed'] == 3
    assert stats['max_ms'] == pytest.approx(300.0)
    assert stats['p50_ms'] == pytest.approx(1.0, abs=1e-3)
    assert _period_stats(np.zeros(0), 1e-3) == {'periods': 0}


def _header(stamp):
    """A header stamped ``stamp`` (s)."""
    sec = int(stamp)
    return types.SimpleNamespace(
        stamp=types.SimpleNamespace(sec=sec, nanosec=int(round((stamp - sec) * 1e9))))


def _command(stamp, value=0.1):
    return types.SimpleNamespace(header=_header(stamp), effort=[value])


def _target(stamp, force=1.0):
    return types.SimpleNamespace(header=_header(stamp),
                                 wrench=types.SimpleNamespace(force=types.SimpleNamespace(z=force)))


def test_recorder_bins_minutes_and_joins_them():
    rec = _Recorder(1e-3, start=0.0)
    clock = iter(np.repeat(np.arange(0.0, 130.0, 0.01), 2))   # 13 000 steps over 130 s (monotonic;
    #                                                             read by on_step and on_command)
    stamps = np.arange(13_000) * 1e-3 + 1000.0       # controller step stamps, 1 ms apart
    stamps[7000:] += 0.004                           # one 5 ms gap in the second minute
    import grip_force_ros.lab.faults.soak as soak
    real = soak.time
    # the recorder's clock only, not the time module's (other threads of the process read it)
    soak.time = types.SimpleNamespace(monotonic=lambda: next(clock))
    try:
        for i, s in enumerate(stamps):
            rec.on_step(_target(float(s)))
            rec.on_command(_command(float(s) - 2e-4, 0.2 if i % 2 else float('nan')))
    finally:
        soak.time = real
    rec.finish()
    assert [m['minute'] for m in rec.minutes] == [1, 2, 3]
    # every interval counted once, across the minute boundaries too
    assert sum(m['periods'] for m in rec.minutes) == 13_000 - 1
    assert sum(m['missed'] for m in rec.minutes) == 1 and rec.minutes[1]['missed'] == 1
    assert rec.commands == 13_000 and rec.non_finite == 6500
    assert rec.max_abs_command == pytest.approx(0.2)
