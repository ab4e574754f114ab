"""Safety properties of the controller over random and garbage input sequences.

For every step: |current command| <= max_current, |change| <= max_current_slew * dt (the step
time, test/_control_oracle.py),
every output finite, 0 <= target force <= min(grip_force_max, max_grip_force).

CI runs ``test_random_sequences``: 120 000 steps (at least 100k) over 30 seeded numpy
sequences, about 2-3 s, plus the hypothesis examples. ``test_random_sequences_full`` (marked
``slow``) runs GRIP_FORCE_PROPERTY_STEPS steps (default 500 000), e.g.
``./dev test test/test_control_properties.py -m slow``.
"""
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _control_oracle import StepClock
from grip_force_ros.control import GripController
from grip_force_ros.params import make_params

STEPS_CI = 120_000
STEPS_SLOW = int(os.environ.get('GRIP_FORCE_PROPERTY_STEPS', '500000'))

GARBAGE = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -5.0, 7.0, None, 'x']


def random_params(rng):
    """Valid controller/limit parameters across their ranges (random gains too)."""
    return make_params({
        'max_current': float(rng.uniform(0.05, 3.0)),
        'max_current_slew': float(rng.choice([1.0, 50.0, 100.0, 2000.0])),
        'max_grip_force': float(rng.uniform(0.5, 20.0)),
        'grip_force_max': float(rng.uniform(0.0, 40.0)),
        'force_kp': float(rng.choice([0.0, 0.01, 1.0, 10.0])),
        'force_ki': float(rng.choice([0.0, 1.0, 100.0, 1000.0])),
        'force_kd': float(rng.choice([0.0, 1e-3, 0.5])),
        'jaw_kp': float(rng.choice([0.0, 0.5, 50.0])),
        'jaw_ki': float(rng.choice([0.0, 5.0, 5000.0])),
        'jaw_kd': float(rng.choice([0.0, 0.01, 5.0])),
        'force_map_exponent': float(rng.uniform(0.2, 5.0)),
        'master_contact_angle': float(rng.uniform(-0.2, 1.0)),
        'object_kind': str(rng.choice(['needle', 'tissue', 'rigid', 'free'])),
        'force_sensor_enabled': bool(rng.random() < 0.3),
        'feedforward_enabled': bool(rng.random() < 0.8),
        'anti_windup_tracking_time': float(rng.choice([1e-4, 0.01, 5.0])),
    })


def value(rng, nominal, spread, garbage_rate):
    if rng.random() < garbage_rate:
        return GARBAGE[rng.integers(len(GARBAGE))]
    return float(nominal + spread * rng.standard_normal())


class Checker:
    def __init__(self, params):
        self.params = params
        self.max_current = params.max_current
        self.clock = StepClock()
        self.force_max = min(params.grip_force_max, params.max_grip_force)
        self.previous = 0.0
        self.previous_mode = 'free'
        self.steps = 0
        self.modes = {'free': 0, 'grip': 0, 'safe': 0}
        self.limits = 0

    def check(self, out, now):
        max_step = self.params.max_current_slew * self.clock.dt(now, self.params)
        c = out.current_command
        for name in ('current_command', 'target_force', 'estimated_force', 'pull_out_force',
                     'target_jaw_angle', 'feedforward_current'):
            assert math.isfinite(getattr(out, name)), (name, out)
        assert abs(c) <= self.max_current + 1e-12, out
        assert abs(c - self.previous) <= max_step * (1 + 1e-9) + 1e-15, (self.previous, out)
        assert 0.0 <= out.target_force <= self.force_max + 1e-12, out
        assert out.mode in ('free', 'grip', 'safe')
        assert set(out.limits_hit) <= {'current_limit', 'slew_limit'}
        assert all(isinstance(r, str) for r in out.reasons)
        if out.mode == 'safe' and self.previous_mode == 'safe':   # the ramp only goes to 0 A
            assert abs(c) <= abs(self.previous), (self.previous, out)
        self.previous = c
        self.previous_mode = out.mode
        self.steps += 1
        self.modes[out.mode] += 1
        self.limits += bool(out.limits_hit)


def run_sequence(seed, n_steps):
    """One random sequence: plausible motion with faults, silences, clock jumps, garbage.

    All random numbers are drawn up front (vectorised), the loop only feeds them.
    """
    rng = np.random.default_rng(seed)
    params = random_params(rng)
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    check = Checker(params)
    garbage_rate = float(rng.choice([0.0, 0.001, 0.02, 0.2]))
    n = n_steps
    dt = 1e-3 * rng.choice([1.0, 0.0, 3.0, 40.0, -1.0], size=n, p=[.9, .03, .03, .02, .02])
    t = float(rng.uniform(0, 1e4)) + np.cumsum(dt)
    master = np.clip(0.6 + np.cumsum(0.01 * rng.standard_normal(n)), -0.6, 1.8)
    jaw = np.clip(master + 0.05 * rng.standard_normal(n), 0.0, 1.5)
    stamp = t - 1e-3 * rng.choice([0.0, 1.0, -200.0, 2.0, 0.5], size=n, p=[.8, .1, .02, .04, .04])
    present = rng.random((n, 4)) < np.array([0.95, 0.95, 0.95, 0.9])
    # 9 values per step: master, wrist, jaw, jaw velocity, current (about the command),
    # motor angle, motor velocity, force, controller clock
    values = np.column_stack([master, 0.2 + 0.5 * rng.standard_normal(n), jaw,
                              rng.standard_normal(n), 0.01 * rng.standard_normal(n),
                              rng.standard_normal(n), rng.standard_normal(n),
                              3.0 + 3.0 * rng.standard_normal(n), t]).tolist()
    bad = np.argwhere(rng.random((n, 9)) < garbage_rate).tolist()
    picks = rng.integers(len(GARBAGE), size=len(bad)).tolist()
    for (k, j), g in zip(bad, picks):
        values[k][j] = GARBAGE[g] if j < 8 else GARBAGE[g % 6]
    malformed = set(np.nonzero(rng.random(n) < 0.002)[0].tolist())
    t, stamp, present = t.tolist(), stamp.tolist(), present.tolist()
    for k in range(n):
        m, wrist, jw, jv, di, ma, mv, force, now = values[k]
        tk, sk, (pm, pi, pa, pf) = t[k], stamp[k], present[k]
        if pm:
            inp.set_master(tk, m, stamp=sk)
        if pi:
            inp.set_instrument(tk, wrist, jw, jv, stamp=sk)
        if pa:
            inp.set_actuator(tk, ctrl.command + di if isinstance(di, float) else di, ma, mv, stamp=sk)
        if pf:
            inp.set_force(tk, force, stamp=sk)
        if k in malformed:
            inp.reject('instrument', tk, 'missing joint jaw')
        check.check(ctrl.step(now, inp), now)
    return check


def test_random_sequences():
    """STEPS_CI (>= 100k) steps over 30 seeded random sequences (random parameters each)."""
    n = STEPS_CI // 30
    checks = [run_sequence(seed, n) for seed in range(30)]
    assert sum(c.steps for c in checks) == 30 * n
    # the sequences visit every mode and hit the limits (the properties are not vacuous)
    for mode in ('free', 'grip', 'safe'):
        assert sum(c.modes[mode] for c in checks) > 0.05 * STEPS_CI, mode
    assert sum(c.limits for c in checks) > 0.01 * STEPS_CI


@pytest.mark.slow
def test_random_sequences_full():
    """>= 100k steps (GRIP_FORCE_PROPERTY_STEPS, default 200000)."""
    n = 20000
    seqs = max(1, STEPS_SLOW // n)
    assert sum(run_sequence(1000 + seed, n).steps for seed in range(seqs)) == seqs * n >= 100_000


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.floats(-2.0, 2.0), st.none(), st.text(max_size=2))
sample = st.tuples(
    st.floats(0.0, 0.1),                   # time advance (s)
    st.sampled_from(['master', 'instrument', 'actuator', 'force', 'none', 'all']),
    finite_or_not, finite_or_not, finite_or_not,
    st.one_of(st.just(math.nan), st.floats(-1.0, 1.0)),   # stamp offset (s) or no stamp
)


@settings(max_examples=150, deadline=None)
@given(st.lists(sample, min_size=1, max_size=150), st.integers(0, 2**31 - 1))
def test_hypothesis_input_sequences(samples, seed):
    rng = np.random.default_rng(seed)
    params = random_params(rng)
    ctrl = GripController(params)
    inp = ctrl.new_inputs()
    check = Checker(params)
    t = 100.0
    for dt, which, a, b, c, stamp_offset in samples:
        t += dt
        stamp = t + stamp_offset
        if which in ('master', 'all'):
            inp.set_master(t, a, stamp=stamp)
        if which in ('instrument', 'all'):
            inp.set_instrument(t, a, b, c, stamp=stamp)
        if which in ('actuator', 'all'):
            inp.set_actuator(t, a, b, c, stamp=stamp)
        if which in ('force', 'all'):
            inp.set_force(t, b, stamp=stamp)
        check.check(ctrl.step(t, inp), t)
        # and a good sample of every input, so grip and free modes are visited too
        inp.set_master(t, float(rng.uniform(0.0, 1.2)))
        inp.set_instrument(t, 0.0, float(rng.uniform(0.0, 1.0)), 0.0)
        inp.set_actuator(t, ctrl.command)
        inp.set_force(t, float(rng.uniform(0.0, 10.0)))
        check.check(ctrl.step(t + 1e-3, inp), t + 1e-3)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.5, 2.0), st.floats(-0.2, 1.6), st.floats(-5.0, 5.0)),
                min_size=1, max_size=60),
       st.floats(0.0, 50.0), st.floats(0.2, 5.0), st.floats(-0.3, 1.0))
def test_force_map_bounded_and_monotone(samples, force_max, exponent, contact):
    from grip_force_ros.control import ForceMap
    fm = ForceMap(master_angle_min=0.0, master_contact_angle=contact, master_to_jaw_gain=1.2,
                  jaw_angle_max=1.5, force_max=force_max, exponent=exponent)
    for master, jaw, jaw_velocity in samples:
        gripping, target = fm.update(master, jaw, jaw_velocity)
        if gripping:
            assert 0.0 <= target <= force_max
            # closing the master further never lowers the target
            assert fm.force_target(master - 0.01) >= target
        else:
            assert 0.0 <= target <= 1.5                       # a jaw angle inside its range
