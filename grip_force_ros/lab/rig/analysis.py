"""Real-data analysis of the rig: held-out jaw torque error, where the gap lies, which effects.

Everything here is judged on runs the fit never saw:

* ``holdout``: fit on the 10 runs at 10 % and 30 % resisting torque, test on
  the 10 runs at 20 % and 40 % (all five frequencies on both sides; 40 % is an
  extrapolation beyond the training loads);
* cross-validation: leave one torque level out (4 folds), leave one frequency
  out (5 folds), leave one run out (20 folds).

The estimators read motor-side columns only (:mod:`.estimator`); the analysis
of *where* the error lies may look at every column (jaw angle, loads).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from grip_force_ros.lab.rig import constants as C
from grip_force_ros.lab.rig.estimator import (ALLOWED_INPUTS, CableFrictionObserver,
                                              LinearCurrentEstimator, ObserverSettings, _signals,
                                              motor_side_inputs)

#: Seconds at the start of each run reported separately (the observer has seen no sliding yet).
STARTUP_S = C.STARTUP_S
HOLDOUT_TRAIN_LEVELS = (0, 2)
HOLDOUT_TEST_LEVELS = (1, 3)
CV_KINDS = ('level', 'frequency', 'run')


@dataclass(frozen=True)
class Candidate:
    """One estimator variant: a name, the effect it adds or removes, and how to build it."""

    name: str
    effect: str
    description: str
    make: Callable[[], object]


def _observer(**changes) -> Callable[[], CableFrictionObserver]:
    settings = replace(ObserverSettings(), **changes)
    return lambda: CableFrictionObserver(settings)


FULL = Candidate('cable_friction_observer', 'all',
                 'direction-dependent efficiency + Coulomb + Dahl hysteresis with stick-hold '
                 'observer + position spring + viscous friction', _observer())
LINEAR = Candidate('linear', 'none', 'jaw torque = a * current + b (raw current)',
                   LinearCurrentEstimator)

#: Cumulative ladder: each step adds one effect to the one before.
LADDER = (
    LINEAR,
    Candidate('efficiency_coulomb', 'tension_dependent_friction + pivot_coulomb_friction',
              'two friction branches (s = sign of motor velocity), direction-dependent '
              'efficiency and Coulomb friction, inverted at every sample',
              _observer(hysteresis=False, viscous=False, spring_order=0)),
    Candidate('+hysteresis', 'cable_hysteresis',
              '+ Dahl friction state over motor angle, invert only while sliding, hold through '
              'stick and reversals', _observer(viscous=False, spring_order=0)),
    Candidate('+spring', 'position_spring',
              '+ position-dependent spring k(x) (cable pretension and jaw), Legendre order 2',
              _observer(viscous=False)),
    Candidate('+viscous', 'viscous_friction', '+ viscous friction c*v (the full model)',
              _observer()),
)

#: Each effect removed from the full model.
DROP_ONE = (
    Candidate('-efficiency', 'tension_dependent_friction', 'full model, one efficiency for '
              'both directions', _observer(efficiency=False)),
    Candidate('-coulomb', 'pivot_coulomb_friction', 'full model without Coulomb friction',
              _observer(coulomb=False)),
    Candidate('-hysteresis', 'cable_hysteresis', 'full model, s = sign(v), no stick-hold',
              _observer(hysteresis=False)),
    Candidate('-spring', 'position_spring', 'full model without the position spring',
              _observer(spring_order=0)),
    Candidate('-viscous', 'viscous_friction', 'full model without viscous friction',
              _observer(viscous=False)),
)

#: Effects the full model lacks, each added on its own.
ADD_ONE = (
    Candidate('+load_dependent_efficiency', 'tension_dependent_friction (load-dependent)',
              'friction split growing with the square of the load (the transfer model: it needs '
              'the 10-100 % loads of Tool_4_Maryland_L_4 to be seen)',
              _observer(load_dependent_efficiency=True)),
    Candidate('+backlash', 'backlash', 'friction state driven by the input-disk encoder '
              '(after the coupling backlash) instead of the motor shaft',
              _observer(backlash_angle='motor_angle')),
    Candidate('+sensor_delay', 'sensor_delay', 'measured current used 5 ms later',
              _observer(current_delay_s=0.005)),
    Candidate('+viscoelastic_creep', 'viscoelastic_creep', 'second, slow friction state '
              '(0.2 rad) for friction that settles over a long stroke',
              _observer(slow_hysteresis_width=0.2)),
    Candidate('+position_ripple', 'position_dependent_friction', 'direction-dependent '
              'friction map s*m(x), Legendre order 6 (pulley/cable ripple)',
              _observer(friction_map_order=6, spring_order=6)),
)

#: Settings swept (holdout split only) to show how much the a-priori settings matter.
SENSITIVITY = (
    ('hysteresis_width', (0.01, 0.02, 0.04)),
    ('observer_time_constant', (0.03, 0.1, 0.3)),
    ('current_filter_hz', (5.0, 10.0, 20.0)),
    ('stick_speed', (0.05, 0.1, 0.2)),
)


# -- splits -----------------------------------------------------------------------------
def holdout_split(runs: Sequence) -> tuple[list, list]:
    """(train, test): train on torque steps 0 and 2 (10, 30 %), test on 1 and 3 (20, 40 %)."""
    train = [r for r in runs if r.torque_step in HOLDOUT_TRAIN_LEVELS]
    test = [r for r in runs if r.torque_step in HOLDOUT_TEST_LEVELS]
    return train, test


def cv_folds(runs: Sequence, kind: str) -> list[list]:
    """Test sets of a cross-validation: ``'level'``, ``'frequency'`` or ``'run'``."""
    if kind == 'level':
        keys = sorted({r.torque_step for r in runs})
        return [[r for r in runs if r.torque_step == k] for k in keys]
    if kind == 'frequency':
        keys = sorted({r.frequency_step for r in runs})
        return [[r for r in runs if r.frequency_step == k] for k in keys]
    if kind == 'run':
        return [[r] for r in runs]
    raise ValueError(f'unknown cross-validation {kind!r}; one of {CV_KINDS}')


def heldout_predictions(candidate: Candidate, runs: Sequence, folds: Sequence[Sequence],
                        cache: dict) -> dict[str, np.ndarray]:
    """Prediction (N*m) of every run in ``folds`` by a model fitted on the other runs."""
    preds = {}
    for test in folds:
        names = {r.name for r in test}
        train = [r for r in runs if r.name not in names]
        est = candidate.make().fit(train, cache=cache)
        for r in test:
            preds[r.name] = est.predict(r, cache=cache)
    return preds


def rmse_of(preds: dict, runs: Sequence, *, skip_s: float = 0.0) -> float:
    """RMS error (N*m) of ``preds`` against the measured jaw torque, over the runs in ``preds``."""
    se, n = 0.0, 0
    for r in runs:
        if r.name not in preds:
            continue
        err = (preds[r.name] - r.jaw_torque)[r.t >= skip_s]
        se += float(np.sum(err ** 2))
        n += err.size
    return math.sqrt(se / n)


def evaluate(candidate: Candidate, runs: Sequence, cache: dict, *,
             kinds: Sequence[str] = CV_KINDS) -> dict:
    """Held-out and cross-validated RMSE (mN*m) of one candidate."""
    train, test = holdout_split(runs)
    preds = heldout_predictions(candidate, runs, [test], cache)
    out = {'name': candidate.name, 'effect': candidate.effect,
           'description': candidate.description,
           'holdout_rmse_mNm': round(rmse_of(preds, test) * 1e3, 3),
           'holdout_rmse_after_startup_mNm': round(rmse_of(preds, test, skip_s=STARTUP_S) * 1e3, 3),
           'cv_rmse_mNm': {}}
    for kind in kinds:
        cv = heldout_predictions(candidate, runs, cv_folds(runs, kind), cache)
        out['cv_rmse_mNm'][kind] = round(rmse_of(cv, runs) * 1e3, 3)
    return out


def _parameters(est) -> dict:
    if isinstance(est, LinearCurrentEstimator):
        return {'slope_Nm_per_A': float(est.coef[0]), 'intercept_Nm': float(est.coef[1])}
    fr = est.fit_result
    return {'forward_model': {n: {'value': float(v), 'std': float(s)}
                              for n, v, s in zip(fr.names, fr.values, fr.std)},
            'physical': {k: {'value': float(v), 'std': float(s)} for k, (v, s) in fr.physical.items()},
            'settings': {k: getattr(est.settings, k) for k in est.settings.__dataclass_fields__},
            'training_samples': fr.training_samples}


# -- where ------------------------------------------------------------------------------
def _region_table(groups: list[tuple[str, str, np.ndarray]]) -> list[dict]:
    """Tabulate groups: (family, label, errors in N*m). Shares of the squared error are within a family."""
    out = []
    families = {}
    for family, label, err in groups:
        families.setdefault(family, []).append((label, err))
    for family, items in families.items():
        total_se = sum(float(np.sum(e ** 2)) for _, e in items)
        total_n = sum(e.size for _, e in items)
        for label, err in items:
            if err.size == 0:
                continue
            se = float(np.sum(err ** 2))
            out.append({'where': f'{family}: {label}', 'family': family,
                        'share_of_gap': round(se / total_se, 4),
                        'share_of_samples': round(err.size / total_n, 4),
                        'rmse_mNm': round(math.sqrt(se / err.size) * 1e3, 3),
                        'bias_mNm': round(float(np.mean(err)) * 1e3, 3)})
    return out


def regions(runs: Sequence, preds: dict, settings: ObserverSettings) -> list[dict]:
    """Held-out error split by motion phase, speed, load, frequency and jaw angle."""
    buckets: dict[tuple[str, str], list] = {}

    def add(family, label, values):
        buckets.setdefault((family, label), []).append(values)

    speed_edges = (0.0, 0.1, 0.5, 1.0, np.inf)
    angle_edges_deg = (-np.inf, 15.0, 30.0, 45.0, np.inf)
    for r in runs:
        if r.name not in preds:
            continue
        err = preds[r.name] - r.jaw_torque
        sig = _signals(motor_side_inputs(r), settings)
        startup = r.t < STARTUP_S
        sliding = (sig.sliding > 0) & ~startup
        add('motion', 'start-up (first 1 s)', err[startup])
        add('motion', 'closing, sliding', err[sliding & (sig.direction > 0)])
        add('motion', 'opening, sliding', err[sliding & (sig.direction < 0)])
        add('motion', 'stuck or reversing (estimate held)', err[~sliding & ~startup])
        speed = np.abs(sig.velocity)
        for lo, hi in zip(speed_edges[:-1], speed_edges[1:]):
            label = f'|motor velocity| {lo:g}..{hi:g} rad/s' if np.isfinite(hi) \
                else f'|motor velocity| > {lo:g} rad/s'
            add('speed', label, err[(speed >= lo) & (speed < hi)])
        add('load', f'{r.torque_level_percent:g} % resisting torque', err)
        add('frequency', f'{r.frequency_hz:g} Hz', err)
        jaw_deg = np.degrees(r.jaw_angle)
        for lo, hi in zip(angle_edges_deg[:-1], angle_edges_deg[1:]):
            label = f'jaw angle < {hi:g} deg' if not np.isfinite(lo) else (
                f'jaw angle > {lo:g} deg' if not np.isfinite(hi) else f'jaw angle {lo:g}..{hi:g} deg')
            add('jaw angle', label, err[(jaw_deg >= lo) & (jaw_deg < hi)])
    groups = [(fam, lab, np.concatenate(v)) for (fam, lab), v in buckets.items()]
    table = _region_table(groups)
    table.sort(key=lambda row: (row['family'], -row['share_of_gap']))
    return table


def run_offsets(runs: Sequence, preds: dict) -> dict:
    """Per-run mean error (a force_sensor_offset or a current offset shows here) and drift.

    Returns the spread of the per-run means and the mean within-run error trend
    (mN*m per 10 s; torque_constant_drift or creep over a run would show here).
    """
    means, slopes = [], []
    for r in runs:
        if r.name not in preds:
            continue
        err = preds[r.name] - r.jaw_torque
        keep = r.t >= STARTUP_S
        means.append(float(np.mean(err[keep])))
        slopes.append(float(np.polyfit(r.t[keep], err[keep], 1)[0]))
    return {'per_run_bias_std_mNm': round(float(np.std(means)) * 1e3, 3),
            'per_run_bias_range_mNm': [round(min(means) * 1e3, 3), round(max(means) * 1e3, 3)],
            'within_run_trend_mNm_per_10s': round(float(np.mean(slopes)) * 1e4, 3),
            'within_run_trend_std_mNm_per_10s': round(float(np.std(slopes)) * 1e4, 3)}


# -- the whole analysis -------------------------------------------------------------------
def analyse(runs: Sequence, *, quick: bool = False, progress=None) -> dict:
    """Run the estimators, the effect ladder, the regions; return the JSON-ready result.

    Parameters
    ----------
    runs : sequence of RigRun
        Imported rig runs (all of them: the splits are made here).
    quick : bool
        Estimators on the holdout split and leave-one-level-out, effects on the
        holdout split only, no sensitivity sweep (for tests and CI).
    progress : callable, optional
        ``progress(message)`` for long steps.
    """
    say = progress or (lambda msg: None)
    kinds = ('level',) if quick else CV_KINDS
    cache: dict = {}
    train, test = holdout_split(runs)
    result = {
        'data': {'runs': [r.name for r in runs], 'attribution': C.ATTRIBUTION},
        'split': {
            'holdout': {'train': [r.name for r in train], 'test': [r.name for r in test],
                        'description': 'fit on the runs at 10 % and 30 % resisting torque, '
                                       'judge on the runs at 20 % and 40 % (never seen; 40 % '
                                       'is beyond the training loads); all 5 frequencies on '
                                       'both sides'},
            'cross_validation': {
                'level': 'leave one torque level out (4 folds of 5 runs)',
                'frequency': 'leave one frequency out (5 folds of 4 runs)',
                'run': 'leave one run out (20 folds)'}},
        'published_rmse_mNm': C.PUBLISHED_RMSE_NM * 1e3,
        'published_source': "O'Neill, Stephens, Kowalewski, IEEE RA-L 3(4) 2018 (neural networks, "
                            'from motor current)',
        'estimator_inputs': list(ALLOWED_INPUTS),
        'startup_s': STARTUP_S,
    }
    estimators = []
    for cand in (LINEAR, FULL):
        say(f'evaluating {cand.name}')
        row = evaluate(cand, runs, cache, kinds=kinds)
        row['parameters'] = _parameters(cand.make().fit(train, cache=cache))
        estimators.append(row)
    result['estimators'] = estimators
    best = estimators[1]
    result['beats_published'] = bool(best['holdout_rmse_mNm'] < C.PUBLISHED_RMSE_NM * 1e3)
    effects = {}
    for label, group in (('ladder', LADDER), ('drop_one', DROP_ONE), ('add_one', ADD_ONE)):
        rows = []
        for cand in group:
            say(f'effect {label}: {cand.name}')
            if cand.name == LINEAR.name:
                rows.append({k: estimators[0][k] for k in ('name', 'effect', 'description',
                                                           'holdout_rmse_mNm', 'cv_rmse_mNm')})
                continue
            row = evaluate(cand, runs, cache, kinds=() if quick else ('level',))
            rows.append({k: row[k] for k in ('name', 'effect', 'description', 'holdout_rmse_mNm',
                                             'cv_rmse_mNm')})
        effects[label] = rows
    full_ho = best['holdout_rmse_mNm']
    for row in effects['add_one']:
        row['change_vs_full_mNm'] = round(row['holdout_rmse_mNm'] - full_ho, 3)
    for row in effects['drop_one']:
        row['change_vs_full_mNm'] = round(row['holdout_rmse_mNm'] - full_ho, 3)
    result['effects'] = effects
    if not quick:
        sens = []
        for field_name, values in SENSITIVITY:
            for value in values:
                cand = Candidate(f'{field_name}={value:g}', 'setting', '',
                                 _observer(**{field_name: value}))
                preds = heldout_predictions(cand, runs, [test], cache)
                sens.append({'setting': field_name, 'value': value,
                             'holdout_rmse_mNm': round(rmse_of(preds, test) * 1e3, 3)})
        result['sensitivity'] = sens
    say('regions')
    loro = heldout_predictions(FULL, runs, cv_folds(runs, 'level' if quick else 'run'), cache)
    lin = heldout_predictions(LINEAR, runs, cv_folds(runs, 'level' if quick else 'run'), cache)
    settings = ObserverSettings()
    result['regions_basis'] = ('held-out predictions of every run, leave one ' +
                               ('level' if quick else 'run') + ' out')
    result['regions'] = regions(runs, loro, settings)
    result['regions_linear'] = regions(runs, lin, settings)
    result['run_offsets'] = run_offsets(runs, loro)
    result['_predictions'] = {'full': loro, 'linear': lin}
    return result
