"""The sim-to-real gap diagnosis: calibrate, locate, name the effect, measure the shrink.

Steps (all fits on the training part, all judgements on the held-out part):

1. nominal: the model's prediction; calibrate what a lab calibrates anyway
   (force gain = efficiency scale, jaw-encoder zero and scale), reported apart;
2. where: the calibrated residual binned over operating regions, ranked by share
   of the held-out gap;
3. which: every effect of :data:`EFFECTS` fitted as an augmentation, ranked by a
   held-out score (change of log mean-square error of both channels, plus a
   per-parameter penalty); ``none`` unless the best one lowers it by a margin;
4. how far: held-out RMS gap before and after the winning effect.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from grip_force_ros.diagnosis.effects import EFFECT_NAMES, EFFECTS, NONE, SPRING_ANGLES, stroke_range
from grip_force_ros.diagnosis.frame import (JAW_SIDE_CABLE_LENGTH, DiagnosisError, build_frame,
                                            load_decimated, measured_of)
from grip_force_ros.objects import OBJECTS

#: Held-out score margin for naming an effect: the mean-square error (both channels
#: summed in log) must fall by at least this fraction, beyond the parameter penalty.
MIN_IMPROVEMENT = 0.15
#: Training rows used per fit at most (an even subsample beyond; 10 min at 200 Hz).
MAX_FIT_ROWS = 120_000
#: Huber threshold in robust standard deviations of the calibrated residual.
HUBER_K = 2.0
#: Penalty per fitted parameter (grid parameter included), in log mean-square error.
PARAM_PENALTY = 0.01
#: Default split of a log into time blocks when no test logs are given.
BLOCKS = 6
FOLDS = 3

UNITS = {'grip_force': 'N', 'jaw_torque': 'N*m'}


@dataclass
class Diagnosis:
    """The JSON result, plus held-out series for the report's plots."""

    result: dict
    series: dict = field(default_factory=dict)


def _lstsq(X: np.ndarray, y: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
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


def _block_bootstrap_std(X, y, rng, blocks: int = 20, draws: int = 200) -> np.ndarray:
    """Std of least-squares coefficients over a moving-block bootstrap (keeps autocorrelation)."""
    n, k = X.shape
    if n < 2 * blocks:
        return np.full(k, np.nan)
    edges = np.linspace(0, n, blocks + 1).astype(int)
    xtx = np.stack([X[a:b].T @ X[a:b] for a, b in zip(edges[:-1], edges[1:])])
    xty = np.stack([X[a:b].T @ y[a:b] for a, b in zip(edges[:-1], edges[1:])])
    picks = rng.integers(0, blocks, size=(draws, blocks))
    coefs = []
    for p in picks:
        try:
            coefs.append(np.linalg.solve(xtx[p].sum(0), xty[p].sum(0)))
        except np.linalg.LinAlgError:
            continue
    return np.std(coefs, axis=0) if len(coefs) > 2 else np.full(k, np.nan)


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float('nan')


def _concat(frames, key):
    return np.concatenate([f[key] for f in frames])


class _Data:
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
        # angle calibration: zero, scale, the cable's elastic stretch under both tensions and
        # the lag of the jaw behind the drum in motion
        # (the scale r0/r_n is geometry: kept, so the target is jaw - jaw_model)
        self.angle_target = self.jaw - self.jaw_model
        self.angle_base = np.column_stack([np.ones_like(self.jaw), _concat(frames, 'drum_tension'),
                                           _concat(frames, 'jaw_tension'), self.jaw_velocity])
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


def _huber_lstsq(X, y, scale: float, iterations: int = 2):
    """Solve least squares with Huber weights (threshold HUBER_K * scale).

    Episodes the nominal model misses (impacts, stuck cables) do not steer an
    effect's coefficients.
    """
    coef = _lstsq(X, y)
    if not scale > 0:
        return coef
    for _ in range(iterations):
        r = np.abs(y - X @ coef)
        coef = _lstsq(X, y, np.minimum(1.0, HUBER_K * scale / np.maximum(r, 1e-300)))
    return coef


def _huber_ms(r, scale: float) -> float:
    """Mean Huber loss (as a mean square: quadratic within HUBER_K * scale, linear beyond)."""
    if not scale > 0:
        return float(np.mean(r ** 2))
    c = HUBER_K * scale
    a = np.abs(r)
    return float(np.mean(np.where(a <= c, a * a, 2.0 * c * a - c * c)))


def _channel_fit(data: _Data, X, fold: int, force: bool):
    """Fit one channel on one fold: training loss and held-out residual.

    A design that is just the channel's baseline (no column of the effect) is fitted
    once and cached.
    """
    base_width = 1 if force else data.angle_base.shape[1]
    key = (fold, force)
    is_base = X.shape[1] == base_width and (not force or np.array_equal(X[:, 0], data.nominal))
    if is_base and key in data.base_cache:
        return data.base_cache[key]
    tr, te = data.fold_index[fold]
    Xtr = X[tr]
    if force:
        ytr = data.y[tr]
        coef = _huber_lstsq(Xtr, ytr, data.force_scale)
        loss = _huber_ms(ytr - Xtr @ coef, data.force_scale)
        resid = data.y[te] - X[te] @ coef
    else:
        ytr = data.angle_target[tr]
        coef = _lstsq(Xtr, ytr)
        loss = float(np.mean((ytr - Xtr @ coef) ** 2))
        resid = data.angle_target[te] - X[te] @ coef
    out = (loss, resid)
    if is_base:
        data.base_cache[key] = out
    return out


def _fold_fit(data: _Data, Xf, Xa, fold: int):
    mse_f, rf = _channel_fit(data, Xf, fold, True)
    mse_a, ra = _channel_fit(data, Xa, fold, False)
    objective = math.log(max(mse_f, 1e-300)) + math.log(max(mse_a, 1e-300))
    return objective, rf, ra


def _evaluate(data: _Data, designs, grid):
    """Fit every grid value on each fold's training part; keep each fold's best.

    Each fold's best is chosen by its own training objective; held-out residuals come
    from the fold that did not see them.

    Returns held-out residual arrays (force, angle; zero outside the held-out part), the
    pooled held-out MSEs, and the grid value chosen by most folds.
    """
    best = [None] * len(data.folds)
    for value in grid:
        Xf, Xa = designs(value)
        for k in range(len(data.folds)):
            objective, rf, ra = _fold_fit(data, Xf, Xa, k)
            if best[k] is None or objective < best[k][0]:
                best[k] = (objective, value, rf, ra)
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
            'test_loss_f': _huber_ms(resid_f[te], data.force_scale)}


def _full_fit(data: _Data, Xf, Xa, rng):
    """Coefficients on every sample the fits may see, with block-bootstrap std."""
    tr = np.flatnonzero(data.train)
    tr = tr[::max(1, int(np.ceil(tr.size / MAX_FIT_ROWS)))]
    cf = _huber_lstsq(Xf[tr], data.y[tr], data.force_scale)
    ca = _lstsq(Xa[tr], data.angle_target[tr])
    return (cf, ca, _block_bootstrap_std(Xf[tr], data.y[tr], rng),
            _block_bootstrap_std(Xa[tr], data.angle_target[tr], rng),
            float(np.mean((data.y[tr] - Xf[tr] @ cf) ** 2)))


#: Resolution floors (mean square) below which a channel's error counts as zero: 0.1 mrad of
#: jaw angle; for the measured column, FORCE_FLOOR times its RMS.
ANGLE_FLOOR_MS = 1e-8
FORCE_FLOOR = 1e-3


def _combine(data, first, other, first_name, other_name, fits, other_value):
    """Build the design of two effects together: both sets of columns.

    With a sensor delay the other effect's columns are delayed too (the sensor sees
    the whole force late).
    """
    (f1, a1), (f2, a2) = first, other
    if other_name == 'sensor_delay':
        Xf = data.shift(f1, float(other_value))
    elif first_name == 'sensor_delay':
        Xf = np.column_stack([f1, data.shift(f2[:, 1:], float(fits[first_name]['value']))])
    else:
        Xf = np.column_stack([f1, f2[:, 1:]])
    Xa = np.column_stack([a1, a2[:, 4:]])
    return Xf, Xa


def _score(fit, base, force_floor_ms: float) -> float:
    return (math.log((fit['test_loss_f'] + force_floor_ms) / (base['test_loss_f'] + force_floor_ms))
            + math.log((fit['test_mse_a'] + ANGLE_FLOOR_MS) / (base['test_mse_a'] + ANGLE_FLOOR_MS)))


def _regions(data: _Data, resid: np.ndarray, unit: str) -> list[dict]:
    """Held-out residual binned over operating regions, ranked by share of the gap."""
    te = data.test
    r2 = resid[te] ** 2
    total = float(r2.sum()) or 1.0
    n = int(te.sum())
    out = []

    def add(dimension, label, sel):
        k = int(sel.sum())
        if k == 0:
            return
        out.append({'where': f'{dimension}: {label}', 'dimension': dimension,
                    'share_of_gap': float(r2[sel].sum() / total), 'share_of_samples': k / n,
                    'rms': _rms(resid[te][sel]), 'mean': float(np.mean(resid[te][sel])), 'unit': unit})

    def tertiles(dimension, values, fmt, value_unit):
        v = values[te]
        if v.size == 0 or np.ptp(v) <= 1e-12 * max(1.0, float(np.max(np.abs(v)))):
            add(dimension, f'constant ({fmt(float(v[0]) if v.size else 0.0)} {value_unit})',
                np.ones(v.size, dtype=bool))
            return
        edges = np.quantile(v, [0, 1 / 3, 2 / 3, 1])
        for i, name in enumerate(('low', 'mid', 'high')):
            lo, hi = edges[i], edges[i + 1]
            sel = (v >= lo) & ((v < hi) if i < 2 else (v <= hi))
            add(dimension, f'{name} ({fmt(lo)}..{fmt(hi)} {value_unit})', sel)

    tertiles('current level', data.current, lambda x: f'{x:.3g}', 'A')
    tertiles('jaw angle', data.jaw, lambda x: f'{x:.3g}', 'rad')
    tertiles('wrist angle', data.wrist, lambda x: f'{x:.3g}', 'rad')
    tertiles('jaw speed', np.abs(data.jaw_velocity), lambda x: f'{x:.3g}', 'rad/s')
    rate = data.current_rate[te]
    thr = 0.25 * float(np.std(rate)) if rate.size else 0.0
    add('direction of motion', 'closing (current rising)', rate > thr)
    add('direction of motion', 'opening (current falling)', rate < -thr)
    add('direction of motion', 'holding (current steady)', np.abs(rate) <= thr)
    lt = data.load_time[te]
    loaded = data.contact[te] > 0
    add('time under load', 'not loaded', ~loaded)
    add('time under load', 'loaded < 1 s', loaded & (lt < 1.0))
    add('time under load', 'loaded 1..5 s', loaded & (lt >= 1.0) & (lt < 5.0))
    add('time under load', 'loaded > 5 s', loaded & (lt >= 5.0))
    obj = data.object[te]
    for code in np.unique(obj):
        add('object', OBJECTS[int(code)], obj == code)
    # a region holding every sample (a constant wrist, one object) says nothing: last
    out.sort(key=lambda r: (r['share_of_samples'] > 0.999, -r['share_of_gap']))
    return out


def _describe(effect, value, force_coefs, force_stds, angle_coefs, angle_stds, gain: float,
              unit: str) -> dict:
    """Describe the fitted parameters of one effect with their physical meaning.

    Its coefficients (force columns, then angle columns) and stds, any derived
    figures, and its grid value.
    """
    out = {}
    for (pname, punit, transform), coef, std in zip(
            effect.describe, list(force_coefs) + list(angle_coefs), list(force_stds) + list(angle_stds)):
        val = float(transform(float(coef), gain))
        scale = abs(val / coef) if coef else 1.0
        out[pname] = {'value': val, 'std': float(std) * scale, 'unit': punit.replace('unit of y', unit)}
    if effect.summary is not None:
        for sname, (sval, sunit) in effect.summary(force_coefs[:len(effect.force_params)], value).items():
            out[sname] = {'value': sval, 'std': None, 'unit': sunit,
                          'note': 'derived from the fitted coefficients'}
    if effect.grid_name and isinstance(value, tuple):
        # (which signal the direction state follows, its width)
        source, width = value
        out[effect.grid_name] = {'value': width, 'std': None, 'direction_state_of': source,
                                 'unit': 'rad' if source == 'motor_angle' else
                                 ('N*m' if source == 'drive_torque' else '-'),
                                 'note': 'picked from a grid on the training parts'}
    elif effect.grid_name:
        out[effect.grid_name] = {'value': value, 'std': None, 'unit': effect.grid_unit,
                                 'note': 'picked from a grid on the training parts'}
    return out


def _set_strokes(train_frames, frames) -> None:
    """Give every frame the stroke (rad) of each angle a position spring may follow.

    Taken over the loaded, steady samples of the training logs: one spring is one
    torque per angle in every log (an input range, no measured value enters it).
    """
    strokes = {}
    for key in set(SPRING_ANGLES.values()):
        parts = [f[key][(f['contact'] > 0) & (f['steady'] > 0)] for f in train_frames]
        values = np.concatenate(parts) if parts else np.zeros(0)
        if values.size < 2:
            values = np.concatenate([f[key] for f in train_frames])
        strokes[key] = stroke_range(values)
    for f in frames:
        f['stroke'] = strokes


def _fold_tests(frames, n_train_logs, have_test_logs, blocks, folds):
    """Held-out masks of each fold: the test logs, or interleaved time blocks of every log."""
    if have_test_logs:
        return [np.concatenate([np.full(len(f['t']), i >= n_train_logs) for i, f in enumerate(frames)])]
    block = []
    for f in frames:
        t = f['t']
        block.append(np.minimum((t - t[0]) / max(t[-1] - t[0], 1e-12) * blocks, blocks - 1).astype(int))
    block = np.concatenate(block)
    return [(block % folds) == k for k in range(folds)]


def _default_model(params):
    """Build the nominal model of ``params`` (the schema defaults when None)."""
    from grip_force_ros.model import GripForceModel
    if params is None:
        from grip_force_ros.params import make_params
        params = make_params()
    return GripForceModel(params)


def _prepare(train_logs, test_logs, model, analysis_rate, default_object, blocks, folds,
             jaw_side_cable_length, say):
    """Step 0: logs -> frames (training logs first) -> the pooled :class:`_Data` with its folds.

    Returns
    -------
    data : _Data
    frames : list of dict
        One analysis frame per log.
    measured : str
        The measured column, 'grip_force' (N) or 'jaw_torque' (N*m).
    """
    logs = [load_decimated(x, analysis_rate) for x in train_logs + test_logs]
    measured = measured_of(logs)
    say(f'building frames of {len(logs)} log(s) at {analysis_rate:g} Hz')
    frames = [build_frame(log, model, measured=measured, default_object=default_object,
                          jaw_side_cable_length=jaw_side_cable_length) for log in logs]
    _set_strokes(frames[:len(train_logs)], frames)
    data = _Data(frames, _fold_tests(frames, len(train_logs), bool(test_logs), blocks, folds))
    return data, frames, measured


def _split(data: _Data, frames, n_train: int, n_test: int, blocks: int, folds: int,
           analysis_rate: float) -> dict:
    """How the logs were split into training and held-out parts (the result's ``split``).

    Raises
    ------
    DiagnosisError
        Too few samples in either part, or no predicted load in the training part.
    """
    if n_test:
        split = {'method': 'files', 'train_logs': n_train, 'test_logs': n_test,
                 'description': f'fitted on {n_train} log(s), judged on {n_test} other log(s)'}
    else:
        split = {'method': 'time_blocks', 'blocks': blocks, 'folds': folds,
                 'description': f'each log cut into {blocks} equal time blocks; {folds}-fold: fold k holds '
                                f'out blocks b with b % {folds} == k and fits on the others, so every '
                                'held-out residual comes from a fit that never saw it'}
    if data.train.sum() < 10 or data.test.sum() < 10:
        raise DiagnosisError('too few samples in the training or the held-out part')
    if not np.any(data.contact[data.train] > 0):
        raise DiagnosisError('the model predicts no load anywhere in the training part: nothing to '
                             'compare (check the object column or --object)')
    split.update({'train_seconds': float(data.train.sum() * np.mean([f['dt'] for f in frames])),
                  'test_seconds': float(data.test.sum() * np.mean([f['dt'] for f in frames])),
                  'analysis_rate_hz': analysis_rate,
                  'transient_share': data.transient_share,
                  'transients': 'samples within 0.2 s of the predicted load starting or stopping '
                                '(impact, fly-off) are left out of every fit and score'})
    return split


def _robust_force_scale(data: _Data) -> float:
    """Return the robust scale (unit of y) of the residual of the gain-calibrated nominal.

    The MAD of the training samples, times 1.4826 (a standard deviation for Gaussian
    noise).
    """
    tr = data.train
    g0 = _lstsq(data.nominal[tr, None], data.y[tr])[0]
    r0 = data.y[tr] - g0 * data.nominal[tr]
    return float(1.4826 * np.median(np.abs(r0 - np.median(r0))))


def _calibrate(data: _Data, rng, measured: str, jaw_side_cable_length: float):
    """Step 1: the nominal model and what a lab calibrates anyway (force gain, jaw zero, ...).

    Returns
    -------
    base : dict
        Held-out fit of the calibrated nominal (:func:`_evaluate`).
    gain : float
        Force gain, measured / model (-).
    calibration : dict
        The result's ``calibration`` section.
    """
    Xf0 = data.nominal[:, None]
    Xa0 = data.angle_base
    base = _evaluate(data, lambda _: (Xf0, Xa0), (None,))
    cf0, ca0, sf0, a_std, _ = _full_fit(data, Xf0, Xa0, rng)
    gain, gain_std = float(cf0[0]), float(sf0[0])
    raw_gap = _rms(data.y[data.test] - data.nominal[data.test])
    calibration = {
        'force_gain': {'value': gain, 'std': gain_std, 'unit': '-',
                       'meaning': f'measured {measured} / model {measured} (efficiency scale)'},
        'jaw_angle_offset': {'value': float(ca0[0]), 'std': float(a_std[0]),
                             'unit': 'rad', 'meaning': 'jaw encoder zero'},
        'jaw_angle_per_drum_tension': {'value': float(ca0[1]), 'std': float(a_std[1]),
                                       'unit': 'rad/N', 'meaning': 'cable stretch, drum side'},
        'jaw_angle_per_jaw_tension': {'value': float(ca0[2]), 'std': float(a_std[2]),
                                      'unit': 'rad/N', 'meaning': 'cable stretch, jaw side'},
        'jaw_angle_lag': {'value': float(ca0[3]), 'std': float(a_std[3]),
                          'unit': 's', 'meaning': 'jaw angle per jaw velocity (dynamic lag)'},
        'jaw_side_cable_length': {'value': jaw_side_cable_length, 'std': None, 'unit': 'm',
                                  'meaning': 'given (not fitted): cable stiffness E*A/length seen '
                                             'by a stuck cable'},
        'gap_uncalibrated': raw_gap,
        'note': 'calibrated as a lab would (values: fit on all training samples; the held-out gaps use '
                'per-fold fits); not counted as an unmodelled effect',
    }
    return base, gain, calibration


def _rank_effects(data: _Data, base: dict, gain: float, rng, force_floor_ms: float,
                  param_penalty: float, min_improvement: float, unit: str, say):
    """Step 3: every effect fitted as an augmentation, ranked by held-out score (lower is better).

    Returns
    -------
    ranking : list of dict
        One entry per effect and one for ``none``, sorted by score.
    fits : dict
        Effect name -> its held-out fit; held-out residual arrays are kept only for the
        best effect (memory).
    """
    ranking = []
    fits = {}
    best_score = math.inf
    for name in EFFECT_NAMES:
        effect = EFFECTS[name]
        say(f'fitting {name}')
        fit = _evaluate(data, lambda v, e=effect: data.designs(e, v), effect.grid)
        value = fit['value']
        Xf, Xa = data.designs(effect, value)
        cf, ca, sf, sa, train_mse = _full_fit(data, Xf, Xa, rng)
        score = _score(fit, base, force_floor_ms) + param_penalty * effect.n_params
        # held-out residual arrays are kept only for the best effect so far (memory)
        if score < best_score:
            best_score = score
            for other in fits.values():
                other.pop('resid_f', None)
                other.pop('resid_a', None)
        else:
            fit = {k: v for k, v in fit.items() if not k.startswith('resid')}
        fits[name] = fit
        g = float(cf[0])
        params_out = _describe(effect, value, cf[1:], sf[1:], ca[4:], sa[4:], g, unit)
        ranking.append({'effect': name, 'holdout_rmse': math.sqrt(fit['test_mse_f']),
                        'holdout_angle_rmse': math.sqrt(fit['test_mse_a']),
                        'train_rmse': math.sqrt(train_mse),
                        'score': score, 'n_params': effect.n_params, 'gain': g, 'params': params_out})
    ranking.append({'effect': NONE, 'holdout_rmse': math.sqrt(base['test_mse_f']),
                    'holdout_angle_rmse': math.sqrt(base['test_mse_a']),
                    'train_rmse': None, 'score': math.log(1.0 - min_improvement),
                    'n_params': 0, 'gain': gain, 'params': {}})
    ranking.sort(key=lambda r: r['score'])
    return ranking, fits


def _second_effect(data: _Data, winner: str, fits: dict, rng, force_floor_ms: float,
                   param_penalty: float, min_improvement: float, unit: str, say):
    """Step 4a: a second effect on top of the first (pairs of effects).

    Same margin as the first, judged against the first effect's held-out loss.

    Returns
    -------
    tuple or None
        (name, held-out fit of both effects, the second effect's described parameters,
        fitted beside the first on every training sample), or None when no effect passes.
    """
    say('looking for a second effect')
    first_design = data.designs(EFFECTS[winner], fits[winner]['value'])

    def pair(value, name):
        other = data.designs(EFFECTS[name], value)
        return _combine(data, first_design, other, winner, name, fits, value)

    best2 = None
    for name in EFFECT_NAMES:
        if name == winner:
            continue
        fit2 = _evaluate(data, lambda value, name=name: pair(value, name), EFFECTS[name].grid)
        score2 = _score(fit2, fits[winner], force_floor_ms) + param_penalty * EFFECTS[name].n_params
        say(f'second effect {name}: held-out {math.sqrt(fit2["test_mse_f"]):.4g} {unit}, score {score2:.3f}')
        if score2 < math.log(1.0 - min_improvement) and (best2 is None or score2 < best2[0]):
            best2 = (score2, name, fit2)
    if best2 is None:
        return None
    _, name, final = best2
    second = EFFECTS[name]
    Xf, Xa = pair(final['value'], name)
    cf, ca, sf, sa, _ = _full_fit(data, Xf, Xa, rng)
    nf, na = len(second.force_params), len(second.angle_params)
    described = _describe(second, final['value'], cf[len(cf) - nf:], sf[len(sf) - nf:],
                          ca[len(ca) - na:], sa[len(sa) - na:], float(cf[0]), unit)
    return name, final, described


def _verdict(base: dict, fits: dict, ranking: list, second, unit: str, measured: str,
             param_penalty: float, min_improvement: float):
    """Step 4b: how far the gap shrinks with every named effect (the result's ``verdict``).

    Returns
    -------
    verdict : dict
    final : dict
        Held-out fit with every named effect (``base`` when none is named).
    """
    winner = ranking[0]['effect']
    gap_before = math.sqrt(base['test_mse_f'])
    angle_before = math.sqrt(base['test_mse_a'])
    named = [] if winner == NONE else [winner]
    final = base if winner == NONE else fits[winner]
    first_gap = math.sqrt(final['test_mse_f'])
    second_params = None
    if second is not None:
        name, final, second_params = second
        named.append(name)
    gap_after = math.sqrt(final['test_mse_f'])
    angle_after = math.sqrt(final['test_mse_a'])
    verdict = {'effect': winner, 'effects': named or [NONE], 'gap_before': gap_before, 'gap_after': gap_after,
               'gap_after_first': first_gap,
               'second_effect_params': second_params,
               'shrink': 1.0 - gap_after / gap_before if gap_before > 0 else 0.0,
               'unit': unit, 'measured': measured,
               'angle_gap_before': angle_before, 'angle_gap_after': angle_after, 'angle_unit': 'rad',
               'runner_up': ranking[1]['effect'],
               'rule': f'an effect is named when its held-out score (log ratio of the Huber loss of the '
                       f'force + log ratio of the angle MSE, +{param_penalty} per parameter) is below '
                       f'log(1 - {min_improvement}); a second effect when it passes the same margin on '
                       f'top of the first; gap_after is with every named effect'}
    return verdict, final


def _held_out_series(data: _Data, base: dict, resid_after: np.ndarray) -> dict:
    """Held-out signals for the report's plots: measured, calibrated nominal, with the effects."""
    te = data.test
    return {'t': data.t[te], 'log_index': data.log_index[te], 'y': data.y[te],
            'calibrated': (data.y - base['resid_f'])[te], 'after': (data.y - resid_after)[te],
            'resid_before': base['resid_f'][te], 'resid_after': resid_after[te],
            'jaw': data.jaw[te], 'jaw_before': (data.jaw - base['resid_a'])[te],
            'current': data.current[te], 'wrist': data.wrist[te], 'jaw_velocity': data.jaw_velocity[te],
            'load_time': data.load_time[te], 'current_rate': data.current_rate[te]}


def run_diagnosis(train_logs: Sequence, test_logs: Sequence | None = None, params=None, *,
                  model=None, analysis_rate: float = 200.0, default_object: str = 'needle',
                  blocks: int = BLOCKS, folds: int = FOLDS,
                  min_improvement: float = MIN_IMPROVEMENT, param_penalty: float = PARAM_PENALTY,
                  jaw_side_cable_length: float = JAW_SIDE_CABLE_LENGTH,
                  seed: int = 0, progress=None) -> Diagnosis:
    """Diagnose the gap between the model and measured logs (see :func:`diagnose`).

    The steps of the module docstring, in order; ``seed`` seeds the block bootstrap of
    the coefficients' standard deviations (one generator, drawn in step order).
    """
    model = _default_model(params) if model is None else model
    say = progress or (lambda msg: None)
    train_logs = list(train_logs)
    test_logs = list(test_logs or [])
    if not train_logs:
        raise DiagnosisError('no logs to diagnose')
    data, frames, measured = _prepare(train_logs, test_logs, model, analysis_rate, default_object,
                                      blocks, folds, jaw_side_cable_length, say)
    unit = UNITS[measured]
    split = _split(data, frames, len(train_logs), len(test_logs), blocks, folds, analysis_rate)
    rng = np.random.default_rng(seed)
    data.force_scale = _robust_force_scale(data)
    base, gain, calibration = _calibrate(data, rng, measured, jaw_side_cable_length)      # 1.
    force_floor_ms = (FORCE_FLOOR * _rms(data.y[data.test])) ** 2
    ranking, fits = _rank_effects(data, base, gain, rng, force_floor_ms, param_penalty,     # 3.
                                  min_improvement, unit, say)
    winner = ranking[0]['effect']
    second = None if winner == NONE else _second_effect(                                    # 4.
        data, winner, fits, rng, force_floor_ms, param_penalty, min_improvement, unit, say)
    verdict, final = _verdict(base, fits, ranking, second, unit, measured, param_penalty,
                              min_improvement)
    regions = _regions(data, base['resid_f'], unit)                                          # 2.
    result = {'verdict': verdict, 'ranking': ranking, 'regions': regions, 'split': split,
              'calibration': calibration, 'measured': measured, 'unit': unit,
              'samples': {'train': int(data.train.sum()), 'test': int(data.test.sum())}}
    return Diagnosis(result, _held_out_series(data, base, final['resid_f']))


def diagnose(train_logs: Sequence, test_logs: Sequence | None = None, params=None, **kwargs) -> dict:
    """Where the model disagrees with the logs, which effect explains it, how far the gap shrinks.

    Parameters
    ----------
    train_logs : sequence of log dicts or paths
        Logs in the DESIGN.md contract (see :mod:`grip_force_ros.logs`). Without
        ``test_logs`` each is split into time blocks (train / held out).
    test_logs : sequence of log dicts or paths, optional
        Held-out logs the fits never see.
    params : ParamSet, optional
        Instrument parameters of the nominal model (defaults when omitted).
    **kwargs
        ``model``, ``analysis_rate`` (Hz), ``default_object``, ``blocks``, ``folds``,
        ``min_improvement``, ``param_penalty``, ``jaw_side_cable_length``
        (m), ``seed``, ``progress``.

    Returns
    -------
    dict
        ``{"verdict": {"effect", "gap_before", "gap_after", ...}, "ranking": [...],
        "regions": [...], "split": {...}, "calibration": {...}}``, gaps in the unit of
        the measured column (N or N*m), RMS on held-out data.
    """
    return run_diagnosis(train_logs, test_logs, params, **kwargs).result
