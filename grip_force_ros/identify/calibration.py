"""Calibrate an instrument's model parameters from a load-cell grasp. No ROS.

A lab holds the instrument on a load cell, squeezes at a few force levels and
records current, joint angles and the measured grip force. This module takes
that log (docs/design.md data contract), keeps the quasi-static plateaus, and fits
schema parameters of the grip-force model (by default the cable-pulley
friction coefficient) by least squares on the plateau means, with a standard
error from the fit's Jacobian. :func:`calibrated_yaml` writes the calibrated
instrument YAML with a header that says where the numbers come from.
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
    from scipy.optimize import least_squares

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
    x0 = np.array([float(params[n_]) for n_ in names])
    lower = np.array([SPECS[n_].min if SPECS[n_].min is not None else -np.inf for n_ in names])
    upper = np.array([SPECS[n_].max if SPECS[n_].max is not None else np.inf for n_ in names])
    measured = plateaus.grip_force

    def residuals(x: np.ndarray) -> np.ndarray:
        try:
            trial = params.replace(**dict(zip(names, map(float, x))))
            return _predict(trial, plateaus, obj) - measured
        except (ParameterError, ValueError):
            return np.full(n, 1e3)

    before = residuals(x0)
    sol = least_squares(residuals, np.clip(x0, lower, upper), bounds=(lower, upper),
                        x_scale=np.maximum(np.abs(x0), 1e-3), diff_step=1e-4)
    if not sol.success:
        raise CalibrationError(f'fit did not converge: {sol.message}')
    res = sol.fun
    dof = max(n - len(names), 1)
    s2 = float(res @ res) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(len(names), np.inf)
    return CalibrationResult(
        values={k: float(v) for k, v in zip(names, sol.x)},
        std_errors={k: float(v) for k, v in zip(names, std)},
        before={k: float(v) for k, v in zip(names, x0)},
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
