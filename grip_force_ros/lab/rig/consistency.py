"""Session consistency: what the motor side of every run of a session says about the instrument.

A run of the rig holds one resisting load while the motor strokes the jaw closed and
open. The observer (:mod:`.estimator`) estimates the jaw torque separately on the two
friction branches: closing (the motor drives, tau = (I - b_close)/alpha_close) and
opening (the load back-drives it, tau = (I - b_open)/alpha_open). The jaw torque itself
differs between the strokes only by what the rig's front end adds: its own friction
(the resisting motor is back-driven while the jaw closes, drives while it opens), a few
mN*m, growing a little with the load. So for every run of a session, motor side only:

* the closing estimate minus the opening estimate must equal the front end's step at
  that load (mid-stroke value, ``d``), and
* the change of the estimate along the stroke (P1 slope over the disk angle) must be the
  same on both branches up to the front end's own difference (``q``).

If the instrument's efficiency, Coulomb friction or its change along the stroke are not
the training folders' values, the two branch estimates disagree by an amount that grows
with the load (efficiency) or not (Coulomb), over the whole stroke or along it (friction
map). A session holds runs at several loads, so the disagreement over its runs
identifies those groups without reading any jaw torque of the session
(:func:`session_residuals`). The front end's step and its scatter are learned on the
training folders, whose jaw torque may be read (:func:`fit_front_end`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from grip_force_ros.lab.rig.constants import STARTUP_S
from grip_force_ros.lab.rig.estimator import CableFrictionObserver, EstimatorError

#: Fewest sliding samples (after start-up) a branch needs for its statistics (0.2 s at 1 kHz).
MIN_BRANCH_SAMPLES = 200


def branch_fits(values: np.ndarray, weight: np.ndarray, direction: np.ndarray,
                position: np.ndarray, t: np.ndarray) -> np.ndarray | None:
    """Weighted straight line of ``values`` over the scaled disk position, per friction branch.

    Parameters
    ----------
    values : ndarray
        Jaw torque (N*m), estimated or measured, per sample.
    weight : ndarray
        Observer weight per sample (0 while stuck or reversing).
    direction, position : ndarray
        Friction direction s and the disk angle scaled to [-1, 1] (:func:`.estimator.scaled_position`).
    t : ndarray
        Time (s).

    Returns
    -------
    ndarray or None
        ``[[mean_close, slope_close], [mean_open, slope_open]]`` (N*m, N*m per unit of the
        scaled position), or None when a branch has fewer than :data:`MIN_BRANCH_SAMPLES`.
    """
    late = t - t[0] >= STARTUP_S          # start-up: friction direction not yet known
    out = []
    for side in (1.0, -1.0):
        sel = (weight > 0) & (np.sign(direction) == side) & late
        if sel.sum() < MIN_BRANCH_SAMPLES:
            return None
        root = np.sqrt(weight[sel])
        design = np.column_stack([root, root * position[sel]])
        out.append(np.linalg.lstsq(design, root * values[sel], rcond=None)[0])
    return np.array(out)


def run_statistics(est: CableFrictionObserver, run, cache: dict | None = None,
                   values: np.ndarray | None = None) -> np.ndarray | None:
    """Load ``L``, branch difference ``d`` and slope difference ``q`` of one run (N*m).

    ``L`` = mean of the two branches' mid-stroke values, ``d`` = closing minus opening
    mid-stroke value, ``q`` = closing minus opening P1 slope. From the estimator's
    inverted torque (motor side) unless ``values`` (e.g. the measured jaw torque of a
    training run, on the same samples and weights) are given. None without both branches.
    """
    inverted, weight, _ = est.inversion(run, cache=cache)
    sig = est._design(run, cache)[0]
    fits = branch_fits(inverted if values is None else values, weight, sig.direction,
                       sig.position, np.asarray(run.t))
    if fits is None:
        return None
    (m_c, k_c), (m_o, k_o) = fits
    return np.array([0.5 * (m_c + m_o), m_c - m_o, k_c - k_o])


@dataclass
class FrontEnd:
    """The rig's front end as the training folders show it, and the consistency noise.

    Attributes
    ----------
    step : tuple of float
        Closing minus opening jaw torque at mid-stroke against the load:
        ``(per N*m of load, at zero load in N*m)``.
    slope_step : tuple of float
        Closing minus opening P1 slope of the jaw torque against the load (same units).
    bias : ndarray
        Mean consistency residual of the trained estimator on its own runs (N*m; ``d``, ``q``).
    scatter : ndarray
        Their standard deviation over the training runs (N*m): the noise of one run.
    runs : int
        Training runs used.
    """

    step: tuple
    slope_step: tuple
    bias: np.ndarray
    scatter: np.ndarray
    runs: int

    def raw_residuals(self, stats: np.ndarray) -> np.ndarray:
        """Return ``d`` and ``q`` minus the front end's at each run's load (N*m), rows of ``stats``."""
        load = stats[:, 0]
        return np.column_stack([stats[:, 1] - np.polyval(self.step, load),
                                stats[:, 2] - np.polyval(self.slope_step, load)])

    def to_json(self) -> dict:
        """Return the front-end model as plain JSON types (N*m)."""
        return {'step_per_Nm': self.step[0], 'step_at_zero_Nm': self.step[1],
                'slope_step_per_Nm': self.slope_step[0], 'slope_step_at_zero_Nm': self.slope_step[1],
                'bias_Nm': self.bias.tolist(), 'scatter_Nm': self.scatter.tolist(), 'runs': self.runs}


def fit_front_end(est: CableFrictionObserver, runs: Sequence, cache: dict | None = None) -> FrontEnd:
    """Learn the front end's branch step and the consistency noise on training runs (jaw side read).

    The step and the slope step are straight lines of the measured jaw torque's
    statistics (:func:`run_statistics` with ``values`` = the jaw torque) against the load;
    the bias and scatter are those of the trained estimator's own statistics.
    """
    measured, estimated = [], []
    for run in runs:
        truth = run_statistics(est, run, cache, values=np.asarray(run.jaw_torque, dtype=np.float64))
        own = run_statistics(est, run, cache)
        if truth is not None and own is not None:
            measured.append(truth)
            estimated.append(own)
    if len(measured) < 3:
        raise EstimatorError('the front-end model needs runs with both branches sliding, '
                             f'got {len(measured)}')
    measured, estimated = np.array(measured), np.array(estimated)
    deg = 1 if np.ptp(measured[:, 0]) > 1e-3 else 0        # one load: a constant step
    step = tuple(float(c) for c in np.polyfit(measured[:, 0], measured[:, 1], deg).tolist())
    slope = tuple(float(c) for c in np.polyfit(measured[:, 0], measured[:, 2], deg).tolist())
    if deg == 0:
        step, slope = (0.0,) + step, (0.0,) + slope
    model = FrontEnd(step, slope, np.zeros(2), np.ones(2), len(measured))
    raw = model.raw_residuals(estimated)
    model.bias = raw.mean(axis=0)
    model.scatter = np.maximum(raw.std(axis=0), 1e-4)
    return model


def session_residuals(est: CableFrictionObserver, runs: Sequence, front: FrontEnd,
                      cache: dict | None = None) -> np.ndarray:
    """Consistency residuals of a session's runs, in units of the training scatter (motor side only).

    Two per run (``d`` and ``q`` minus the front end's, minus the training bias, over the
    training scatter), flattened; a run without both branches sliding gives zeros
    (no information). Reads ``t``, ``current``, ``motor_angle``, ``motor_shaft_angle``.
    """
    out = np.zeros((len(runs), 2))
    for i, run in enumerate(runs):
        stats = run_statistics(est, run, cache)
        if stats is not None:
            out[i] = (front.raw_residuals(stats[None, :])[0] - front.bias) / front.scatter
    return out.ravel()
