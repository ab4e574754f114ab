"""Safety properties of the controller core under runtime retuning.

``test/test_control_properties.py`` checks the three properties of the issue (current and
slew limits, finite outputs, target force <= the configured maximum) over >= 100k random
steps with fixed parameters. Here the same properties must hold while the parameters a
node accepts at runtime (everything not read-only: gains, force map, watchdog, feedback
source, object) change at random moments, as ``ControllerNode._on_params`` applies them
with ``GripController.update_params``. The read-only hardware limits stay fixed, as the
node guarantees.

Properties, every period:
* |command| <= max_current and |command - previous command| <= max_current_slew * dt (the
  step time, test/_control_oracle.py),
  across every retune (the retune itself never makes the output jump);
* every output is finite;
* 0 <= target force <= min(grip_force_max in force, max_grip_force).
"""
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from _control_oracle import StepClock
from grip_force_ros.control import GripController
from grip_force_ros.params import SPECS, make_params

#: Random steps of the seeded test (CI); with the hypothesis examples > 100k in all.
STEPS = 100_000
GARBAGE = [math.nan, math.inf, -math.inf, 1e300, -5.0, 7.0]


def hardware(rng):
    """Read-only limits, fixed for a whole sequence."""
    return {'max_current': float(rng.uniform(0.05, 3.0)),
            'max_current_slew': float(rng.choice([1.0, 100.0, 5000.0])),
            'max_grip_force': float(rng.uniform(0.5, 20.0))}


def tunable(rng):
    """A random set of runtime-settable parameters, each within its schema range."""
    values = {
        'force_kp': float(rng.choice([0.0, 0.02, 1.0, 10.0])),
        'force_ki': float(rng.choice([0.0, 8.8, 300.0, 1000.0])),
        'force_kd': float(rng.choice([0.0, 1e-3, 0.5])),
        'jaw_kp': float(rng.choice([0.0, 0.5, 50.0])),
        'jaw_ki': float(rng.choice([0.0, 5.0, 5000.0])),
        'grip_force_max': float(rng.uniform(0.0, 200.0)),
        'force_map_exponent': float(rng.uniform(0.2, 5.0)),
        'master_contact_angle': float(rng.uniform(-0.2, 1.0)),
        'watchdog_timeout': float(rng.choice([0.002, 0.03, 0.5])),
        'object_kind': str(rng.choice(['needle', 'tissue', 'rigid', 'free'])),
        'force_sensor_enabled': bool(rng.random() < 0.3),
        'feedforward_enabled': bool(rng.random() < 0.8),
    }
    keys = list(values)
    chosen = rng.choice(len(keys), size=int(rng.integers(1, len(keys) + 1)), replace=False)
    out = {keys[i]: values[keys[i]] for i in chosen}
    if 'watchdog_timeout' in out:   # the four watchdogs as a set: no feedback one above the master's
        feedback = [out['watchdog_timeout']] + [float(rng.choice([0.002, 0.03, 0.5])) for _ in range(2)]
        out.update(actuator_watchdog_timeout=feedback[1], force_watchdog_timeout=feedback[2],
                   master_watchdog_timeout=max(max(feedback), float(rng.choice([0.03, 0.1, 1.0]))))
    return out


def test_tunables_are_not_read_only_and_limits_are():
    for name in ('force_kp', 'grip_force_max', 'watchdog_timeout', 'master_watchdog_timeout',
                 'actuator_watchdog_timeout', 'force_watchdog_timeout', 'object_kind'):
        assert not SPECS[name].read_only
    for name in ('max_current', 'max_current_slew', 'max_grip_force', 'control_rate'):
        assert SPECS[name].read_only


class Checker:
    def __init__(self, params):
        self.max_current = params.max_current
        self.clock = StepClock()
        self.previous = 0.0
        self.steps = 0
        self.retunes = 0
        self.modes = {'free': 0, 'grip': 0, 'safe': 0}

    def check(self, out, params, now):
        max_step = params.max_current_slew * self.clock.dt(now, params)
        force_max = min(params.grip_force_max, params.max_grip_force)
        for name in ('current_command', 'target_force', 'estimated_force', 'pull_out_force',
                     'target_jaw_angle', 'feedforward_current'):
            assert math.isfinite(getattr(out, name)), (name, out)
        c = out.current_command
        assert abs(c) <= self.max_current + 1e-12, out
        assert abs(c - self.previous) <= max_step * (1 + 1e-9) + 1e-15, (self.previous, out)
        assert 0.0 <= out.target_force <= force_max + 1e-12, (force_max, out)
        self.previous = c
        self.steps += 1
        self.modes[out.mode] += 1


def run_sequence(seed: int, n_steps: int) -> Checker:
    rng = np.random.default_rng(seed)
    limits = hardware(rng)
    params = make_params({**limits, **tunable(rng)})
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    check = Checker(params)
    garbage = float(rng.choice([0.0, 0.002, 0.05]))
    t = float(rng.uniform(0, 1e3))
    master = 0.6
    for _ in range(n_steps):
        if rng.random() < 0.004:   # an accepted runtime parameter set
            params = make_params({**dict(params), **tunable(rng)})
            ctrl.update_params(params)
            fresh = ctrl.new_inputs()
            for name in ('master_angle_min', 'master_angle_max', 'master_angle_tolerance',
                         'stamp_future_tolerance'):
                setattr(inputs, name, getattr(fresh, name))
            check.retunes += 1
        t += 1e-3 * float(rng.choice([1.0, 1.0, 0.0, 3.0, 40.0], p=[.8, .1, .04, .04, .02]))
        master = float(np.clip(master + 0.01 * rng.standard_normal(), -0.6, 1.8))
        jaw = max(0.0, min(1.5, master + 0.05 * rng.standard_normal()))

        def v(nominal, spread=0.0):
            if rng.random() < garbage:
                return GARBAGE[rng.integers(len(GARBAGE))]
            return float(nominal + spread * rng.standard_normal())
        if rng.random() < 0.97:
            inputs.set_master(t, v(master), stamp=t)
        if rng.random() < 0.97:
            inputs.set_instrument(t, v(0.1, 0.3), v(jaw), v(0.0, 1.0), stamp=t)
        if rng.random() < 0.97:
            inputs.set_actuator(t, v(ctrl.command, 0.02), v(0.0, 1.0), v(0.0, 1.0), stamp=t)
        if rng.random() < 0.95:
            inputs.set_force(t, v(3.0, 3.0), stamp=t)
        check.check(ctrl.step(t, inputs), params, t)
    return check


def test_properties_hold_across_runtime_retunes():
    """STEPS random steps over 40 seeded sequences, ~0.4 % of the periods retune."""
    n = STEPS // 40
    checks = [run_sequence(seed, n) for seed in range(40)]
    assert sum(c.steps for c in checks) == STEPS >= 100_000
    assert sum(c.retunes for c in checks) > 0.002 * STEPS
    for mode in ('free', 'grip', 'safe'):      # the properties are not vacuous
        assert sum(c.modes[mode] for c in checks) > 0.02 * STEPS, mode


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2**31 - 1), st.integers(1, 200)), min_size=1, max_size=8),
       st.integers(0, 2**31 - 1))
def test_hypothesis_retune_schedules(schedule, seed):
    """Retunes at hypothesis-chosen periods, in grip at full current (the worst case)."""
    rng = np.random.default_rng(seed)
    params = make_params({**hardware(rng), 'object_kind': 'needle',
                          'master_contact_angle': 0.2, 'grip_force_max': 150.0})
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    check = Checker(params)
    t = 10.0
    for tune_seed, periods in schedule:
        for _ in range(periods):
            t += 1e-3
            inputs.set_master(t, 0.0, stamp=t)                 # fully closed: largest target
            inputs.set_instrument(t, 0.0, 0.02, 0.0, stamp=t)  # blocked on the needle
            inputs.set_actuator(t, ctrl.command * 0.5, 0.0, 0.0, stamp=t)   # weak plant
            inputs.set_force(t, 0.1, stamp=t)
            check.check(ctrl.step(t, inputs), params, t)
        params = make_params({**dict(params), **tunable(np.random.default_rng(tune_seed))})
        ctrl.update_params(params)
    assert check.steps == sum(p for _, p in schedule)
