"""Blind check of the diagnosis: simulated logs with known effects, diagnosed without the answer.

Each log is a run of :class:`grip_force_ros.sim.InstrumentSim` (the plant, with the
sim's own versions of the docs/design.md effects) under a varied, seeded excitation:
segments of a few seconds, each opening the jaw (free motion, negative current),
closing it on a needle, tissue or rigid object and loading it with one of several
current profiles (ramps, steps with holds, sines, smoothed noise), while the wrist
moves. Noise levels and the plant's cable stiffness vary per log. The diagnosis sees
only the contract columns (t, current, motor_angle, wrist_angle, jaw_angle,
grip_force, object) - no name, seed or effect setting travels with a log.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from grip_force_ros.diagnosis.effects import EFFECT_NAMES, EFFECTS, NONE
from grip_force_ros.effects import REGISTRY, SIMULATED

#: Effects the blind set holds: those of the diagnosis vocabulary the sim can generate. The
#: diagnosis still considers every effect of its vocabulary on every log (a verdict naming an
#: effect outside this set is a false positive like any other). Each is set at its registry
#: strengths (weak, medium, strong) with its registry ``blind_extras``.
BLIND_EFFECTS = tuple(name for name in EFFECT_NAMES if name in SIMULATED)

#: Effects seen only in the jaw-angle channel: their shrink is that of the angle gap.
ANGLE_ONLY = tuple(name for name, e in EFFECTS.items() if not e.force_params and e.angle_params)

#: Object of a loaded segment -> its probability (the excitation's mix of contacts).
OBJECT_MIX = {'needle': 0.45, 'tissue': 0.3, 'rigid': 0.25}

#: Pairs of effects in the full check (medium strengths).
PAIRS = (('pivot_coulomb_friction', 'sensor_delay'), ('viscoelastic_creep', 'force_sensor_offset'),
         ('cable_hysteresis', 'torque_constant_drift'), ('backlash', 'tension_dependent_friction'))


@dataclass(frozen=True)
class BlindCase:
    """One blind log: its effects (name -> strength) and seed. Never given to the diagnosis."""

    effects: tuple
    seed: int
    #: extra sim parameters of the effects (e.g. a time constant), name -> value
    extras: tuple = ()

    @property
    def truth(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.effects) or (NONE,)


def cases(quick: bool = False, seed: int = 0, none_logs: int | None = None) -> list[BlindCase]:
    """Build the blind set: every effect at several strengths, some pairs, effect-free logs."""
    out = []
    k = seed * 1000
    levels = (1,) if quick else (0, 1, 2)
    for name in BLIND_EFFECTS:
        for lv in levels:
            out.append(BlindCase(((name, REGISTRY[name].strengths[lv]),), k, REGISTRY[name].blind_extras))
            k += 1
    for a, b in (PAIRS[:1] if quick else PAIRS):
        out.append(BlindCase(((a, REGISTRY[a].strengths[1]), (b, REGISTRY[b].strengths[1])), k,
                             REGISTRY[a].blind_extras + REGISTRY[b].blind_extras))
        k += 1
    for _ in range(none_logs if none_logs is not None else (3 if quick else 10)):
        out.append(BlindCase((), k))
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


def generate_log(case: BlindCase, *, duration: float = 60.0, dt: float = 1e-3, params=None) -> dict:
    """Simulate one blind log; returns only the docs/design.md contract columns."""
    from grip_force_ros.params import make_params
    from grip_force_ros.sim import InstrumentSim

    rng = np.random.default_rng(case.seed)
    noise = rng.uniform(0.6, 1.6)
    values = {'stiffness_scale': float(rng.uniform(0.85, 1.15)),
              'current_noise_std': 0.002 * noise, 'jaw_angle_noise_std': 1e-3 * noise,
              'motor_angle_noise_std': 1e-4 * noise, 'wrist_angle_noise_std': 1e-3 * noise,
              'grip_force_noise_std': 0.02 * noise, 'sim_seed': int(case.seed % (2**31 - 1))}
    if params is not None:
        values = {**{k: params[k] for k in params.keys()}, **values} if hasattr(params, 'keys') else values
    p = make_params(values)
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


def run_blindcheck(quick: bool = False, seed: int = 0, *, duration: float | None = None,
                   progress=None, params=None) -> dict:
    """Generate the blind set, diagnose each log blind, score the verdicts.

    Returns
    -------
    dict
        ``logs`` (count), ``accuracy`` (share named right; a pair is right when
        either of its effects is named), ``median_shrink`` (median held-out
        1 - gap_after/gap_before over logs with an effect, in the channel of the
        named effect: the jaw angle for backlash, the measured force otherwise),
        ``median_force_shrink`` (the same, force channel only), ``none_accuracy``
        (share of effect-free logs reported ``none``), ``confusion`` (truth ->
        verdict -> count), ``per_log`` (truth, strengths, verdict, gaps), ``seconds``.
    """
    from grip_force_ros.diagnosis.engine import diagnose

    say = progress or (lambda msg: None)
    duration = duration or (60.0 if quick else 90.0)
    start = time.perf_counter()
    per_log = []
    for i, case in enumerate(cases(quick, seed)):
        log = generate_log(case, duration=duration, params=params)
        result = diagnose([log], params=params, seed=case.seed)
        v = result['verdict']
        truth = case.truth
        right = v['effect'] in truth
        # shrink in the channel the named effect acts on (the jaw angle for angle-only effects)
        angle_only = v['effect'] in ANGLE_ONLY
        shrink = (1.0 - v['angle_gap_after'] / v['angle_gap_before']) if angle_only else v['shrink']
        per_log.append({'truth': list(truth), 'strengths': [s for _, s in case.effects],
                        'verdict': v['effect'], 'named': v.get('effects', [v['effect']]), 'right': right,
                        'gap_before': v['gap_before'],
                        'gap_after': v['gap_after'], 'force_shrink': v['shrink'], 'shrink': shrink,
                        'angle_gap_before': v['angle_gap_before'], 'angle_gap_after': v['angle_gap_after'],
                        'runner_up': v['runner_up']})
        say(f'[{i + 1}] truth={"+".join(truth)} verdict={v["effect"]} shrink={shrink:.2f}'
            f' {"ok" if right else "WRONG"}')
    labels = list(EFFECT_NAMES) + [NONE]
    confusion = {t: {p: 0 for p in labels} for t in labels + ['pair']}
    for r in per_log:
        row = r['truth'][0] if len(r['truth']) == 1 else 'pair'
        confusion[row][r['verdict']] += 1
    effect_logs = [r for r in per_log if r['truth'] != [NONE]]
    none_logs = [r for r in per_log if r['truth'] == [NONE]]
    return {'logs': len(per_log),
            'accuracy': float(np.mean([r['right'] for r in per_log])),
            'median_shrink': float(np.median([r['shrink'] for r in effect_logs])) if effect_logs else None,
            'none_accuracy': float(np.mean([r['right'] for r in none_logs])) if none_logs else None,
            'median_force_shrink': (float(np.median([r['force_shrink'] for r in effect_logs]))
                                    if effect_logs else None),
            'confusion': confusion, 'per_log': per_log,
            'settings': {'quick': quick, 'seed': seed, 'duration_s': duration, 'rate_hz': 1000.0},
            'seconds': time.perf_counter() - start}
