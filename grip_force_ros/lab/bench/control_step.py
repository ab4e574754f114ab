"""Speed of the control step: :meth:`GripController.step` against the 1 ms period (no rclpy).

* :func:`step_share`: one step in grip mode, model calls included (the force
  estimate and the feedforward inverse), as a share of the control period (goal
  <= 5 %), the input setters the node's callbacks call timed beside it; the
  ``model`` section of ``grip-force bench`` carries it;
* ``python -m grip_force_ros.lab.bench.control_step [--steps N] [--repeats N] [--config YAML]``
  prints the step alone and the full period of a node (three ``set_*`` calls +
  ``step``), in grip (model feedforward and estimate) and in free motion, as the
  median over repeats of the mean time per step (us), then the distribution of
  single periods (p50, p99, max).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from grip_force_ros.control import GripController
from grip_force_ros.params import load_params_file, make_params


def step_share(params, steps: int = 20_000, repeats: int = 3) -> dict:
    """Time of one :meth:`GripController.step` in grip mode, as a share of the period.

    The controller runs on inputs like a grasp's hold phase: master closed past
    contact, jaw on the needle, measured current near the hold current, each
    sample a little different and newer (so no check short-cuts it).

    Returns
    -------
    dict
        ``step_us`` and ``inputs_us`` (best mean per period, us), ``step_share``
        and ``step_and_inputs_share`` (of the period, -), ``period_ms``, ``mode``
        (of the last step: must be 'grip'), ``feedforward`` (bool: the inverse ran).
    """
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    period = ctrl.period
    rng = np.random.default_rng(1)
    n = steps
    master = params.master_angle_min + 0.05 * (params.master_angle_max - params.master_angle_min) \
        + rng.normal(0.0, 1e-4, n)                                 # rad, closed: grip
    jaw = 0.004 + rng.normal(0.0, 1e-5, n)                          # rad, on the needle
    wrist = 0.2 + rng.normal(0.0, 1e-4, n)                          # rad
    current = 0.25 + rng.normal(0.0, 1e-3, n)                       # A
    motor = 1.0 + rng.normal(0.0, 1e-4, n)                          # rad
    master, jaw, wrist, current, motor = (v.tolist() for v in (master, jaw, wrist, current, motor))
    clock = [1000.0]                                                # s, controller clock

    def feed(k: int) -> float:
        now = clock[0] = clock[0] + period
        inputs.set_master(now, master[k], now)
        inputs.set_instrument(now, wrist[k], jaw[k], 0.0, now)
        inputs.set_actuator(now, current[k], motor[k], 0.0, now)
        return now

    # warm up into grip (bumpless transfer, force map state)
    out = None
    for k in range(2000):
        out = ctrl.step(feed(k % n), inputs)
    step = ctrl.step
    best_step = best_inputs = float('inf')
    for _ in range(repeats):
        t_in = t_step = 0.0
        for k in range(n):
            t0 = time.perf_counter()
            now = feed(k)
            t1 = time.perf_counter()
            out = step(now, inputs)
            t2 = time.perf_counter()
            t_in += t1 - t0
            t_step += t2 - t1
        best_step = min(best_step, t_step / n)
        best_inputs = min(best_inputs, t_in / n)
    return {'period_ms': period * 1e3, 'step_us': best_step * 1e6, 'inputs_us': best_inputs * 1e6,
            'step_share': best_step / period, 'step_and_inputs_share': (best_step + best_inputs) / period,
            'mode': out.mode, 'feedforward': bool(out.feedforward_current > 0.0),
            'target_force_N': out.target_force, 'reasons': list(out.reasons)}


def _bench(ctrl, inputs, steps: int, master: float, jaw: float, with_setters: bool) -> float:
    """Mean wall time of one period over ``steps`` periods (us): ``step`` alone, or with the setters."""
    t0 = ctrl.last_now if ctrl.last_now > 0 else 0.0
    step, set_m, set_i, set_a = ctrl.step, inputs.set_master, inputs.set_instrument, inputs.set_actuator
    start = time.perf_counter()
    if with_setters:
        for k in range(steps):
            now = t0 + (k + 1) * 1e-3
            set_m(now, master)
            set_i(now, 0.1, jaw, 0.0)
            set_a(now, ctrl.command, 0.0, 0.0)
            step(now, inputs)
    else:
        for k in range(steps):
            now = t0 + (k + 1) * 1e-3
            inputs.master_time = inputs.instrument_time = inputs.actuator_time = now
            step(now, inputs)
    return (time.perf_counter() - start) / steps * 1e6


def main(argv: list[str] | None = None) -> int:
    """Print the step timings (us per period) of ``--config`` (default: the schema defaults)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--steps', type=int, default=20000)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--config', help='instrument YAML (default: schema defaults)')
    args = parser.parse_args(argv)
    params = load_params_file(args.config) if args.config else make_params({})
    for label, master, jaw in (('grip (needle, feedforward + model estimate)', 0.05, 0.04),
                               ('free motion (jaw-angle PID)', 0.8, 0.8)):
        for with_setters in (False, True):
            ctrl = GripController(params)
            inputs = ctrl.new_inputs()
            _bench(ctrl, inputs, 500, master, jaw, True)               # warm up, leave safe
            runs = [_bench(ctrl, inputs, args.steps, master, jaw, with_setters)
                    for _ in range(args.repeats)]
            what = 'set_* x3 + step' if with_setters else 'step only     '
            print(f'{label:<45} {what}: median {statistics.median(runs):6.2f} us/step, '
                  f'max {max(runs):6.2f} us ({args.repeats} x {args.steps} steps)')
    # distribution of single periods (node view: set_* x3 + step), grip mode
    ctrl = GripController(params)
    inputs = ctrl.new_inputs()
    _bench(ctrl, inputs, 500, 0.05, 0.04, True)
    clock = time.perf_counter_ns
    samples = [0] * args.steps
    for k in range(args.steps):
        now = 1.0 + k * 1e-3
        start = clock()
        inputs.set_master(now, 0.05)
        inputs.set_instrument(now, 0.1, 0.04, 0.0)
        inputs.set_actuator(now, ctrl.command, 0.0, 0.0)
        ctrl.step(now, inputs)
        samples[k] = clock() - start
    samples.sort()
    n = len(samples)
    print(f'single periods, grip, set_* x3 + step: p50 {samples[n // 2] / 1e3:.2f} us, '
          f'p99 {samples[int(n * 0.99)] / 1e3:.2f} us, max {samples[-1] / 1e3:.2f} us ({n} periods)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
