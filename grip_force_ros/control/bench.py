"""Benchmark of the controller step (prints figures; not a test).

    .venv/bin/python -m grip_force_ros.control.bench [--steps N] [--config YAML]

Times ``GripController.step`` alone and the full period of a node (four ``set_*`` calls
+ ``step``), in grip (model feedforward and estimate) and in free motion; prints the
median over repeats of the mean time per step (us).
"""
from __future__ import annotations

import argparse
import statistics
import time


def _bench(ctrl, inputs, steps: int, master: float, jaw: float, with_setters: bool) -> float:
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


def main(argv=None) -> int:
    from grip_force_ros.control import GripController
    from grip_force_ros.params import load_params_file, make_params
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
