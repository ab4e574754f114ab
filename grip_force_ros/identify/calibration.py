"""Calibrate an instrument's model parameters from measured data. No ROS.

One fitter, :func:`fit_parameters`: schema parameters of the instrument by (robust)
nonlinear least squares on any residual of a trial parameter set, bounded, with
standard errors from the fit's covariance or from a moving-block bootstrap of the
linearised fit over time blocks (:func:`block_bootstrap_std`, for residuals of a time
series, which are not independent). Two users:

- :func:`fit_instrument`: a lab holds the instrument on a load cell, squeezes at a few
  force levels and records current, joint angles and the measured grip force; the
  quasi-static plateaus of that log (docs/design.md data contract) fix schema parameters
  of the grip-force model (by default the cable-pulley friction coefficient), standard
  errors from the covariance. :func:`calibrated_yaml` writes the calibrated instrument
  YAML with a header that says where the numbers come from.
- the sim-to-real diagnosis re-identifies the instrument's own parameters on whole logs
  before it looks for an unmodelled effect (``lab/diagnosis/engine.py``).
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from grip_force_ros.params import SPECS, ParameterError, ParamSet, read_params_yaml

#: Parameters a calibration may fit (instrument group, one number each).
FITTABLE = ('pulley_friction_coefficient', 'torque_constant', 'drive_resistance_fraction',
            'tension_friction_gain')


class CalibrationError(ValueError):
    """The log cannot calibrate the requested parameters."""


@dataclass
class Plateaus:
    """Quasi-static samples: window means of a calibration log (SI units)."""

    t: np.ndarray             # s, window centre
    current: np.ndarray       # A
    wrist_angle: np.ndarray   # rad
    jaw_angle: np.ndarray     # rad
    grip_force: np.ndarray    # N
    force_std: np.ndarray     # N, within the window


def steady_plateaus(log: Mapping[str, np.ndarray], window: float = 0.1, min_force: float = 0.3,
                    max_force_cv: float = 0.05, max_current_cv: float = 0.05,
                    loading_only: bool = True) -> Plateaus:
    """Means of consecutive ``window``-long slices where force and current are steady.

    Cable-pulley friction sticks: once the cable stops, the tension it holds
    depends on the way it got there. The model describes the loading
    direction (motor driving the jaw), so by default only the slices up to
    the steady slice with the largest force count (a staircase up, as a lab
    records it).

    Parameters
    ----------
    log : mapping
        Columns 't' (s), 'current' (A), 'wrist_angle', 'jaw_angle' (rad),
        'grip_force' (N).
    window : float
        Slice length (s).
    min_force : float
        Slices whose mean force is below this (N) are dropped (no contact).
    max_force_cv, max_current_cv : float
        Largest std/mean within a slice for it to count as steady.
    loading_only : bool
        Keep only the steady slices up to the one with the largest force.

    Raises
    ------
    CalibrationError
        Missing columns or no steady slice.
    """
    needed = ('t', 'current', 'wrist_angle', 'jaw_angle', 'grip_force')
    missing = [c for c in needed if c not in log]
    if missing:
        raise CalibrationError(f'calibration log lacks column(s) {missing} '
                               '(a torque-measuring rig is not supported)')
    t = np.asarray(log['t'], float)
    if t.size < 10:
        raise CalibrationError('calibration log has fewer than 10 samples')
    slot = np.floor((t - t[0]) / window).astype(int)
    edges = np.flatnonzero(np.diff(slot)) + 1
    bounds = np.concatenate([[0], edges, [t.size]])
    cols = {c: np.asarray(log[c], float)
            for c in ('current', 'wrist_angle', 'jaw_angle', 'grip_force')}
    rows = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a < 5:
            continue
        seg = {c: v[a:b] for c, v in cols.items()}
        if not all(np.all(np.isfinite(v)) for v in seg.values()):
            continue
        f_mean, i_mean = seg['grip_force'].mean(), seg['current'].mean()
        if f_mean < min_force or i_mean <= 0:
            continue
        f_std, i_std = seg['grip_force'].std(), seg['current'].std()
        if f_std > max_force_cv * f_mean or i_std > max_current_cv * i_mean:
            continue
        rows.append((t[a:b].mean(), i_mean, seg['wrist_angle'].mean(), seg['jaw_angle'].mean(),
                     f_mean, f_std))
    if not rows:
        raise CalibrationError('no steady plateau with force above '
                               f'{min_force} N in the calibration log')
    arr = np.asarray(rows)
    if loading_only:   # up to the steadiest largest force (an impact spike is not steady)
        arr = arr[:int(np.argmax(arr[:, 4])) + 1]
    return Plateaus(*(arr[:, k] for k in range(6)))


def block_bootstrap_std(X, y, rng, blocks: int = 20, draws: int = 200, labels=None) -> np.ndarray:
    """Std of least-squares coefficients over a moving-block bootstrap (keeps autocorrelation).

    Parameters
    ----------
    X : ndarray, shape (n, k)
        Design (columns in their units).
    y : ndarray, shape (n,)
        Target.
    rng : numpy.random.Generator
        Draws the blocks.
    blocks : int
        Number of contiguous equal blocks of rows (when ``labels`` is None).
    draws : int
        Bootstrap draws.
    labels : ndarray of int, shape (n,), optional
        Block of each row (e.g. the time block of a sample whose rows sit in several
        channels); the blocks are the distinct labels.

    Returns
    -------
    ndarray, shape (k,)
        Standard deviation of each coefficient (unit of y per unit of its column); NaN
        when there are too few rows or draws.
    """
    n, k = X.shape
    if labels is None:
        if n < 2 * blocks:
            return np.full(k, np.nan)
        edges = np.linspace(0, n, blocks + 1).astype(int)
        xtx = np.stack([X[a:b].T @ X[a:b] for a, b in zip(edges[:-1], edges[1:])])
        xty = np.stack([X[a:b].T @ y[a:b] for a, b in zip(edges[:-1], edges[1:])])
    else:
        groups = [np.flatnonzero(labels == g) for g in np.unique(labels)]
        blocks = len(groups)
        if blocks < 2:
            return np.full(k, np.nan)
        xtx = np.stack([X[g].T @ X[g] for g in groups])
        xty = np.stack([X[g].T @ y[g] for g in groups])
    picks = rng.integers(0, blocks, size=(draws, blocks))
    coefs = []
    for p in picks:
        a, b = xtx[p].sum(0), xty[p].sum(0)
        try:
            coefs.append(np.linalg.solve(a, b))
        except np.linalg.LinAlgError:      # a column that is zero in the draw: its minimum-norm 0
            coefs.append(np.linalg.lstsq(a, b, rcond=None)[0])
    return np.std(coefs, axis=0) if len(coefs) > 2 else np.full(k, np.nan)


@dataclass
class ParameterFit:
    """Result of :func:`fit_parameters` (values in the schema's units)."""

    values: dict[str, float]
    std_errors: dict[str, float]
    before: dict[str, float]
    #: residuals at the solution and with the start values (as the residual function returns them)
    residuals: np.ndarray
    residuals_before: np.ndarray
    #: how the standard errors were taken
    std_method: str
    #: parameters at a bound of the fit at the solution
    at_bound: tuple[str, ...] = ()
    evaluations: int = 0


def _huber_weights(r: np.ndarray, f_scale: float, loss: str) -> np.ndarray:
    if loss == 'linear':
        return np.ones_like(r)
    return np.minimum(1.0, f_scale / np.maximum(np.abs(r), 1e-300))


def fit_parameters(params: ParamSet, names: Sequence[str], residuals, *, relative: Sequence[str] = (),
                   bounds: Mapping[str, tuple[float, float]] | None = None, loss: str = 'linear',
                   f_scale: float = 1.0, labels=None, rng=None, draws: int = 200,
                   diff_step: float = 1e-4) -> ParameterFit:
    """Fit schema parameters ``names`` so that ``residuals(trial)`` is least (bounded, optionally robust).

    Parameters
    ----------
    params : ParamSet
        Start values and every parameter not fitted.
    names : sequence of str
        Schema parameters (one number each).
    residuals : callable
        ``residuals(trial: ParamSet) -> ndarray`` of a fixed length (units of the data;
        scale them so the channels compare).
    relative : sequence of str
        Names fitted as a log factor of their start value (positive, scale-like
        parameters: a friction coefficient, a modulus); the others are fitted additively.
    bounds : mapping, optional
        Name -> (low, high) in the schema's unit; default the schema's range.
    loss, f_scale : str, float
        scipy ``least_squares`` loss ('linear', 'huber', ...) and its scale (unit of the
        residuals).
    labels : ndarray of int, optional
        Time block of each residual row: the standard errors are then a moving-block
        bootstrap of the fit linearised at the solution (residuals of a time series are
        not independent); without, the covariance ``s^2 (J^T J)^-1`` of the fit.
    rng : numpy.random.Generator, optional
        Draws the bootstrap (seeded by the caller).
    draws : int
        Bootstrap draws.
    diff_step : float
        Relative finite-difference step of the Jacobian.

    Returns
    -------
    ParameterFit

    Raises
    ------
    CalibrationError
        Unknown parameter, or a fit that does not converge.
    """
    from scipy.optimize import least_squares

    names = list(names)
    bad = [n for n in names if n not in SPECS]
    if bad or not names:
        raise CalibrationError(f'cannot fit {bad or names}: not schema parameters')
    x0_values = np.array([float(params[n]) for n in names])
    rel = np.array([n in relative for n in names])
    if np.any(rel & (x0_values <= 0.0)):
        raise CalibrationError('a parameter fitted as a factor must start positive')
    lows, highs = [], []
    for n in names:
        low, high = (bounds or {}).get(n, (SPECS[n].min, SPECS[n].max))
        lows.append(-np.inf if low is None else low)
        highs.append(np.inf if high is None else high)
    lows, highs = np.array(lows, float), np.array(highs, float)

    def to_values(x):
        return np.where(rel, x0_values * np.exp(x), x)

    with np.errstate(divide='ignore'):
        lower = np.where(rel, np.log(np.maximum(lows, 0.0) / x0_values), lows)
        upper = np.where(rel, np.log(highs / x0_values), highs)
    start = np.clip(np.where(rel, 0.0, x0_values), lower, upper)
    count = [0]

    def trial(x):
        return params.replace(**dict(zip(names, map(float, to_values(x)))))

    def fun(x):
        count[0] += 1
        try:
            return np.asarray(residuals(trial(x)), float)
        except (ParameterError, ValueError):
            return np.full(n_rows, 1e3 * max(f_scale, 1.0))

    before = np.asarray(residuals(params), float)
    n_rows = before.size
    x_scale = np.where(rel, 1.0, np.maximum(np.abs(x0_values), 1e-3))
    sol = least_squares(fun, start, bounds=(lower, upper), x_scale=x_scale, diff_step=diff_step,
                        loss=loss, f_scale=f_scale)
    if not sol.success:
        raise CalibrationError(f'fit did not converge: {sol.message}')
    res = sol.fun
    values = to_values(sol.x)
    # the Jacobian of the raw residuals (per unit of x), rows weighted as the robust loss weights them
    w = np.sqrt(_huber_weights(res, f_scale, loss))
    if labels is None:
        jac = sol.jac if loss == 'linear' else None
        if jac is None:
            jac = _jacobian(fun, sol.x, res, x_scale * diff_step)
        jw = jac * (w[:, None] if loss != 'linear' else 1.0)
        dof = max(n_rows - len(names), 1)
        s2 = float(np.sum((w * res) ** 2)) / dof
        try:
            std_x = np.sqrt(np.clip(np.diag(np.linalg.inv(jw.T @ jw) * s2), 0.0, None))
        except np.linalg.LinAlgError:
            std_x = np.full(len(names), np.inf)
        method = 'covariance of the fit: s^2 (J^T J)^-1'
    else:
        jac = _jacobian(fun, sol.x, res, x_scale * diff_step)
        std_x = block_bootstrap_std(jac * w[:, None], -res * w, rng if rng is not None
                                    else np.random.default_rng(0), draws=draws, labels=labels)
        method = (f'moving-block bootstrap of the fit linearised at the solution ({len(np.unique(labels))} '
                  f'time blocks, {draws} draws)')
    std = np.where(rel, values * std_x, std_x)
    at_bound = tuple(n for n, x, lo, hi in zip(names, sol.x, lower, upper)
                     if x <= lo + 1e-6 * max(1.0, abs(lo)) or x >= hi - 1e-6 * max(1.0, abs(hi)))
    return ParameterFit(values={k: float(v) for k, v in zip(names, values)},
                        std_errors={k: float(v) for k, v in zip(names, std)},
                        before={k: float(v) for k, v in zip(names, x0_values)},
                        residuals=res, residuals_before=before, std_method=method, at_bound=at_bound,
                        evaluations=count[0])


def _jacobian(fun, x, f0, steps) -> np.ndarray:
    """Forward-difference Jacobian of ``fun`` at ``x`` (columns per unit of x)."""
    cols = []
    for j, h in enumerate(steps):
        xj = np.array(x, float)
        xj[j] += h
        cols.append((fun(xj) - f0) / h)
    return np.column_stack(cols)


@dataclass
class CalibrationResult:
    """Fitted values, their standard errors, and how well the fit explains the log."""

    values: dict[str, float]
    std_errors: dict[str, float]
    before: dict[str, float]
    residual_rms: float          # N, plateau means, after the fit
    residual_rms_before: float   # N, with the YAML as shipped
    n_plateaus: int
    force_levels: list[float] = field(default_factory=list)   # N, distinct plateau forces
    obj: str = 'needle'

    def as_dict(self) -> dict[str, Any]:
        return {'fitted': self.values, 'std_error': self.std_errors, 'shipped': self.before,
                'residual_rms': self.residual_rms, 'residual_rms_before': self.residual_rms_before,
                'n_plateaus': self.n_plateaus, 'force_levels': self.force_levels,
                'object': self.obj}


def _predict(params: ParamSet, plateaus: Plateaus, obj: str) -> np.ndarray:
    from grip_force_ros.model import GripForceModel
    model = GripForceModel(params)
    return np.asarray(model.forward(plateaus.current, plateaus.wrist_angle, plateaus.jaw_angle,
                                    obj=obj).grip_force, float)


def _levels(force: np.ndarray, tolerance: float = 0.1) -> list[float]:
    """Distinct force levels (N): plateau forces more than ``tolerance`` (relative) apart."""
    levels: list[float] = []
    for f in np.sort(force):
        if not levels or f > levels[-1] * (1 + tolerance):
            levels.append(float(f))
    return levels


def fit_instrument(params: ParamSet, log: Mapping[str, np.ndarray],
                   fit: Sequence[str] = ('pulley_friction_coefficient',), obj: str = 'needle',
                   **plateau_options) -> CalibrationResult:
    """Fit ``fit`` (schema parameter names) so the model explains the load-cell log.

    Parameters
    ----------
    params : ParamSet
        The instrument as shipped (start values and every parameter not fitted).
    log : mapping
        A calibration log (see :func:`steady_plateaus`).
    fit : sequence of str
        Names from :data:`FITTABLE`. With one wrist angle and constant
        friction the force is proportional to the current, so the log fixes
        one gain: fit one parameter unless the log varies the wrist.
    obj : str
        Object in the jaws during the calibration (the load cell: 'needle').

    Returns
    -------
    CalibrationResult

    Raises
    ------
    CalibrationError
        Unknown parameter, too few plateaus, or a fit that does not converge.
    """
    names = list(fit)
    bad = [n for n in names if n not in FITTABLE or n not in SPECS]
    if bad or not names:
        raise CalibrationError(f'cannot fit {bad or names}; fittable: {list(FITTABLE)}')
    plateaus = steady_plateaus(log, **plateau_options)
    n = plateaus.grip_force.size
    if n < len(names) + 1:
        raise CalibrationError(f'{n} steady plateau(s) cannot fit {len(names)} parameter(s)')
    levels = _levels(plateaus.grip_force)
    if len(levels) < 2:
        raise CalibrationError('the calibration log holds one force level; record at least two')
    measured = plateaus.grip_force
    fitted = fit_parameters(params, names, lambda trial: _predict(trial, plateaus, obj) - measured)
    res, before = fitted.residuals, fitted.residuals_before
    return CalibrationResult(
        values=fitted.values, std_errors=fitted.std_errors, before=fitted.before,
        residual_rms=float(np.sqrt(np.mean(res ** 2))),
        residual_rms_before=float(np.sqrt(np.mean(before ** 2))),
        n_plateaus=int(n), force_levels=[round(f, 4) for f in levels], obj=obj)


def calibrated_yaml(config: str | Path, result: CalibrationResult, log_path: str | Path) -> str:
    """Return the instrument YAML with the fitted values, and a header saying where they come from.

    Every key of ``config`` is kept (in order); only the fitted ones change.
    """
    config = Path(config)
    values = read_params_yaml(config)
    for name, value in result.values.items():
        values[name] = round(float(value), 6)
    lines = [
        f'# Calibrated from {config.name} by `grip-force calibrate`, '
        f'{_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}.',
        f'# Source log: {log_path}',
        f'# Load-cell plateaus: {result.n_plateaus} (force levels '
        + ', '.join(f'{f:.2f}' for f in result.force_levels) + f' N, object {result.obj}).',
    ]
    for name, value in result.values.items():
        lines.append(f'# Fitted {name}: {value:.5f} +/- {result.std_errors[name]:.5f} '
                     f'(shipped {result.before[name]:.5f})')
    lines.append(f'# Residual rms of the plateau forces: {result.residual_rms:.4f} N '
                 f'(with the shipped values: {result.residual_rms_before:.4f} N)')
    body = yaml.safe_dump({'/**': {'ros__parameters': {
        k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}}},
        sort_keys=False, default_flow_style=None)
    return '\n'.join(lines) + '\n' + body
