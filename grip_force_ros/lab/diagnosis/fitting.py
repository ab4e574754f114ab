"""Held-out fitting of the diagnosis: pooled frames, folds, robust least squares, scores.

The machinery :mod:`grip_force_ros.lab.diagnosis.engine` runs its steps with: the logs'
frames pooled into one :class:`PooledData` with its train/held-out masks per fold;
(Huber-weighted) least squares on unit-scaled columns; every grid value of an effect
fitted on each fold's training part and judged on its held-out part (:func:`evaluate`);
the coefficients on all training samples with block-bootstrap standard deviations
(:func:`full_fit`); and the held-out score of one fit against another
(:func:`held_out_score`). Units: those of the measured column (N or N*m) and rad.
"""
from __future__ import annotations

import math

import numpy as np

from grip_force_ros.identify.calibration import block_bootstrap_std

__all__ = ['MAX_FIT_ROWS', 'HUBER_K', 'ANGLE_FLOOR_MS', 'FORCE_FLOOR', 'PooledData', 'lstsq',
           'block_bootstrap_std', 'rms', 'huber_lstsq', 'huber_ms', 'channel_fit', 'fold_fit',
           'neighbours', 'evaluate', 'full_fit', 'combine_designs', 'held_out_score']

#: Training rows used per fit at most (an even subsample beyond; 10 min at 200 Hz).
MAX_FIT_ROWS = 120_000
#: Huber threshold in robust standard deviations of the calibrated residual.
HUBER_K = 2.0


def lstsq(X: np.ndarray, y: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Solve (weighted) least squares of a tall, narrow X by its normal equations.

    Columns are scaled to unit norm first (fast for n >> k; falls back to lstsq when
    singular).
    """
    Xw = X if weights is None else X * weights[:, None]
    norms = np.sqrt(np.einsum('ij,ij->j', Xw, Xw))
    norms[norms == 0] = 1.0
    A = (Xw.T @ X) / np.outer(norms, norms)
    b = (Xw.T @ y) / norms
    try:
        if np.linalg.cond(A) > 1e10:
            raise np.linalg.LinAlgError
        return np.linalg.solve(A, b) / norms
    except np.linalg.LinAlgError:
        sw = np.ones(len(y)) if weights is None else np.sqrt(weights)
        coef, *_ = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)
        return coef


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float('nan')


def _concat(frames, key):
    return np.concatenate([f[key] for f in frames])


class PooledData:
    """Frames of all logs, concatenated, with the train/test masks."""

    def __init__(self, frames, fold_tests):
        self.frames = frames
        steady = _concat(frames, 'steady') > 0
        #: (train, test) masks of each fold; the test parts are disjoint
        self.folds = [(~test & steady, test & steady) for test in fold_tests]
        self.test = np.zeros(steady.size, dtype=bool)
        for _, test in self.folds:
            self.test |= test
        #: what the reported parameters are fitted on: every steady sample the fits may see
        self.train = steady & ~self.test if len(self.folds) == 1 else steady.copy()
        self.transient_share = float(1.0 - steady.mean())
        #: robust scale (N or N*m) of the calibrated nominal residual, for the Huber loss
        self.force_scale = 0.0
        #: (train, test) row indices of each fold, and the baseline fits per (fold, channel)
        # long logs: the fits use an even subsample of at most MAX_FIT_ROWS training rows (the
        # held-out residuals still cover every held-out row), so the cost stops growing
        self.fold_index = []
        for tr, te in self.folds:
            rows = np.flatnonzero(tr)
            stride = max(1, int(np.ceil(rows.size / MAX_FIT_ROWS)))
            self.fold_index.append((rows[::stride], np.flatnonzero(te)))
        self.base_cache: dict = {}
        for key in ('y', 'nominal', 'jaw', 'jaw_model', 'contact', 'current', 'current_rate', 'wrist',
                    'jaw_velocity', 'load_time', 'object', 't'):
            setattr(self, key, _concat(frames, key))
        #: the force channel's base columns: the nominal and, when the frames have them, its
        #: derivatives by the re-identified parameters (a local refit of them with every effect)
        self.base = (np.concatenate([f['base'] for f in frames]) if all('base' in f for f in frames)
                     else self.nominal[:, None])
        self.force_base_width = self.base.shape[1]
        # angle calibration: the encoder zero, the cable's elastic stretch on the drum side and on
        # the jaw side (their coefficients: the re-identified stiffness refitted, and the split
        # of the cable left free), the lag of the jaw behind the drum in motion
        # and the wrist (the re-identified coupling refitted); the scale r0/r_n is geometry:
        # kept, so the target is jaw - jaw_model
        self.angle_target = self.jaw - self.jaw_model
        self.angle_base = np.column_stack([np.ones_like(self.jaw), _concat(frames, 'stretch_drum'),
                                           _concat(frames, 'stretch_jaw'), self.jaw_velocity, self.wrist])
        #: columns of the angle channel's base (an effect's angle columns follow them)
        self.angle_base_width = self.angle_base.shape[1]
        self.log_index = np.concatenate([np.full(len(f['t']), i) for i, f in enumerate(frames)])

    def shift(self, X, delay: float):
        """Columns of X delayed by ``delay`` (s), log by log: what a delayed sensor would see."""
        out = np.empty_like(X)
        for i in np.unique(self.log_index):
            sel = self.log_index == i
            t = self.t[sel]
            for j in range(X.shape[1]):
                out[sel, j] = np.interp(t - delay, t, X[sel, j])
        return out

    def designs(self, effect, grid_value):
        parts = [effect.build(f, grid_value) for f in self.frames]
        base = np.concatenate([d.force_base for d in parts])
        fcols = [np.concatenate([d.force_cols[j] for d in parts]) for j in range(len(parts[0].force_cols))]
        acols = [np.concatenate([d.angle_cols[j] for d in parts]) for j in range(len(parts[0].angle_cols))]
        Xf = np.column_stack([base] + fcols)
        Xa = np.column_stack([self.angle_base] + acols)
        return Xf, Xa


def huber_lstsq(X, y, scale: float, iterations: int = 2):
    """Solve least squares with Huber weights (threshold HUBER_K * scale).

    Episodes the nominal model misses (impacts, stuck cables) do not steer an
    effect's coefficients.
    """
    coef = lstsq(X, y)
    if not scale > 0:
        return coef
    for _ in range(iterations):
        r = np.abs(y - X @ coef)
        coef = lstsq(X, y, np.minimum(1.0, HUBER_K * scale / np.maximum(r, 1e-300)))
    return coef


def huber_ms(r, scale: float) -> float:
    """Mean Huber loss (as a mean square: quadratic within HUBER_K * scale, linear beyond)."""
    if not scale > 0:
        return float(np.mean(r ** 2))
    c = HUBER_K * scale
    a = np.abs(r)
    return float(np.mean(np.where(a <= c, a * a, 2.0 * c * a - c * c)))


def channel_fit(data: PooledData, X, fold: int, force: bool):
    """Fit one channel on one fold: training loss and held-out residual.

    A design that is just the channel's baseline (no column of the effect) is fitted
    once and cached.
    """
    base_width = data.force_base_width if force else data.angle_base.shape[1]
    key = (fold, force)
    is_base = X.shape[1] == base_width and (not force or np.array_equal(X[:, 0], data.nominal))
    if is_base and key in data.base_cache:
        return data.base_cache[key]
    tr, te = data.fold_index[fold]
    Xtr = X[tr]
    if force:
        ytr = data.y[tr]
        coef = huber_lstsq(Xtr, ytr, data.force_scale)
        loss = huber_ms(ytr - Xtr @ coef, data.force_scale)
        resid = data.y[te] - X[te] @ coef
    else:
        ytr = data.angle_target[tr]
        coef = lstsq(Xtr, ytr)
        loss = float(np.mean((ytr - Xtr @ coef) ** 2))
        resid = data.angle_target[te] - X[te] @ coef
    out = (loss, resid)
    if is_base:
        data.base_cache[key] = out
    return out


def fold_fit(data: PooledData, Xf, Xa, fold: int):
    mse_f, rf = channel_fit(data, Xf, fold, True)
    mse_a, ra = channel_fit(data, Xa, fold, False)
    objective = math.log(max(mse_f, 1e-300)) + math.log(max(mse_a, 1e-300))
    return objective, rf, ra


def neighbours(grid, value) -> list:
    """Values between ``value`` and its neighbours on the grid: geometric midpoints of the numeric width.

    A grid value is a number (a time constant, a delay, a width) or a tuple whose second
    element is one (``(source, width[, ...])``: neighbours share the other elements). A
    non-numeric value (None, a name) has no neighbours.
    """
    def width(v):
        w = v[1] if isinstance(v, tuple) else v
        return float(w) if isinstance(w, (int, float)) and not isinstance(w, bool) and w > 0 else None

    def same_kind(v):
        return isinstance(v, tuple) == isinstance(value, tuple) and (
            not isinstance(v, tuple) or (len(v) == len(value) and v[:1] + v[2:] == value[:1] + value[2:]))

    w0 = width(value)
    if w0 is None:
        return []
    widths = sorted({width(v) for v in grid if same_kind(v) and width(v) is not None})
    i = widths.index(w0) if w0 in widths else None
    if i is None:
        return []
    out = []
    for j in (i - 1, i + 1):
        if 0 <= j < len(widths):
            mid = math.sqrt(w0 * widths[j])
            out.append(value[:1] + (mid,) + value[2:] if isinstance(value, tuple) else mid)
    return out


def evaluate(data: PooledData, designs, grid, refine: bool = True):
    """Fit every grid value on each fold's training part; keep each fold's best.

    Each fold's best is chosen by its own training objective; held-out residuals come
    from the fold that did not see them. With ``refine``, each fold then tries the geometric
    midpoints between its best value and the grid neighbours (:func:`neighbours`), so a time
    constant or a width between the grid points is not stuck at one of them.

    Returns held-out residual arrays (force, angle; zero outside the held-out part), the
    pooled held-out MSEs, and the grid value chosen by most folds.
    """
    best = [None] * len(data.folds)

    def consider(value, folds):
        Xf, Xa = designs(value)
        for k in folds:
            objective, rf, ra = fold_fit(data, Xf, Xa, k)
            if best[k] is None or objective < best[k][0]:
                best[k] = (objective, value, rf, ra)

    for value in grid:
        consider(value, range(len(data.folds)))
    if refine:
        candidates: dict = {}
        for k, b in enumerate(best):
            for v in neighbours(grid, b[1]):
                candidates.setdefault(v, []).append(k)
        for value, folds in candidates.items():
            consider(value, folds)
    resid_f = np.zeros(data.y.size)
    resid_a = np.zeros(data.y.size)
    for (_, te), (_, _, rf, ra) in zip(data.folds, best):
        resid_f[te] = rf
        resid_a[te] = ra
    te = data.test
    values = [b[1] for b in best]
    chosen = max(values, key=lambda v: (values.count(v), -values.index(v)))
    return {'resid_f': resid_f, 'resid_a': resid_a, 'value': chosen,
            'test_mse_f': float(np.mean(resid_f[te] ** 2)), 'test_mse_a': float(np.mean(resid_a[te] ** 2)),
            'test_loss_f': huber_ms(resid_f[te], data.force_scale)}


def full_fit(data: PooledData, Xf, Xa, rng):
    """Coefficients on every sample the fits may see, with block-bootstrap std."""
    tr = np.flatnonzero(data.train)
    tr = tr[::max(1, int(np.ceil(tr.size / MAX_FIT_ROWS)))]
    cf = huber_lstsq(Xf[tr], data.y[tr], data.force_scale)
    ca = lstsq(Xa[tr], data.angle_target[tr])
    return (cf, ca, block_bootstrap_std(Xf[tr], data.y[tr], rng),
            block_bootstrap_std(Xa[tr], data.angle_target[tr], rng),
            float(np.mean((data.y[tr] - Xf[tr] @ cf) ** 2)))


#: Resolution floors (mean square) below which a channel's error counts as zero: 0.1 mrad of
#: jaw angle; for the measured column, FORCE_FLOOR times its RMS.
ANGLE_FLOOR_MS = 1e-8
FORCE_FLOOR = 1e-3


def combine_designs(data, first, other, first_name, other_name, fits, other_value):
    """Build the design of two effects together: both sets of columns.

    With a sensor delay the other effect's columns are delayed too (the sensor sees
    the whole force late).
    """
    (f1, a1), (f2, a2) = first, other
    nb = data.force_base_width
    if other_name == 'sensor_delay':
        Xf = data.shift(f1, float(other_value))
    elif first_name == 'sensor_delay':
        Xf = np.column_stack([f1, data.shift(f2[:, nb:], float(fits[first_name]['value']))])
    else:
        Xf = np.column_stack([f1, f2[:, nb:]])
    Xa = np.column_stack([a1, a2[:, data.angle_base_width:]])
    return Xf, Xa


def held_out_score(fit, base, force_floor_ms: float) -> float:
    return (math.log((fit['test_loss_f'] + force_floor_ms) / (base['test_loss_f'] + force_floor_ms))
            + math.log((fit['test_mse_a'] + ANGLE_FLOOR_MS) / (base['test_mse_a'] + ANGLE_FLOOR_MS)))
