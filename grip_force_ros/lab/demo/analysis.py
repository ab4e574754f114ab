"""Figures of a run: phases, hold-phase force error, steady hold ratio, spreads.

Plain numpy on the resampled series of :func:`grip_force_ros.lab.demo.series.resample`
(keys 't', 'master_angle', 'target_force', 'measured_force', ...). No ROS.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from grip_force_ros import topics
from grip_force_ros.control import Mode
from grip_force_ros.control.inputs import SOURCES
from grip_force_ros.trajectories import Trajectory

#: Share of the hold phase, at its end, over which the force counts as steady.
STEADY_SHARE = 0.6


class AnalysisError(ValueError):
    """The run has no data where a figure needs it."""


def trajectory_start(t: np.ndarray, master_angle: np.ndarray, trajectory: Trajectory) -> float:
    """Time (on the ``t`` axis, s) at which the master started ``trajectory``.

    Found from the first crossing of the mid opening while closing, in the
    data and in the trajectory: robust to the first samples that a recorder
    misses while it discovers the master.

    Raises
    ------
    AnalysisError
        If the recorded master angle never crosses the mid opening.
    """
    tt = np.linspace(0.0, trajectory.duration, max(2, int(trajectory.duration * 1000) + 1))
    aa = trajectory.angle(tt)
    mid = 0.5 * (float(np.max(aa)) + float(np.min(aa)))
    if not np.any(aa < mid):
        raise AnalysisError('the trajectory never closes')
    t_traj = _first_down_crossing(tt, aa, mid)
    ok = np.isfinite(master_angle)
    if not np.any(master_angle[ok] < mid) or not np.any(master_angle[ok] > mid):
        raise AnalysisError('the recorded master angle never crosses the mid opening')
    return _first_down_crossing(t[ok], master_angle[ok], mid) - t_traj


def _first_down_crossing(t: np.ndarray, a: np.ndarray, level: float) -> float:
    above = a >= level
    idx = np.flatnonzero(above[:-1] & ~above[1:])
    if idx.size == 0:
        raise AnalysisError('no downward crossing')
    i = int(idx[0])
    da = a[i + 1] - a[i]
    return float(t[i] + (level - a[i]) / da * (t[i + 1] - t[i])) if da else float(t[i])


def phase_windows(trajectory: Trajectory, start: float) -> dict[str, tuple[float, float]]:
    """Phase -> (start, end) on the data time axis (s)."""
    return {name: (a + start, b + start) for name, (a, b) in trajectory.phase_times().items()}


def steady_window(windows: Mapping[str, tuple[float, float]],
                  share: float = STEADY_SHARE) -> tuple[float, float]:
    """Return the last ``share`` of the hold phase (s): where the grip force is steady."""
    if 'hold' not in windows:
        raise AnalysisError('the trajectory has no hold phase')
    a, b = windows['hold']
    return b - share * (b - a), b


def _mask(t: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    return (t >= window[0]) & (t <= window[1])


def _mean(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.mean(x)) if x.size else float('nan')


def force_metrics(data: Mapping[str, np.ndarray], windows: Mapping[str, tuple[float, float]],
                  force_key: str = 'measured_force') -> dict[str, float]:
    """Hold-phase force error and the other figures the demo prints.

    Parameters
    ----------
    data : mapping
        Resampled series ('t', 'target_force', ``force_key``, ...).
    windows : mapping
        Phase windows on the same time axis (:func:`phase_windows`).
    force_key : str
        Which force is compared with the target: the load cell
        ('measured_force') by default.

    Returns
    -------
    dict
        target_force, measured_force, estimated_force (steady-hold means, N);
        hold_error_mean / _rms / _max (N, measured - target over the steady
        hold); hold_error_rel (mean error / target); steady_ratio (measured /
        target); settling_time (s from the start of hold until the error
        stays within 5 % of the target, NaN if never); estimate_error_rms (N,
        model estimate - load cell over the steady hold); pull_out_force and
        pull_grip_force (means over the pull phase, N); peak_current (A,
        largest |command|).

    Raises
    ------
    AnalysisError
        If the steady hold window holds no sample with a target and a force.
    """
    t = data['t']
    steady = _mask(t, steady_window(windows))
    target = data['target_force']
    force = data[force_key]
    ok = steady & np.isfinite(target) & np.isfinite(force)
    if ok.sum() < 3:
        raise AnalysisError('no force samples in the steady hold window')
    err = force[ok] - target[ok]
    target_mean = float(np.mean(target[ok]))
    out = {
        'target_force': target_mean,
        'measured_force': float(np.mean(force[ok])),
        'estimated_force': _mean(data.get('estimated_force', np.full(t.shape, np.nan))[ok]),
        'hold_error_mean': float(np.mean(err)),
        'hold_error_rms': float(np.sqrt(np.mean(err ** 2))),
        'hold_error_max': float(np.max(np.abs(err))),
        'hold_error_rel': float(np.mean(err) / target_mean) if target_mean > 0 else float('nan'),
        'steady_ratio': (float(np.mean(force[ok]) / target_mean) if target_mean > 0
                         else float('nan')),
    }
    est = data.get('estimated_force')
    meas = data.get('measured_force')
    if est is not None and meas is not None:
        both = steady & np.isfinite(est) & np.isfinite(meas)
        out['estimate_error_rms'] = (float(np.sqrt(np.mean((est[both] - meas[both]) ** 2)))
                                     if both.any() else float('nan'))
    out['settling_time'] = settling_time(t, target, force, windows['hold'])
    if 'pull' in windows:
        pull = _mask(t, windows['pull'])
        out['pull_out_force'] = _mean(data.get('pull_out_force', np.full(t.shape, np.nan))[pull])
        out['pull_grip_force'] = _mean(force[pull])
    cmd = data.get('current_command')
    if cmd is not None and np.isfinite(cmd).any():
        out['peak_current'] = float(np.nanmax(np.abs(cmd)))
    return out


def settling_time(t: np.ndarray, target: np.ndarray, force: np.ndarray,
                  hold: tuple[float, float], tolerance: float = 0.05) -> float:
    """Time (s) from the start of ``hold`` until |force - target| <= tolerance*target for good."""
    m = _mask(t, hold) & np.isfinite(target) & np.isfinite(force)
    if m.sum() < 2:
        return float('nan')
    tt, tg, f = t[m], target[m], force[m]
    bad = np.abs(f - tg) > tolerance * np.maximum(np.abs(tg), 1e-9)
    if not bad.any():
        return 0.0
    last_bad = int(np.flatnonzero(bad)[-1])
    if last_bad == tt.size - 1:
        return float('nan')
    return float(tt[last_bad + 1] - hold[0])


def spread(ratios: Sequence[float]) -> float:
    """Return max - min of the steady hold force / target ratios (NaN if any is missing)."""
    r = np.asarray(list(ratios), dtype=float)
    if r.size == 0 or not np.all(np.isfinite(r)):
        return float('nan')
    return float(np.max(r) - np.min(r))


def safe_state_entries(diagnostics, window: tuple[float, float], offset: float = 0.0,
                       name_part: str = 'controller') -> list[dict]:
    """Entries of the controller into its safe state within ``window`` (s, data axis).

    Parameters
    ----------
    diagnostics : list
        (time [s], list of status dicts) as :func:`grip_force_ros.lab.demo.series.read_bag_series`
        returns them.
    window : (float, float)
        Time window on the analysis axis (s).
    offset : float
        Subtracted from the diagnostic times to put them on that axis (s).
    name_part : str
        Only statuses whose name contains it (the controller's).

    Returns
    -------
    list of dict
        {'t': s, 'reason': str} per transition into mode 'safe'.
    """
    out, last = [], None
    for t, statuses in diagnostics:
        for status in statuses:
            if name_part not in status['name']:
                continue
            mode = status['values'].get('mode')
            tt = t - offset
            if mode == Mode.SAFE and last != Mode.SAFE and window[0] <= tt <= window[1]:
                out.append({'t': round(tt, 3),
                            'reason': status['values'].get('reasons') or status['message']})
            last = mode
    return out


def late_inputs(diagnostics, window: tuple[float, float], offset: float = 0.0,
                name_part: str = 'controller') -> dict:
    """Late inputs the controller counted within ``window`` (s, data axis), per source.

    Late: older than three of its own sample intervals but not lost (control went on with
    the last value; docs/control.md). The controller's /diagnostics carry cumulative
    counts (``late_<source>``) and the largest age (``late_<source>_max_ms``); the counts
    in the window are the last report in it minus the last report before it.

    Parameters
    ----------
    diagnostics, window, offset, name_part
        As :func:`safe_state_entries`.

    Returns
    -------
    dict
        ``total`` (int) and, per source with late inputs in the window, ``{'count': int,
        'max_ms': float}`` (``max_ms``: the largest age reported within the window, ms).
    """
    before: dict = {}
    last: dict = {}
    oldest: dict = {}          # source -> largest age reported in the window (ms)
    for t, statuses in diagnostics:
        for status in statuses:
            if name_part not in status['name']:
                continue
            values = status['values']
            tt = t - offset
            if tt < window[0]:
                before = values
            elif tt <= window[1]:
                last = values
                for source in SOURCES:
                    age = values.get(f'late_{source}_max_ms')
                    if age is not None:
                        oldest[source] = max(oldest.get(source, 0.0), float(age))
    out: dict = {'total': 0}
    for source in SOURCES:
        count = int(last.get(f'late_{source}', 0)) - int(before.get(f'late_{source}', 0))
        if count > 0:
            out[source] = {'count': count, 'max_ms': oldest.get(source, float('nan'))}
            out['total'] += count
    return out


def largest_gap(times: np.ndarray, window: tuple[float, float]) -> float:
    """Longest interval (s) without a sample inside ``window`` (its edges count as samples)."""
    t = np.asarray(times, float)
    inside = t[(t > window[0]) & (t < window[1])]
    edges = np.concatenate([[window[0]], inside, [window[1]]])
    return float(np.max(np.diff(edges)))


#: The phases the demo's figures come from: the hold (force error, steady ratio) and the
#: pull test (pull-out force).
MEASURED_PHASES = ('hold', 'pull')


def run_problems(metrics: dict, windows: dict, max_gap: float = 0.1) -> list[str]:
    """Why a run cannot be trusted (empty if it can): stalls and safe-state entries.

    In the phases the figures come from (:data:`MEASURED_PHASES`). A loaded machine can
    starve a node for a while; the controller then loses an input and enters its safe
    state. Such a run measures the machine, not the controller.
    """
    problems = []
    for phase in MEASURED_PHASES:
        gap = metrics.get(f'largest_gap_{phase}', 0.0)
        if gap > max_gap:
            problems.append(f'a topic went silent for {gap * 1e3:.0f} ms during the {phase} phase')
        window = windows.get(phase)
        for event in metrics.get('safe_events', []):
            if window and window[0] <= event['t'] <= window[1]:
                problems.append(f"safe state at {event['t']:.2f} s ({phase} phase): "
                                f"{event['reason']}")
                break
    if not metrics.get('target_force', 0.0) > 0:
        problems.append('no grip force target during the hold phase')
    return problems


#: Name of the simulated instrument's /diagnostics status.
SIM_STATUS = topics.diagnostic_name('/', 'sim_instrument')


def drive_cuts_under_current(diagnostics, until: float) -> int:
    """Count the simulated drive's cuts of a non-zero current reported up to ``until``.

    A cut means the drive got no command for its timeout (30 ms) while it held a
    current: on a loaded machine, a starved node. A calibration staircase with one
    no longer loads the pulley friction in one direction, and its fit is off
    (seen on a loaded machine: long-jaw mu 0.1149 against 0.1189-0.1194 in other runs).

    Parameters
    ----------
    diagnostics : list
        (time [s], list of status dicts) per /diagnostics message
        (:func:`grip_force_ros.lab.demo.series.read_bag_series`).
    until : float
        Last time that counts (s, the recorder's clock), e.g. the master's last
        sample: cuts while the nodes are stopped do not count.
    """
    count = 0
    for t, statuses in diagnostics:
        if t > until:
            continue
        for status in statuses:
            if topics.is_status_of(status['name'], 'sim_instrument'):
                count = max(count, int(status['values'].get('drive_cuts_under_current', 0)))
    return count
