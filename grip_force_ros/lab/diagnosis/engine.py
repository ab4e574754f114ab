"""The sim-to-real gap diagnosis: calibrate, locate, name the effect, measure the shrink.

Steps (all fits on the training part, all judgements on the held-out part):

0. re-identify the instrument's own parameters (pulley friction, cable stiffness, torque
   gain, wrist-finger coupling; :mod:`.reidentify`): a real instrument never matches its
   YAML, and a parameter mismatch must not read as an unmodelled effect;
1. nominal: the re-identified model's prediction; calibrate what a lab calibrates anyway
   (force gain, jaw-encoder zero, stretch, lag), reported apart; the derivatives of the
   nominal by the re-identified parameters stay in every fit (a local refit of them);
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

from grip_force_ros.lab.diagnosis.effects import EFFECT_NAMES, EFFECTS, NONE, SPRING_ANGLES, stroke_range
from grip_force_ros.lab.diagnosis.fitting import (FORCE_FLOOR, MAX_FIT_ROWS, PooledData, combine_designs,
                                                  evaluate, full_fit, held_out_score, lstsq, rms)
from grip_force_ros.lab.diagnosis.frame import (DiagnosisError, assemble_frame, cable_lengths, frame_inputs,
                                                load_decimated, measured_of, nominal)
from grip_force_ros.lab.diagnosis.reidentify import Reidentified, reidentify
from grip_force_ros.objects import OBJECTS

#: Held-out score margin for naming an effect: the mean-square error (both channels
#: summed in log) must fall by at least this fraction, beyond the parameter penalty.
MIN_IMPROVEMENT = 0.15
#: Penalty per fitted parameter (grid parameter included), in log mean-square error.
PARAM_PENALTY = 0.01
#: An effect that acts on the measured column (it has force columns) is named only when that
#: column's held-out loss alone falls by at least this fraction: a jaw-angle residual of a few
#: tenths of a mrad must not name a friction whose force the data do not show (an angle-only
#: effect, backlash, is judged on the angle).
MIN_FORCE_SUPPORT = 0.05
#: Default split of a log into time blocks when no test logs are given.
BLOCKS = 6
FOLDS = 3

UNITS = {'grip_force': 'N', 'jaw_torque': 'N*m'}
#: Step (in log mu) of the nominal's derivative by the pulley friction coefficient (a central
#: difference: wide enough to average over samples switching between stick and slip).
FRICTION_STEP = 0.03
#: An effect whose fit moves log(mu) by more than this through the derivative column has the
#: friction refitted beside it (the linearisation no longer holds); at most JOINT_CANDIDATES
#: effects (the best-scoring), in at most JOINT_ITERATIONS Gauss-Newton steps of at most
#: JOINT_MAX_STEP each, until a step is below JOINT_TOLERANCE.
JOINT_STEP = 0.01
JOINT_CANDIDATES = 4
JOINT_ITERATIONS = 4
JOINT_MAX_STEP = 0.3
JOINT_TOLERANCE = 0.003


@dataclass
class Diagnosis:
    """The JSON result, plus held-out series for the report's plots."""

    result: dict
    series: dict = field(default_factory=dict)


def _regions(data: PooledData, resid: np.ndarray, unit: str) -> list[dict]:
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
                    'rms': rms(resid[te][sel]), 'mean': float(np.mean(resid[te][sel])), 'unit': unit})

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
        # (which signal the direction state follows, its width[, the drive's width on soft objects])
        source, width = value[:2]
        out[effect.grid_name] = {'value': width, 'std': None, 'direction_state_of': source,
                                 'unit': 'rad' if source == 'motor_angle' else
                                 ('N*m' if source == 'drive_torque' else '-'),
                                 'note': 'picked on the training parts (grid, refined between its points)'}
        if len(value) > 2:
            out['soft_direction_state_width'] = {'value': value[2], 'std': None,
                                                 'direction_state_of': 'motor_angle', 'unit': 'rad',
                                                 'note': 'picked from a grid on the training parts'}
    elif effect.grid_name:
        out[effect.grid_name] = {'value': value, 'std': None, 'unit': effect.grid_unit,
                                 'note': 'picked on the training parts (grid, refined between its points)'}
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


def _model_of(model):
    """Build models of other parameter sets of the same kind as ``model`` (losses kept)."""
    from grip_force_ros.model import GripForceModel
    losses = getattr(model, 'losses', True)
    return lambda p: GripForceModel(p, losses=losses)


def _default_model(params):
    """Build the nominal model of ``params`` (the schema defaults when None)."""
    from grip_force_ros.model import GripForceModel
    if params is None:
        from grip_force_ros.params import make_params
        params = make_params()
    return GripForceModel(params)


def _prepare(train_logs, test_logs, model, analysis_rate, default_object, blocks, folds,
             jaw_side_cable_length, say):
    """Step 0a: logs -> inputs and frames at the YAML (training logs first) -> :class:`PooledData`.

    Returns
    -------
    data : PooledData
    inputs : list of dict
        The parameter-free part of each log's frame (:func:`frame_inputs`).
    fold_tests : list of ndarray
        Held-out mask of each fold.
    measured : str
        The measured column, 'grip_force' (N) or 'jaw_torque' (N*m).
    """
    logs = [load_decimated(x, analysis_rate) for x in train_logs + test_logs]
    measured = measured_of(logs)
    say(f'building frames of {len(logs)} log(s) at {analysis_rate:g} Hz')
    inputs = [frame_inputs(log, measured=measured, default_object=default_object) for log in logs]
    frames = [assemble_frame(inp, model, jaw_side_cable_length=jaw_side_cable_length) for inp in inputs]
    fold_tests = _fold_tests(frames, len(train_logs), bool(test_logs), blocks, folds)
    return PooledData(frames, fold_tests), inputs, fold_tests, measured


def _training_rows(data: PooledData, frames) -> list[np.ndarray]:
    """Return the indices (within each frame) of the samples the fits may see, MAX_FIT_ROWS at most."""
    offsets = np.cumsum([0] + [len(f['t']) for f in frames])
    train = np.flatnonzero(data.train)
    train = train[::max(1, int(np.ceil(train.size / MAX_FIT_ROWS)))]
    return [train[(train >= a) & (train < b)] - a for a, b in zip(offsets[:-1], offsets[1:])]


def _reidentified_frames(inputs, params, model_of, jaw_side_cable_length, train_count: int, steady=None,
                         friction_column: bool = True):
    """Step 0b: frames of the re-identified model, with the nominal's derivative by log(mu) as a base column.

    The base columns of every fit are (nominal, d nominal / d log mu): the gain column refits
    the torque gain and this one the pulley friction, locally, beside each effect. Without
    ``friction_column`` (the friction was not identified: held at the YAML) the base is the
    nominal alone. ``steady``: the frames' masks of usable samples to keep (so that models of
    other frictions are judged on the same samples).
    """
    model = model_of(params)
    mu = float(params.pulley_friction_coefficient)
    frames = []
    for k, inp in enumerate(inputs):
        frame = assemble_frame(inp, model, jaw_side_cable_length=jaw_side_cable_length)
        if not friction_column:
            frame['base'] = frame['nominal'][:, None]
        elif mu > 0.0:
            up, down = (nominal(inp, model_of(params.replace(pulley_friction_coefficient=mu * factor)),
                                jaw_side_cable_length=jaw_side_cable_length)['nominal']
                        for factor in (math.exp(FRICTION_STEP), math.exp(-FRICTION_STEP)))
            slope = (up - down) / (2.0 * FRICTION_STEP)
        else:
            slope = np.zeros(len(frame['t']))
        if friction_column:
            frame['base'] = np.column_stack([frame['nominal'], slope])
        if steady is not None:
            frame['steady'] = steady[k]
        frames.append(frame)
    _set_strokes(frames[:train_count], frames)
    return frames


def _joint_refit(name, value, step, data: PooledData, inputs, params, model_of, jaw_side_cable_length,
                 train_count: int, fold_tests, yaml, modulus_follows: bool = True):
    """Refit the friction and the gain beside one effect (``name`` None: the base alone): Gauss-Newton.

    Each step rebuilds the frames at the friction, fits the effect with the base's derivative
    column on the training samples (robust) and moves log(mu) by the derivative's coefficient /
    the gain (starting with ``step``) and the torque constant by the gain. The cable modulus
    moves with the torque constant (``modulus_follows``, when the jaw angle identified it): the
    angle measured the stretch, tension / E, and the tension per ampere scales with the torque
    constant. Returns the pooled data of the refitted
    model (:func:`_pooled`), on the same samples as ``data``; None when a parameter goes to its
    bound, a factor MAX_FACTOR from the ``yaml`` ParamSet's value (not identified beside this
    effect, as in the re-identification).
    """
    from grip_force_ros.lab.diagnosis.fitting import huber_lstsq
    from grip_force_ros.lab.diagnosis.reidentify import MAX_FACTOR
    mu0 = float(params.pulley_friction_coefficient)                # the re-identified values
    torque0, modulus0 = float(params.torque_constant), float(params.cable_modulus)
    mu_yaml = float(yaml.pulley_friction_coefficient)
    if not (mu0 > 0.0 and data.force_base_width > 1):
        return None
    steady = [f['steady'] for f in data.frames]
    limit = math.log(MAX_FACTOR)
    log_mu, scale = math.log(mu0 / mu_yaml), 1.0
    torque_yaml = math.log(torque0 / float(yaml.torque_constant))
    refitted = None
    for _ in range(JOINT_ITERATIONS):
        log_mu += min(max(step, -JOINT_MAX_STEP), JOINT_MAX_STEP)
        if not (abs(log_mu) < limit and abs(torque_yaml + math.log(scale)) < limit):
            return None                     # at a bound: not identified beside this effect
        p = params.replace(pulley_friction_coefficient=mu_yaml * math.exp(log_mu),
                           torque_constant=torque0 * scale,
                           cable_modulus=modulus0 * (scale if modulus_follows else 1.0))
        frames = _reidentified_frames(inputs, p, model_of, jaw_side_cable_length, train_count, steady)
        refitted = _pooled(frames, fold_tests, p, data.force_scale)
        Xf = refitted.base if name is None else refitted.designs(EFFECTS[name], value)[0]
        tr = np.flatnonzero(refitted.train)
        tr = tr[::max(1, int(np.ceil(tr.size / MAX_FIT_ROWS)))]
        coef = huber_lstsq(Xf[tr], refitted.y[tr], refitted.force_scale)
        gain = float(coef[0])
        if not gain > 0.0:
            return None
        step = float(coef[1]) / gain
        scale *= gain
        if abs(step) < JOINT_TOLERANCE and abs(gain - 1.0) < JOINT_TOLERANCE:
            break
    if scale != float(p.torque_constant) / torque0:       # the last gain, applied
        if not abs(torque_yaml + math.log(scale)) < limit:
            return None
        p = p.replace(torque_constant=torque0 * scale,
                      cable_modulus=modulus0 * (scale if modulus_follows else 1.0))
        frames = _reidentified_frames(inputs, p, model_of, jaw_side_cable_length, train_count, steady)
        refitted = _pooled(frames, fold_tests, p, data.force_scale)
    return refitted


def _pooled(frames, fold_tests, params, force_scale: float | None = None) -> PooledData:
    """Pool ``frames``; remember the friction and torque constant of their model (and the force scale)."""
    data = PooledData(frames, fold_tests)
    data.friction = float(params.pulley_friction_coefficient)
    data.torque_constant = float(params.torque_constant)
    data.cable_modulus = float(params.cable_modulus)
    if force_scale is not None:
        data.force_scale = force_scale
    return data


def _split(data: PooledData, frames, n_train: int, n_test: int, blocks: int, folds: int,
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


def _robust_force_scale(data: PooledData) -> float:
    """Return the robust scale (unit of y) of the residual of the gain-calibrated nominal.

    The MAD of the training samples, times 1.4826 (a standard deviation for Gaussian
    noise).
    """
    tr = data.train
    g0 = lstsq(data.nominal[tr, None], data.y[tr])[0]
    r0 = data.y[tr] - g0 * data.nominal[tr]
    return float(1.4826 * np.median(np.abs(r0 - np.median(r0))))


def _calibrate(data: PooledData, rng, measured: str, jaw_side_cable_length: float,
               re: Reidentified, raw_gap: float):
    """Step 1: the re-identified nominal and what a lab calibrates anyway (force gain, jaw zero, ...).

    Returns
    -------
    base : dict
        Held-out fit of the calibrated nominal (:func:`evaluate`).
    gain : float
        Force gain, measured / re-identified model (-).
    calibration : dict
        The result's ``calibration`` section (with the re-identified ``parameters``).
    """
    Xf0 = data.base
    Xa0 = data.angle_base
    base = evaluate(data, lambda _: (Xf0, Xa0), (None,))
    cf0, ca0, sf0, a_std, _ = full_fit(data, Xf0, Xa0, rng)
    gain, gain_std = float(cf0[0]), float(sf0[0])
    calibration = {
        **re.as_json(),
        'force_gain': {'value': gain, 'std': gain_std, 'unit': '-',
                       'meaning': f'measured {measured} / re-identified model {measured} (efficiency '
                                  'scale left after the re-identification: 1 when it holds)'},
        'jaw_angle_offset': {'value': float(ca0[0]), 'std': float(a_std[0]),
                             'unit': 'rad', 'meaning': 'jaw encoder zero'},
        'jaw_angle_lag': {'value': float(ca0[3]), 'std': float(a_std[3]),
                          'unit': 's', 'meaning': 'jaw angle per jaw velocity (dynamic lag)'},
        'jaw_side_cable_length': {'value': jaw_side_cable_length, 'std': None, 'unit': 'm',
                                  'meaning': 'given (not fitted; cable_length x cable_jaw_side_fraction '
                                             'of the schema unless set): the stiffness E*A/length a '
                                             'stuck cable shows the wrist, and the jaw side of the stretch'},
        'gap_uncalibrated': raw_gap,
        'gap_reidentified': rms(data.y[data.test] - data.nominal[data.test]),
        'note': 'parameters re-identified on the training samples, then calibrated as a lab would (values: '
                'fit on all training samples; the held-out gaps use per-fold fits); not counted as an '
                'unmodelled effect',
    }
    return base, gain, calibration


def _friction_step(data: PooledData) -> float:
    """Return the move of log(mu) the base alone asks for (derivative coefficient / gain) in training."""
    from grip_force_ros.lab.diagnosis.fitting import huber_lstsq
    tr = np.flatnonzero(data.train)
    tr = tr[::max(1, int(np.ceil(tr.size / MAX_FIT_ROWS)))]
    coef = huber_lstsq(data.base[tr], data.y[tr], data.force_scale)
    return float(coef[1]) / float(coef[0]) if coef[0] != 0.0 else 0.0


def _force_support(effect, fit: dict, reference: dict, force_floor_ms: float) -> bool:
    """Whether the measured column's held-out loss supports ``effect`` (:data:`MIN_FORCE_SUPPORT`).

    Always True for an effect without force columns (judged on the jaw angle).
    """
    if effect.angle_params and not effect.force_params:
        return True
    ratio = (fit['test_loss_f'] + force_floor_ms) / (reference['test_loss_f'] + force_floor_ms)
    return ratio <= 1.0 - MIN_FORCE_SUPPORT


def _first_named(ranking: list) -> int:
    """Index of the verdict in the ranking: the best score whose effect the force supports, or none."""
    return next(i for i, r in enumerate(ranking) if r['effect'] == NONE or r.get('force_support', True))


def _fit_effect(data: PooledData, name: str, base: dict, rng, force_floor_ms: float, param_penalty: float,
                unit: str):
    """Fit one effect on top of ``data``'s base: its held-out fit, its ranking entry, its friction step.

    The friction step is the move of log(mu) its fit asks for through the base's derivative
    column (coefficient / gain): the first-order change of the re-identified pulley friction
    beside this effect.
    """
    effect = EFFECTS[name]
    fit = evaluate(data, lambda v: data.designs(effect, v), effect.grid)
    value = fit['value']
    Xf, Xa = data.designs(effect, value)
    cf, ca, sf, sa, train_mse = full_fit(data, Xf, Xa, rng)
    score = held_out_score(fit, base, force_floor_ms) + param_penalty * effect.n_params
    g = float(cf[0])
    nb = data.force_base_width
    na = data.angle_base_width
    params_out = _describe(effect, value, cf[nb:], sf[nb:], ca[na:], sa[na:], g, unit)
    entry = {'effect': name, 'holdout_rmse': math.sqrt(fit['test_mse_f']),
             'holdout_angle_rmse': math.sqrt(fit['test_mse_a']), 'train_rmse': math.sqrt(train_mse),
             'score': score, 'n_params': effect.n_params, 'gain': g, 'params': params_out,
             'force_support': _force_support(effect, fit, base, force_floor_ms)}
    step = float(cf[1]) / g if nb > 1 and g != 0.0 else 0.0
    if nb > 1:
        # the re-identified parameters beside this effect: the gain column scales the torque
        # constant, the derivative column moves the friction (to first order)
        entry['reidentified_beside'] = {
            'pulley_friction_coefficient': data.friction * math.exp(step),
            'torque_constant': data.torque_constant * g, 'cable_modulus': data.cable_modulus * g}
    return fit, entry, step


def _rank_effects(data: PooledData, base: dict, gain: float, rng, force_floor_ms: float,
                  param_penalty: float, min_improvement: float, unit: str, say, joint=None):
    """Step 3: every effect fitted as an augmentation, ranked by held-out score (lower is better).

    Every effect is first fitted on the re-identified model, whose pulley friction it may move
    to first order (the base's derivative column). ``joint(name, value, step)`` refits the
    friction with an effect whose fit asks for a larger move (:data:`JOINT_STEP`; the
    :data:`JOINT_CANDIDATES` best-scoring such effects): it returns the pooled data of the
    model re-identified beside that effect (or None), on which the effect is then fitted
    and scored against the same base. A friction change and an effect that resembles one
    (a hysteresis, a stick-slip) are so told apart on the data, not by the order of the fits.

    Returns
    -------
    ranking : list of dict
        One entry per effect and one for ``none``, sorted by score.
    fits : dict
        Effect name -> its held-out fit (with ``data``: the pooled data it was fitted on);
        held-out residual arrays are kept only for the best effect (memory).
    """
    entries = {}
    fits = {}
    steps = {}
    for name in EFFECT_NAMES:
        say(f'fitting {name}')
        fit, entries[name], steps[name] = _fit_effect(data, name, base, rng, force_floor_ms, param_penalty,
                                                      unit)
        fits[name] = {**fit, 'data': data}
        _keep_residuals_of_best(fits, entries)
    if joint is not None:
        moving = sorted((n for n in EFFECT_NAMES if abs(steps[n]) > JOINT_STEP),
                        key=lambda n: entries[n]['score'])
        for name in moving[:JOINT_CANDIDATES]:
            refitted = joint(name, fits[name]['value'], steps[name])
            if refitted is None:
                continue
            say(f'fitting {name} with the pulley friction refitted beside it')
            fit, entry, _ = _fit_effect(refitted, name, base, rng, force_floor_ms, param_penalty, unit)
            entry['friction_refitted_beside'] = True        # not only to first order
            entries[name] = entry
            fits[name] = {**fit, 'data': refitted}
            _keep_residuals_of_best(fits, entries)
    ranking = list(entries.values())
    ranking.append({'effect': NONE, 'holdout_rmse': math.sqrt(base['test_mse_f']),
                    'holdout_angle_rmse': math.sqrt(base['test_mse_a']),
                    'train_rmse': None, 'score': math.log(1.0 - min_improvement),
                    'n_params': 0, 'gain': gain, 'params': {}})
    ranking.sort(key=lambda r: r['score'])
    return ranking, fits


def _keep_residuals_of_best(fits: dict, entries: dict) -> None:
    """Drop the held-out residual arrays of every fit but the best-scoring one (memory)."""
    best = min(entries, key=lambda n: entries[n]['score'])
    for name, fit in fits.items():
        if name != best:
            fit.pop('resid_f', None)
            fit.pop('resid_a', None)


def _second_effect(data: PooledData, winner: str, fits: dict, rng, force_floor_ms: float,
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
    data = fits[winner].get('data', data)             # the model re-identified beside the winner
    first_design = data.designs(EFFECTS[winner], fits[winner]['value'])

    def pair(value, name):
        other = data.designs(EFFECTS[name], value)
        return combine_designs(data, first_design, other, winner, name, fits, value)

    best2 = None
    for name in EFFECT_NAMES:
        if name == winner:
            continue
        fit2 = evaluate(data, lambda value, name=name: pair(value, name), EFFECTS[name].grid)
        score2 = held_out_score(fit2, fits[winner], force_floor_ms) + param_penalty * EFFECTS[name].n_params
        say(f'second effect {name}: held-out {math.sqrt(fit2["test_mse_f"]):.4g} {unit}, score {score2:.3f}')
        supported = _force_support(EFFECTS[name], fit2, fits[winner], force_floor_ms)
        if supported and score2 < math.log(1.0 - min_improvement) and (best2 is None or score2 < best2[0]):
            best2 = (score2, name, fit2)
    if best2 is None:
        return None
    _, name, final = best2
    second = EFFECTS[name]
    Xf, Xa = pair(final['value'], name)
    cf, ca, sf, sa, _ = full_fit(data, Xf, Xa, rng)
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
    winner = ranking[_first_named(ranking)]['effect']
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
               'runner_up': next(r['effect'] for r in ranking if r['effect'] != winner),
               'rule': f'an effect is named when its held-out score (log ratio of the Huber loss of the '
                       f'force + log ratio of the angle MSE, +{param_penalty} per parameter) is below '
                       f'log(1 - {min_improvement}) and, if it acts on the measured column, that '
                       f'column\'s held-out loss alone falls by {100 * MIN_FORCE_SUPPORT:g} % '
                       f'(force_support); a second effect when it passes the same on top of the first; '
                       f'gap_after is with every named effect'}
    return verdict, final


def _held_out_series(data: PooledData, base: dict, resid_after: np.ndarray) -> dict:
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
                  jaw_side_cable_length: float | None = None,
                  seed: int = 0, progress=None) -> Diagnosis:
    """Diagnose the gap between the model and measured logs (see :func:`diagnose`).

    The steps of the module docstring, in order; ``seed`` seeds the block bootstrap of
    the coefficients' standard deviations (one generator, drawn in step order).
    """
    model = _default_model(params) if model is None else model
    model_of = _model_of(model)
    say = progress or (lambda msg: None)
    train_logs = list(train_logs)
    test_logs = list(test_logs or [])
    if not train_logs:
        raise DiagnosisError('no logs to diagnose')
    jaw_side = cable_lengths(model.params, jaw_side_cable_length)[1]
    data, inputs, fold_tests, measured = _prepare(train_logs, test_logs, model, analysis_rate, default_object,
                                                  blocks, folds, jaw_side, say)
    unit = UNITS[measured]
    split = _split(data, data.frames, len(train_logs), len(test_logs), blocks, folds, analysis_rate)
    rng = np.random.default_rng(seed)
    say('re-identifying the instrument parameters')
    re = reidentify(inputs, _training_rows(data, data.frames), model.params, model_of,           # 0.
                    force_scale=_robust_force_scale(data), rng=rng, jaw_side_cable_length=jaw_side)
    raw_gap = rms(data.y[data.test] - data.nominal[data.test])
    frames = _reidentified_frames(inputs, re.params, model_of, jaw_side, len(train_logs),
                                  friction_column='pulley_friction_coefficient' in re.values)
    data = _pooled(frames, fold_tests, re.params)
    data.force_scale = _robust_force_scale(data)
    if data.force_base_width > 1:
        # the base's friction at the optimum of the same objective every effect's refit reaches
        # (the re-identification's fit weighs and scales a little differently)
        polished = _joint_refit(None, None, _friction_step(data), data, inputs, re.params, model_of, jaw_side,
                                len(train_logs), fold_tests, re.yaml, 'cable_modulus' in re.values)
        if polished is not None:
            re.polish(pulley_friction_coefficient=polished.friction,
                      torque_constant=polished.torque_constant, cable_modulus=polished.cable_modulus)
            data = polished
    base, gain, calibration = _calibrate(data, rng, measured, jaw_side, re, raw_gap)         # 1.
    force_floor_ms = (FORCE_FLOOR * rms(data.y[data.test])) ** 2

    def joint(name, value, step):
        return _joint_refit(name, value, step, data, inputs, re.params, model_of, jaw_side, len(train_logs),
                            fold_tests, re.yaml, 'cable_modulus' in re.values)

    ranking, fits = _rank_effects(data, base, gain, rng, force_floor_ms, param_penalty,     # 3.
                                  min_improvement, unit, say, joint)
    winner = ranking[_first_named(ranking)]['effect']
    second = None if winner == NONE else _second_effect(                                    # 4.
        data, winner, fits, rng, force_floor_ms, param_penalty, min_improvement, unit, say)
    verdict, final = _verdict(base, fits, ranking, second, unit, measured, param_penalty,
                              min_improvement)
    regions = _regions(data, base['resid_f'], unit)                                          # 2.
    result = {'verdict': verdict, 'ranking': ranking, 'regions': regions, 'split': split,
              'calibration': calibration, 'measured': measured, 'unit': unit,
              'samples': {'train': int(data.train.sum()), 'test': int(data.test.sum())},
              # the training logs' stroke (rad) of each angle a position spring follows
              'strokes': {k: [float(v) for v in r]
                          for k, r in data.frames[0].get('stroke', {}).items()}}
    return Diagnosis(result, _held_out_series(data, base, final['resid_f']))


def diagnose(train_logs: Sequence, test_logs: Sequence | None = None, params=None, **kwargs) -> dict:
    """Where the model disagrees with the logs, which effect explains it, how far the gap shrinks.

    Parameters
    ----------
    train_logs : sequence of log dicts or paths
        Logs in the docs/design.md contract (see :mod:`grip_force_ros.logs`). Without
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
