"""Why a folder's own floor is what it is: the transfer model cross-validated inside one folder.

``grip-force realdata --floor DIR`` fits the transfer model (:data:`.transfer.TRANSFER_SETTINGS`,
the same training path as :func:`.transfer.train`) on some runs of one folder and judges
the others (2-fold even/odd runs, leave one load level, one frequency, one run out), then
breaks the held-out error down where it lies: by load level, by frequency, by stroke phase
(start-up before the first slide, closing, opening, held through stick and reversals),
per-run bias against within-run error, frequency band, drift within a run. It measures the
data where a model cannot help (the start-up, the jaw torque's own fast oscillation,
saturation, resolution), a non-causal bound (the same model, averaged forward and backward
in time), the stick band after reversals against the load, and the candidate terms that
were tried. Every number is held out; the analysis of *where* may read every column, the
estimators only the motor side.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.signal import welch

from grip_force_ros.lab.rig import constants as C
from grip_force_ros.lab.rig.analysis import cv_folds
from grip_force_ros.lab.rig.estimator import CableFrictionObserver, ObserverSettings, causal_lowpass
from grip_force_ros.lab.rig.transfer import TRANSFER_SETTINGS, Folder, predict_session, train

#: Cross-validations of the floor: even/odd runs in file order (2 folds, both directions),
#: leave one load level, one frequency, one run out.
FOLD_KINDS = ('even_odd', 'level', 'frequency', 'run')
#: Frequency bands (Hz) of the error spectrum: below the slowest stroke, the stroke
#: fundamentals (0.1-0.5 Hz), their harmonics, the observer's averaging band, the back
#: end's 10 Hz stick-slip, the front end's 40 Hz oscillation, above.
ERROR_BANDS_HZ = ((0.0, 0.09), (0.09, 0.6), (0.6, 2.0), (2.0, 5.0), (5.0, 15.0), (15.0, 60.0),
                  (60.0, 500.0))
#: Jaw torque above this frequency (Hz) is beyond the observer's 10 Hz current filter and
#: its 0.1 s averaging: what the motor side cannot follow.
FAST_HZ = 10.0
#: Fraction of the current swing between the friction branches that counts as "across"
#: when the stick band after a reversal is measured.
SWING_FRACTION = 0.9

#: Disk encoder counts the input disk must move before a run counts as started
#: (:func:`startup_bound`): a few counts of the 8192 per turn, above the encoder's jitter.
STANDSTILL_COUNTS = 4

#: Candidate structures tried against the floor (settings changed from the transfer model).
CANDIDATES = (
    ('previous transfer model (no friction map, no load model)',
     {'friction_map_order': 0, 'load_model': False}),
    ('friction map P1, no load model', {'load_model': False}),
    ('transfer model (friction map P1, load model)', {}),
    ('level time constant 0.3 s', {'level_time_constant': 0.3}),
    ('level time constant 3 s', {'level_time_constant': 3.0}),
    ('friction map to P2', {'friction_map_order': 2}),
    ('Dahl width 0.03 rad (stick band wider)', {'hysteresis_width': 0.03}),
    ('Dahl width 0.04 rad', {'hysteresis_width': 0.04}),
    ('friction state from the disk encoder (after the backlash)', {'backlash_angle': 'motor_angle'}),
    ('current 5 ms later (lag)', {'current_delay_s': 0.005}),
    ('observer time constant 0.05 s (less lag)', {'observer_time_constant': 0.05}),
    ('current filter 20 Hz (less lag)', {'current_filter_hz': 20.0}),
    ('slow second friction state 0.2 rad (creep)', {'slow_hysteresis_width': 0.2}),
)


@dataclass
class HeldOut:
    """One run's held-out prediction and the observer state that goes with it.

    Attributes
    ----------
    run : RigRun
    prediction : ndarray
        Jaw torque estimate (N*m), start-up at the session estimate.
    weight, direction, position : ndarray
        Observer weight, friction direction s, scaled disk position.
    first : int
        Index of the first sliding sample (the start-up ends there).
    sensor_zero : float
        The jaw torque sensor's zero (N*m) found on the training runs against the resisting
        motor (:func:`.transfer.front_end_reference`), the frame the fit was made in.
    """

    run: object
    prediction: np.ndarray
    weight: np.ndarray
    direction: np.ndarray
    position: np.ndarray
    first: int
    sensor_zero: float = 0.0

    @property
    def error(self) -> np.ndarray:
        """Prediction minus the measured jaw torque in the fit's frame (N*m)."""
        return self.prediction - (self.run.jaw_torque - self.sensor_zero)


def folds(runs: Sequence, kind: str) -> list[list]:
    """Test sets of a floor cross-validation (:data:`FOLD_KINDS`)."""
    if kind == 'even_odd':
        return [list(runs[0::2]), list(runs[1::2])]
    return cv_folds(runs, kind)


def held_out(folder: Folder, settings: ObserverSettings, kind: str, *,
             two_sided: bool = False) -> list[HeldOut]:
    """Held-out predictions of every run of ``folder`` by the transfer model fitted on the others.

    ``two_sided``: the non-causal bound instead of the observer: the same inverted torque
    and weights averaged forward and backward in time (:func:`.estimator.two_sided_average`; with a
    load model, the level averaged so and put back through the load's shape).
    """
    out = []
    for test in folds(folder.runs, kind):
        ids = {id(r) for r in test}
        model = train([replace(folder, runs=[r for r in folder.runs if id(r) not in ids])], settings)
        est, cache = model.estimator, model.cache
        zero = model.front_end['zeros_Nm'][folder.name]      # same session: the same sensor zero
        preds, _ = predict_session(est, test, cache)
        for run, pred in zip(test, preds):
            inverted, weight, dt = est.inversion(run, cache=cache)
            sig = est._design(run, cache)[0]
            on = np.flatnonzero(weight > 0)
            first = int(on[0]) if on.size else weight.size
            if two_sided:
                pred = est.predict(run, cache=cache, offline=True)
            out.append(HeldOut(run, pred, weight, sig.direction, sig.position, first, zero))
    return out


def rmse_mNm(items: Sequence[HeldOut], *, skip_s: float = 0.0) -> float:
    """RMS error (mN*m) over every sample of ``items`` (after ``skip_s`` of each run)."""
    se, n = 0.0, 0
    for h in items:
        err = h.error[h.run.t - h.run.t[0] >= skip_s]
        se += float(np.sum(err ** 2))
        n += err.size
    return 1e3 * math.sqrt(se / n)


def _late(h: HeldOut) -> np.ndarray:
    return h.run.t - h.run.t[0] >= C.STARTUP_S


def _group_rows(items: Sequence[HeldOut], key, label: str) -> list[dict]:
    rows = []
    for value in sorted({key(h) for h in items}):
        group = [h for h in items if key(h) == value]
        biases = [1e3 * float(np.mean(h.error[_late(h)])) for h in group]
        within = np.concatenate([h.error[_late(h)] - np.mean(h.error[_late(h)]) for h in group])
        rows.append({label: value,
                     'mean_torque_mNm': round(1e3 * float(np.mean([np.mean(h.run.jaw_torque)
                                                                   for h in group])), 2),
                     'rmse_mNm': round(rmse_mNm(group), 3),
                     'rmse_after_startup_mNm': round(rmse_mNm(group, skip_s=C.STARTUP_S), 3),
                     'run_bias_mean_mNm': round(float(np.mean(biases)), 3),
                     'run_bias_std_mNm': round(float(np.std(biases)), 3),
                     'within_run_mNm': round(1e3 * float(np.sqrt(np.mean(within ** 2))), 3)})
    return rows


def breakdown(items: Sequence[HeldOut]) -> dict:
    """Where the held-out error lies: load, frequency, stroke phase, bias, band, drift."""
    total = sum(float(np.sum(h.error ** 2)) for h in items)
    samples = sum(h.error.size for h in items)
    phases = {'start-up (before the first slide)': [], 'closing (sliding)': [],
              'opening (sliding)': [], 'held (stick, reversal)': []}
    for h in items:
        phase = np.where(h.weight > 0, np.where(h.direction > 0, 1, 2), 3)
        phase[:h.first] = 0
        for k, name in enumerate(phases):
            phases[name].append(h.error[phase == k])
    by_phase = []
    for name, parts in phases.items():
        err = np.concatenate(parts)
        by_phase.append({'phase': name, 'fraction_of_samples': round(err.size / samples, 4),
                         'rmse_mNm': round(1e3 * float(np.sqrt(np.mean(err ** 2))), 3) if err.size else 0.0,
                         'share_of_squared_error': round(float(np.sum(err ** 2)) / total, 4)})
    biases = np.array([np.mean(h.error[_late(h)]) for h in items])
    within = np.concatenate([h.error[_late(h)] - np.mean(h.error[_late(h)]) for h in items])
    power, freq = 0.0, None
    for h in items:
        freq, p = welch(h.error[_late(h)], fs=1.0 / C.SAMPLE_PERIOD, nperseg=8192, detrend=False)
        power = power + p
    power = power / len(items)
    df = freq[1] - freq[0]
    bands = [{'band_hz': [lo, hi], 'rms_mNm': round(1e3 * float(np.sqrt(np.sum(
        power[(freq >= lo) & (freq < hi)]) * df)), 3)} for lo, hi in ERROR_BANDS_HZ]
    blocks = []
    for h in items:
        t, err = h.run.t - h.run.t[0], h.error
        blocks.append([float(np.mean(err[(t >= a) & (t < a + 4.0)])) for a in (1.0, 5.0, 9.0, 13.0)])
    blocks = 1e3 * np.array(blocks)
    return {
        'by_level': _group_rows(items, lambda h: h.run.torque_level_percent, 'level_percent'),
        'by_frequency': _group_rows(items, lambda h: h.run.frequency_hz, 'frequency_hz'),
        'by_phase': by_phase,
        'after_startup': {'run_bias_rms_mNm': round(1e3 * float(np.sqrt(np.mean(biases ** 2))), 3),
                          'within_run_rms_mNm': round(1e3 * float(np.sqrt(np.mean(within ** 2))), 3)},
        'error_bands': bands,
        'drift_mean_error_per_4s_block_mNm': {'blocks_s': [[1, 5], [5, 9], [9, 13], [13, 17]],
                                              'mean': np.round(blocks.mean(axis=0), 3).tolist(),
                                              'std_over_runs': np.round(blocks.std(axis=0), 3).tolist()},
    }


def stick_band(folder: Folder, settings: ObserverSettings = TRANSFER_SETTINGS) -> list[dict]:
    """Motor angle over which the current crosses from one friction branch to the other.

    At every reversal of the gearbox output (after the start-up) the filtered current's
    swing to the new branch's level (its median 0.15-0.25 rad after the reversal) is
    followed over the angle moved since the reversal; the band is the angle at which
    :data:`SWING_FRACTION` of the swing is done. Median per load level (rad): a band that
    grows with the tension would be cable stretch (a load-dependent Dahl width).
    """
    per_level: dict = {}
    for run in folder.runs:
        dt = float(np.median(np.diff(run.t)))
        current = causal_lowpass(run.current, settings.current_filter_hz, dt)
        angle = run.motor_shaft_angle
        step = np.sign(np.diff(causal_lowpass(angle, 5.0, dt), prepend=angle[0]))
        turns = np.flatnonzero((step[1:] * step[:-1] < 0) & (run.t[1:] - run.t[0] > C.STARTUP_S)) + 1
        for k in turns:
            moved = np.abs(angle[k:] - angle[k])
            start = float(np.median(current[max(0, k - 50):k + 1]))
            far = (moved > 0.15) & (moved < 0.25)
            if far.sum() < 20 or moved.max() < 0.25:
                continue
            end = float(np.median(current[k:][far]))
            swing = end - start
            if abs(swing) < 0.02:                 # no reversal of the friction (< 20 mA)
                continue
            done = np.flatnonzero((current[k:] - start) / swing >= SWING_FRACTION)
            if done.size:
                per_level.setdefault(run.torque_level_percent, []).append(float(moved[done[0]]))
    return [{'level_percent': lv, 'reversals': len(v), 'median_band_rad': round(float(np.median(v)), 4)}
            for lv, v in sorted(per_level.items())]


def data_checks(folder: Folder) -> dict:
    """Measure the data where no motor-side model can help: resolution, range, fast jaw torque.

    Reads every column (the analysis of the data, not an estimator).
    """
    cur = np.concatenate([r.current for r in folder.raw_runs])
    step = float(np.min(np.diff(np.unique(np.round(cur, 6)))))
    peaks = np.array([np.max(np.abs(r.current_command)) / C.BACKEND_COMMAND_FULL_SCALE
                      for r in folder.raw_runs])
    fast, jig = [], []
    for r in folder.runs:
        tau = r.jaw_torque - np.mean(r.jaw_torque)
        late = r.t - r.t[0] >= C.STARTUP_S
        slow = causal_lowpass(r.jaw_torque, FAST_HZ, float(np.median(np.diff(r.t))))
        fast.append((r.torque_level_percent, float(np.sqrt(np.mean((r.jaw_torque - slow)[late] ** 2)))))
        jig.append((r.torque_level_percent, float(np.std(tau[late]))))
    levels = sorted({lv for lv, _ in fast})

    def by_level(pairs):
        return [{'level_percent': lv, 'rms_mNm': round(1e3 * float(np.sqrt(np.mean(
            [v ** 2 for x, v in pairs if x == lv]))), 3)} for lv in levels]
    return {
        'current_resolution_A': round(step, 6),
        'command_peak_fraction_of_full_scale': {'median': round(float(np.median(peaks)), 4),
                                                'max': round(float(peaks.max()), 4),
                                                'runs_above_0.5': [r.name for r, p in
                                                                   zip(folder.raw_runs, peaks) if p > 0.5]},
        'jaw_torque_above_10Hz': by_level(fast),
        'jaw_torque_within_run_std': by_level(jig),
    }


def startup_observability(folder: Folder, settings: ObserverSettings = TRANSFER_SETTINGS) -> dict:
    """How much the current says about the load before the first slide, and after.

    Per run: the mean filtered current over the start-up (before the first sliding
    sample) and over the first closing slide after it; slope of each against the run's
    mean jaw torque over the folder's runs (A per N*m) and the correlation.
    """
    est = CableFrictionObserver(settings)
    before, after, load = [], [], []
    for run in folder.runs:
        sig = est._design(run)[0]
        on = np.flatnonzero(sig.sliding > 0)
        if not on.size:
            continue
        first = int(on[0])
        closing = np.flatnonzero((sig.sliding > 0) & (sig.direction > 0))
        before.append(float(np.mean(sig.current[:first])))
        after.append(float(np.mean(sig.current[closing[:500]])))
        load.append(float(np.mean(run.jaw_torque)))
    load = np.array(load)

    def fit(values):
        values = np.array(values)
        return {'slope_A_per_Nm': round(float(np.polyfit(load, values, 1)[0]), 4),
                'correlation': round(float(np.corrcoef(load, values)[0, 1]), 3)}
    return {'startup_mean_current': fit(before), 'first_closing_slide_current': fit(after)}


def startup_bound(folder: Folder, settings: ObserverSettings = TRANSFER_SETTINGS) -> dict:
    """Bound the whole-run RMSE by what the start-up alone costs, before the load can be seen.

    Before the first slide the motor side does not carry the load (correlation 0.3,
    :func:`startup_observability`). An estimator that gives those samples one value,
    whatever it is, is at best the mean of the folder's start-up torques (an oracle:
    chosen on the scored runs themselves); a linear function of the start-up mean current
    fitted on the scored runs (another oracle) does a little better. Their squared error
    spread over every sample of the folder is a lower bound on the whole-run RMSE,
    whatever the estimator does after the start-up. Also the bound from the samples
    before the disk has moved at all (:data:`STANDSTILL_COUNTS` encoder counts): there
    the current is a static friction, and the load cannot be seen from the motor side.

    Returns
    -------
    dict
        Sample fractions and whole-run RMSE bounds (mN*m) for the start-up (until the
        first sliding sample of ``settings``' observer) and the standstill.
    """
    est = CableFrictionObserver(settings)
    total, startup, currents, standstill = 0, [], [], []
    for run in folder.runs:
        sig = est._design(run)[0]
        on = np.flatnonzero(sig.sliding > 0)
        first = int(on[0]) if on.size else run.t.size
        total += run.t.size
        startup.append(run.jaw_torque[:first])
        currents.append(np.full(first, float(np.mean(sig.current[:first])) if first else 0.0))
        moved = np.flatnonzero(np.abs(run.motor_angle - run.motor_angle[0])
                               > STANDSTILL_COUNTS * C.TWO_PI / C.DISK_COUNTS_PER_REV)
        standstill.append(run.jaw_torque[:int(moved[0]) if moved.size else run.t.size])
    tau, current = np.concatenate(startup), np.concatenate(currents)
    still = np.concatenate(standstill)
    design = np.column_stack([current, np.ones_like(current)])
    linear = tau - design @ np.linalg.lstsq(design, tau, rcond=None)[0]

    def bound(residual):
        return round(1e3 * math.sqrt(float(residual @ residual) / total), 3)
    return {'startup_fraction_of_samples': round(tau.size / total, 4),
            'startup_torque_std_mNm': round(1e3 * float(np.std(tau)), 2),
            'bound_one_value_mNm': bound(tau - tau.mean()),
            'bound_linear_in_startup_current_mNm': bound(linear),
            'standstill_fraction_of_samples': round(still.size / total, 4),
            'bound_standstill_one_value_mNm': bound(still - still.mean()),
            'published_rmse_mNm': C.PUBLISHED_RMSE_NM * 1e3}


def plot_floor(panels: Sequence[tuple[str, Sequence[HeldOut]]], path: Path) -> Path:
    """Held-out error against the disk angle per friction branch, one panel per model."""
    from grip_force_ros.lab.plotting import pyplot, save
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.6), sharey=True)
    for ax, (title, items) in zip(np.atleast_1d(axes), panels):
        for h in items:
            colour = plt.cm.viridis(h.run.torque_level_percent / 100.0)
            for side, offset in ((1, 40.0), (-1, 0.0)):
                sel = np.flatnonzero((h.weight > 0) & (np.sign(h.direction) == side) & _late(h))[::40]
                ax.plot(h.run.motor_angle[sel], 1e3 * h.error[sel] + offset, '.', ms=1.2,
                        color=colour, alpha=0.5)
        ax.axhline(40.0, color='k', lw=0.6)
        ax.axhline(0.0, color='k', lw=0.6)
        ax.set_title(f'{title}:\n{rmse_mNm(items, skip_s=C.STARTUP_S):.2f} mN m after 1 s', fontsize=9)
        ax.set_xlabel('disk angle (rad, 0 = most closed)')
        ax.grid(alpha=0.3)
    axes[0].set_ylabel('held-out error (mN m): closing + 40, opening')
    fig.suptitle('in-folder floor (even/odd runs); colour = load 10 % (purple) .. 100 % (yellow)',
                 fontsize=9)
    return save(fig, path, dpi=80)


def analyse_floor(folder: Folder, *, quick: bool = False, out_dir=None, progress=None) -> dict:
    """Run the whole floor analysis of one folder, JSON-ready (``grip-force realdata --floor``).

    ``quick``: even/odd and leave-one-level-out only, no candidate beyond the two models.
    ``out_dir``: also write the figure ``realdata_floor.png`` there.
    """
    say = progress or (lambda msg: None)
    started = time.perf_counter()
    kinds = FOLD_KINDS[:2] if quick else FOLD_KINDS
    models = (('previous', replace(TRANSFER_SETTINGS, friction_map_order=0, load_model=False)),
              ('friction_map', replace(TRANSFER_SETTINGS, load_model=False)),
              ('transfer_model', TRANSFER_SETTINGS))
    result: dict = {'folder': folder.name, 'runs': len(folder.runs),
                    'model': 'transfer model (TRANSFER_SETTINGS), trained as transfer.train does',
                    'models': {'previous': 'no friction map, no load model',
                               'friction_map': 'friction map P1, no load model',
                               'transfer_model': 'friction map P1 and load model (the default)'},
                    'cross_validation': {}}
    keep = {}
    for label, settings in models:
        say(f'cross-validating the {label} model')
        rows = {}
        for kind in kinds:
            items = held_out(folder, settings, kind)
            rows[kind] = {'rmse_mNm': round(rmse_mNm(items), 3),
                          'rmse_after_startup_mNm': round(rmse_mNm(items, skip_s=C.STARTUP_S), 3)}
            if kind == 'even_odd':
                keep[settings] = items
        result['cross_validation'][label] = rows
    say('breaking the error down')
    result['breakdown'] = {label: breakdown(keep[settings]) for label, settings in models}
    say('non-causal bound, data checks, stick band')
    bound = held_out(folder, TRANSFER_SETTINGS, 'even_odd', two_sided=True)
    result['two_sided_bound_even_odd'] = {'rmse_mNm': round(rmse_mNm(bound), 3),
                                          'rmse_after_startup_mNm': round(rmse_mNm(
                                              bound, skip_s=C.STARTUP_S), 3)}
    result['data'] = data_checks(folder)
    result['startup_observability'] = startup_observability(folder)
    result['startup_bound'] = startup_bound(folder)
    result['stick_band'] = stick_band(folder)
    say('candidate terms')
    result['candidates'] = []
    for name, changes in (CANDIDATES[:2] if quick else CANDIDATES):
        settings = replace(TRANSFER_SETTINGS, **changes)
        items = keep[settings] if settings in keep else held_out(folder, settings, 'even_odd')
        result['candidates'].append({'name': name, 'changes': changes,
                                     'even_odd_rmse_mNm': round(rmse_mNm(items), 3),
                                     'even_odd_after_startup_mNm': round(rmse_mNm(
                                         items, skip_s=C.STARTUP_S), 3)})
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        titles = ('previous transfer model', 'with the friction map (Coulomb friction along the '
                  'stroke)', 'with the load model as well (the default)')
        panels = [(title, keep[settings]) for title, (_, settings) in zip(titles, models)]
        result['figure'] = str(plot_floor(panels, out / 'realdata_floor.png'))
    result['runtime_s'] = round(time.perf_counter() - started, 2)
    return result
