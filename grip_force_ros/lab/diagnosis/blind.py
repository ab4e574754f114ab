"""Blind check of the diagnosis: simulated logs with known effects, diagnosed without the answer.

Each log is a run of :class:`grip_force_ros.sim.InstrumentSim` (the plant, with the
sim's own versions of the docs/design.md effects) under a varied, seeded excitation:
segments of a few seconds, each opening the jaw (free motion, negative current),
closing it on a needle, tissue or rigid object and loading it with one of several
current profiles (ramps, steps with holds, sines, smoothed noise), while the wrist
moves. Noise levels vary per log, and no plant matches its YAML: pulley friction,
cable stiffness, torque constant and wrist-finger coupling differ per log (``_plant``;
the effect-free logs at fixed friction / stiffness mismatches, :data:`NONE_PLANTS`).
Effect strengths and time constants are drawn around the registry's values, off the
diagnosis' grid points. The diagnosis sees only the contract columns (t, current,
motor_angle, wrist_angle, jaw_angle, grip_force, object) - no name, seed, plant or
effect setting travels with a log.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from grip_force_ros.lab.diagnosis.effects import EFFECT_NAMES, EFFECTS, NONE
from grip_force_ros.effects import REGISTRY, SIMULATED

#: Effects the blind set holds: those of the diagnosis vocabulary the sim can generate. The
#: diagnosis still considers every effect of its vocabulary on every log (a verdict naming an
#: effect outside this set is a false positive like any other). Each is set around its registry
#: strengths (weak, medium, strong) and its registry ``blind_extras`` (:func:`cases`).
BLIND_EFFECTS = tuple(name for name in EFFECT_NAMES if name in SIMULATED)

#: Effects seen only in the jaw-angle channel: their shrink is that of the angle gap.
ANGLE_ONLY = tuple(name for name, e in EFFECTS.items() if not e.force_params and e.angle_params)

#: Object of a loaded segment -> its probability (the excitation's mix of contacts).
OBJECT_MIX = {'needle': 0.45, 'tissue': 0.3, 'rigid': 0.25}

#: Pairs of effects in the full check (medium strengths).
PAIRS = (('pivot_coulomb_friction', 'sensor_delay'), ('viscoelastic_creep', 'force_sensor_offset'),
         ('cable_hysteresis', 'torque_constant_drift'), ('backlash', 'tension_dependent_friction'))


#: Seeds of the blind set (``cases(seed=s)``), fixed: the development seeds are the ones the
#: thresholds, grids and strengths were tuned on; the held-out seeds give the headline figures and
#: are never tuned on; the CI seeds are the test's, never tuned on either.
DEVELOPMENT_SEEDS = (0, 1, 2, 3, 4)
HELD_OUT_SEEDS = tuple(range(100, 110))
CI_SEEDS = (50, 51, 52, 53)

#: Factor range (log-uniform) of an effect's strength around its registry level, and of its further
#: parameters (time constants, rest angle) around the registry's value: the blind logs sit off the
#: diagnosis' grid points.
STRENGTH_SPREAD = (0.8, 1.25)
EXTRA_SPREAD = (0.5, 2.0)

#: Plant mismatches of the effect-free logs: (pulley friction, cable stiffness) factors of the
#: plant against the YAML (the sim's ``friction_scale``, ``stiffness_scale``).
NONE_PLANTS = ((0.85, 1.0), (1.15, 1.0), (1.0, 0.8), (1.0, 1.2), (0.85, 0.8), (0.85, 1.2), (1.15, 0.8),
               (1.15, 1.2), (1.0, 1.0), (1.0, 1.0))
QUICK_NONE_PLANTS = ((0.85, 1.2), (1.15, 0.8), (1.0, 1.0))
#: Factor range (uniform) of the plant's torque constant and wrist-finger coupling against the YAML
#: on every log (a real instrument never matches its YAML).
SMALL_MISMATCH = (0.92, 1.08)


@dataclass(frozen=True)
class BlindCase:
    """One blind log: its effects (name -> strength), seed and plant. Never given to the diagnosis."""

    effects: tuple
    seed: int
    #: extra sim parameters of the effects (e.g. a time constant), name -> value
    extras: tuple = ()
    #: the plant against the YAML: instrument parameter -> factor (pulley friction and cable
    #: stiffness through the sim's friction_scale and stiffness_scale)
    plant: tuple = ()

    @property
    def truth(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.effects) or (NONE,)

    def plant_values(self, params) -> dict[str, float]:
        """Return the plant's values of the mismatched instrument parameters (their schema units)."""
        return {name: float(params[name]) * factor for name, factor in self.plant}


def _log_uniform(rng, low: float, high: float) -> float:
    return float(np.exp(rng.uniform(np.log(low), np.log(high))))


def _effect(rng, name: str, level: int) -> tuple[tuple, tuple]:
    """(name, strength) off the registry level, and the effect's further parameters off their values."""
    spec = REGISTRY[name]
    strength = float(np.clip(spec.strengths[level] * _log_uniform(rng, *STRENGTH_SPREAD), spec.min, spec.max))
    centre = {p.name: p.default for p in spec.params} | dict(spec.blind_extras)
    extras = tuple((k, v * _log_uniform(rng, *EXTRA_SPREAD)) for k, v in centre.items())
    return (name, strength), extras


def _plant(rng, friction: float | None = None, stiffness: float | None = None) -> tuple:
    """Plant factors: the given ones, or drawn (friction 0.85/1/1.15; stiffness 0.8 or 1.2, or 0.85-1.15)."""
    if friction is None:
        friction = float(rng.choice((0.85, 1.0, 1.15)))
    if stiffness is None:
        stiffness = float(rng.choice((0.8, 1.2))) if rng.uniform() < 1 / 3 else float(rng.uniform(0.85, 1.15))
    return (('pulley_friction_coefficient', friction), ('cable_modulus', stiffness),
            ('torque_constant', float(rng.uniform(*SMALL_MISMATCH))),
            ('wrist_finger_coupling', float(rng.uniform(*SMALL_MISMATCH))))


def cases(quick: bool = False, seed: int = 0, none_logs: int | None = None) -> list[BlindCase]:
    """Build the blind set of one seed: every effect at several strengths, pairs, effect-free logs.

    Strengths and time constants are drawn around the registry's (``STRENGTH_SPREAD``,
    ``EXTRA_SPREAD``); every plant differs from the YAML (``_plant``; the effect-free logs
    by :data:`NONE_PLANTS`). Full: each effect at three levels, :data:`PAIRS`, ten effect-free
    logs; quick: each effect at its medium level, one pair, three effect-free logs.
    """
    rng = np.random.default_rng([seed, 10])
    out = []
    k = seed * 1000
    levels = (1,) if quick else (0, 1, 2)
    for name in BLIND_EFFECTS:
        for lv in levels:
            effect, extras = _effect(rng, name, lv)
            out.append(BlindCase((effect,), k, extras, _plant(rng)))
            k += 1
    for a, b in (PAIRS[:1] if quick else PAIRS):
        (ea, xa), (eb, xb) = _effect(rng, a, 1), _effect(rng, b, 1)
        out.append(BlindCase((ea, eb), k, xa + xb, _plant(rng)))
        k += 1
    plants = QUICK_NONE_PLANTS if quick else NONE_PLANTS
    count = none_logs if none_logs is not None else len(plants)
    for i in range(count):
        out.append(BlindCase((), k, (), _plant(rng, *plants[i % len(plants)])))
        k += 1
    return out


def _smooth_noise(rng, n, dt, time_constant):
    """Unit-std noise through two first-order low-passes (smooth: its rate is bounded too)."""
    from scipy.signal import lfilter
    a = math.exp(-dt / time_constant)
    y = lfilter([1 - a], [1, -a], lfilter([1 - a], [1, -a], rng.normal(size=n)))
    return y / (np.std(y) + 1e-12)


def excitation(rng, duration: float, dt: float, max_current: float = 0.5):
    """Draw the current command (A), wrist (rad) and object per sample: seeded, varied segments."""
    n = int(round(duration / dt))
    # slow intensity envelope: busy and quiet periods (heats and cools the motor)
    period = rng.uniform(30.0, 60.0)
    envelope_phase = rng.uniform(0.0, 2.0 * np.pi)
    current = np.empty(n)
    objects = np.empty(n, dtype=object)
    i = 0
    while i < n:
        seg = int(rng.uniform(3.0, 8.0) / dt)
        obj = str(rng.choice(list(OBJECT_MIX), p=list(OBJECT_MIX.values())))
        open_n = int(rng.uniform(0.4, 0.9) / dt)
        t = np.arange(seg) * dt
        load_t = t[open_n:] - t[open_n]
        span = max(load_t[-1], dt)
        envelope = 0.5 + 0.5 * math.sin(2.0 * math.pi * i * dt / period + envelope_phase)
        top = rng.uniform(0.5, 1.0) * (0.2 + 0.8 * envelope) * max_current
        kind = rng.integers(0, 4)
        if kind == 0:      # triangle ramps up and down, 1-3 cycles
            cycles = rng.integers(1, 4)
            phase = (load_t / span * cycles) % 1.0
            prof = top * (1.0 - np.abs(2.0 * phase - 1.0))
        elif kind == 1:    # steps with holds
            levels = rng.uniform(0.05, 1.0, size=rng.integers(2, 5)) * top
            idx = np.minimum((load_t / span * levels.size).astype(int), levels.size - 1)
            prof = levels[idx]
        elif kind == 2:    # sine around a mean
            f = rng.uniform(0.2, 1.5)
            prof = top * (0.55 + 0.4 * np.sin(2 * np.pi * f * load_t + rng.uniform(0, 6.28)))
        else:              # smoothed noise
            prof = top * np.clip(0.5 + 0.25 * _smooth_noise(rng, load_t.size, dt, rng.uniform(0.15, 0.5)),
                                 0.02, 1.0)
        open_current = -rng.uniform(0.03, 0.12)
        block = np.concatenate([np.full(open_n, open_current), prof])[: n - i]
        current[i:i + block.size] = block
        objects[i:i + block.size] = obj
        i += block.size
    t = np.arange(n) * dt
    wrist = np.zeros(n)
    for _ in range(3):                   # smooth wrist motion: a few slow sines (0.03..0.3 Hz)
        wrist += rng.uniform(0.05, 0.3) * np.sin(2 * np.pi * rng.uniform(0.03, 0.3) * t + rng.uniform(0, 6.3))
    return current, wrist, objects


def plant_params(case: BlindCase, params=None):
    """Parameters of the simulated plant of ``case``: the YAML ``params`` (schema defaults) with its mismatch.

    Pulley friction and cable stiffness differ through the sim's ``friction_scale`` and
    ``stiffness_scale`` (the plant's mu and E*A/L; the YAML keeps its values), the torque
    constant and the wrist-finger coupling by their plant values.
    """
    from grip_force_ros.params import make_params
    base = make_params() if params is None else params
    plant = dict(case.plant)
    return base.replace(friction_scale=plant.get('pulley_friction_coefficient', 1.0),
                        stiffness_scale=plant.get('cable_modulus', 1.0),
                        torque_constant=base.torque_constant * plant.get('torque_constant', 1.0),
                        wrist_finger_coupling=base.wrist_finger_coupling
                        * plant.get('wrist_finger_coupling', 1.0))


def generate_log(case: BlindCase, *, duration: float = 60.0, dt: float = 1e-3, params=None) -> dict:
    """Simulate one blind log; returns only the docs/design.md contract columns."""
    from grip_force_ros.sim import InstrumentSim

    rng = np.random.default_rng(case.seed)
    noise = rng.uniform(0.6, 1.6)
    p = plant_params(case, params).replace(
        current_noise_std=0.002 * noise, jaw_angle_noise_std=1e-3 * noise, motor_angle_noise_std=1e-4 * noise,
        wrist_angle_noise_std=1e-3 * noise, grip_force_noise_std=0.02 * noise,
        sim_seed=int(case.seed % (2**31 - 1)))
    current, wrist, objects = excitation(rng, duration, dt, p.max_current)
    sim = InstrumentSim(p, obj=str(objects[0]), effects={**dict(case.effects), **dict(case.extras)},
                        seed=int(case.seed))
    n = current.size
    cols = {k: np.empty(n) for k in ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force')}
    last_obj = None
    for k in range(n):
        if objects[k] != last_obj:
            last_obj = objects[k]
            sim.set_object(str(last_obj))
        sim.set_wrist_angle(float(wrist[k]))
        sim.step(float(current[k]), dt)
        m = sim.measure()
        cols['t'][k] = m.t
        cols['current'][k] = m.current
        cols['motor_angle'][k] = m.motor_angle
        cols['wrist_angle'][k] = m.wrist_angle
        cols['jaw_angle'][k] = m.jaw_angle
        cols['grip_force'][k] = m.grip_force
    cols['object'] = objects.astype(str)
    return cols


def is_right(truth, verdict: dict) -> bool:
    """Tell whether a verdict names the truth.

    The effect first for one effect, every effect of a pair, ``none`` alone for none.
    """
    named = list(verdict.get('effects', [verdict['effect']]))
    if tuple(truth) == (NONE,):
        return named == [NONE]
    if len(truth) == 1:
        return verdict['effect'] == truth[0]
    return set(truth) <= set(named)


def _parameter_check(case: BlindCase, result: dict, params) -> dict:
    """Fitted against true plant values of the re-identified parameters (relative error, named off)."""
    fitted = result['calibration'].get('parameters', {})
    off = set(result['calibration'].get('parameters_off', []))
    truth = case.plant_values(params)
    out = {}
    for name, value in truth.items():
        if name in fitted and fitted[name].get('fitted') is not None:
            out[name] = {'truth': value, 'factor': dict(case.plant)[name], 'fitted': fitted[name]['fitted'],
                         'rel_err': fitted[name]['fitted'] / value - 1.0, 'named_off': name in off}
    return out


#: A plant factor this far from 1 makes a parameter "off" (the blind set's 0.85/1.15, 0.8/1.2).
OFF_FACTOR = 0.1
#: Relative error of a fitted parameter that counts as recovered.
PARAMETER_TOLERANCE = 0.05


def _one_seed(quick: bool, seed: int, duration: float, params, say) -> dict:
    """Generate one seed's blind set, diagnose each log blind, score the verdicts."""
    from grip_force_ros.lab.diagnosis.engine import diagnose
    say = say or (lambda msg: None)
    from grip_force_ros.params import make_params

    yaml_params = make_params() if params is None else params
    per_log = []
    for i, case in enumerate(cases(quick, seed)):
        log = generate_log(case, duration=duration, params=params)
        result = diagnose([log], params=params, seed=case.seed)
        v = result['verdict']
        truth = case.truth
        right = is_right(truth, v)
        # shrink in the channel the named effect acts on (the jaw angle for angle-only effects)
        angle_only = v['effect'] in ANGLE_ONLY
        shrink = (1.0 - v['angle_gap_after'] / v['angle_gap_before']) if angle_only else v['shrink']
        per_log.append({'seed': seed, 'truth': list(truth), 'strengths': [s for _, s in case.effects],
                        'extras': dict(case.extras), 'plant': dict(case.plant),
                        'verdict': v['effect'], 'named': v.get('effects', [v['effect']]), 'right': right,
                        'gap_before': v['gap_before'],
                        'gap_after': v['gap_after'], 'force_shrink': v['shrink'], 'shrink': shrink,
                        'angle_gap_before': v['angle_gap_before'], 'angle_gap_after': v['angle_gap_after'],
                        'runner_up': v['runner_up'],
                        'parameters': _parameter_check(case, result, yaml_params)})
        say(f'[seed {seed}, {i + 1}] truth={"+".join(truth)} named={"+".join(per_log[-1]["named"])} '
            f'shrink={shrink:.2f} {"ok" if right else "WRONG"}')
    return _score(per_log)


def _score(per_log: list) -> dict:
    """Scores of a list of blind logs (see :func:`run_blindcheck`)."""
    labels = list(EFFECT_NAMES) + [NONE]
    confusion = {t: {p: 0 for p in labels} for t in labels + ['pair']}
    for r in per_log:
        row = r['truth'][0] if len(r['truth']) == 1 else 'pair'
        confusion[row][r['verdict']] += 1
    effect_logs = [r for r in per_log if r['truth'] != [NONE]]
    none_logs = [r for r in per_log if r['truth'] == [NONE]]
    mismatch = _mismatch(per_log)
    return {'logs': len(per_log),
            'accuracy': float(np.mean([r['right'] for r in per_log])),
            'median_shrink': float(np.median([r['shrink'] for r in effect_logs])) if effect_logs else None,
            'none_accuracy': float(np.mean([r['right'] for r in none_logs])) if none_logs else None,
            'median_force_shrink': (float(np.median([r['force_shrink'] for r in effect_logs]))
                                    if effect_logs else None),
            'pair_accuracy': (float(np.mean([r['right'] for r in per_log if len(r['truth']) == 2]))
                              if any(len(r['truth']) == 2 for r in per_log) else None),
            'mismatch_recovered': mismatch['within_5pct'], 'mismatch': mismatch,
            'confusion': confusion, 'per_log': per_log}


#: Plant parameters the mismatch figures are about (the sim's friction_scale, stiffness_scale).
MISMATCHED = ('pulley_friction_coefficient', 'cable_modulus')


def _off(r: dict) -> list[str]:
    """Return the MISMATCHED parameters a blind log's plant has off the YAML by >= OFF_FACTOR."""
    return [name for name in MISMATCHED if abs(r['plant'].get(name, 1.0) - 1.0) >= OFF_FACTOR - 1e-9]


def _mismatch(per_log: list) -> dict:
    """Figures of the logs whose plant has its pulley friction or cable stiffness off.

    ``logs``: effect-free logs with a parameter off; ``none``: their share reported ``none``;
    ``within_5pct``: the share of their off parameters named off with the fitted value within
    :data:`PARAMETER_TOLERANCE` of the plant's; ``effect_logs``, ``effect_named``: the logs with
    an effect (or a pair) and a parameter off, and their share named right.
    """
    def share(values):
        return float(np.mean(values)) if values else None

    free = [r for r in per_log if r['truth'] == [NONE] and _off(r)]
    with_effect = [r for r in per_log if r['truth'] != [NONE] and _off(r)]
    params = [r['parameters'][name] for r in free for name in _off(r) if name in r['parameters']]
    # an off parameter left unidentified (absent from r['parameters']) counts as missed
    missed = sum(name not in r['parameters'] for r in free for name in _off(r))
    return {'logs': len(free), 'none': share([r['right'] for r in free]),
            'within_5pct': share([c['named_off'] and abs(c['rel_err']) <= PARAMETER_TOLERANCE
                                  for c in params] + [False] * missed),
            'effect_logs': len(with_effect), 'effect_named': share([r['right'] for r in with_effect])}


#: Scores averaged over seeds (mean) and taken at their worst seed (min); those of ``mismatch`` apart.
SCORES = ('accuracy', 'median_shrink', 'none_accuracy', 'median_force_shrink', 'pair_accuracy',
          'mismatch_recovered')
MISMATCH_SCORES = ('none', 'within_5pct', 'effect_named')


def _over_seeds(values: list, how) -> float | None:
    """Return ``how`` (mean or min) of per-seed figures, None when a seed has none."""
    return float(how(values)) if all(v is not None for v in values) else None


def run_blindcheck(quick: bool = False, seed: int = HELD_OUT_SEEDS[0], *, seeds: int = 1,
                   duration: float | None = None, progress=None, params=None, workers: int = 1) -> dict:
    """Generate the blind sets of ``seeds`` seeds from ``seed`` on, diagnose each log blind, score.

    ``workers`` > 1 diagnoses that many seeds at once, one process each (the same figures:
    every seed is independent and seeded; no progress lines from the workers).

    Returns
    -------
    dict
        ``logs`` (count), ``accuracy`` (share named right: the effect named first for a
        single effect, both effects named for a pair, ``none`` for an effect-free log),
        ``median_shrink`` (median held-out 1 - gap_after/gap_before over logs with an
        effect, in the channel of the named effect: the jaw angle for backlash, the
        measured force otherwise), ``median_force_shrink`` (the same, force channel
        only), ``none_accuracy`` (share of effect-free logs reported ``none``),
        ``pair_accuracy``, ``mismatch_recovered`` (share of the off parameters of the
        effect-free logs named off and fitted within 5 %): each the mean of the per-seed
        figures; ``mismatch`` (the logs whose plant has its pulley friction or cable
        stiffness >= 10 % off, :func:`_mismatch`: ``logs``, ``none``, ``within_5pct``,
        ``effect_logs``, ``effect_named``; counts summed, shares the mean of the per-seed
        ones); ``worst`` (each figure at its worst seed), ``per_seed`` (each seed's
        figures), ``confusion`` (truth -> verdict -> count, all seeds), ``per_log`` (truth,
        strengths, plant, verdict, gaps, fitted parameters), ``seconds``.
    """
    say = progress or (lambda msg: None)
    duration = duration or (60.0 if quick else 90.0)
    start = time.perf_counter()
    todo = range(seed, seed + seeds)
    if workers > 1 and seeds > 1:
        import concurrent.futures as cf
        import multiprocessing
        say(f'{seeds} seeds in {min(workers, seeds)} processes')
        with cf.ProcessPoolExecutor(max_workers=min(workers, seeds),
                                    mp_context=multiprocessing.get_context('spawn')) as pool:
            runs = list(pool.map(_one_seed, *zip(*[(quick, s, duration, params, None) for s in todo])))
    else:
        runs = [_one_seed(quick, s, duration, params, say) for s in todo]
    mean = {k: _over_seeds([r[k] for r in runs], np.mean) for k in SCORES}
    worst = {k: _over_seeds([r[k] for r in runs], np.min) for k in SCORES}
    mismatch = [r['mismatch'] for r in runs]
    mean['mismatch'] = {'logs': sum(m['logs'] for m in mismatch),
                        'effect_logs': sum(m['effect_logs'] for m in mismatch),
                        **{k: _over_seeds([m[k] for m in mismatch], np.mean) for k in MISMATCH_SCORES}}
    worst['mismatch'] = {k: _over_seeds([m[k] for m in mismatch], np.min) for k in MISMATCH_SCORES}
    confusion = runs[0]['confusion']
    for r in runs[1:]:
        for truth, row in r['confusion'].items():
            for verdict, count in row.items():
                confusion[truth][verdict] += count
    return {'logs': sum(r['logs'] for r in runs), **mean, 'worst': worst,
            'per_seed': [{'seed': s, **{k: r[k] for k in ('logs',) + SCORES + ('mismatch',)}}
                         for s, r in zip(range(seed, seed + seeds), runs)],
            'confusion': confusion, 'per_log': [x for r in runs for x in r['per_log']],
            'settings': {'quick': quick, 'seed': seed, 'seeds': seeds, 'duration_s': duration,
                         'rate_hz': 1000.0},
            'seconds': time.perf_counter() - start}
