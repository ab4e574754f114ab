"""Benchmark of the model's control-loop fast paths (prints figures; never a timed test).

Run: ``.venv/bin/python -m grip_force_ros.model.bench [config.yaml ...]``
"""
from __future__ import annotations

import sys
import timeit

import numpy as np

from grip_force_ros.model import GripForceModel, HystereticGripForce, hysteretic_grip_force
from grip_force_ros.params import instrument_path, load_params_file


def bench(path: str, number: int = 20000) -> dict:
    """Microseconds per call of the scalar paths and per sample of the vectorised forward."""
    model = GripForceModel(load_params_file(path))
    force = model.grip_force_scalar(0.3, 0.2, 0.1, 'rigid')
    out = {
        'grip_force_scalar_us': timeit.timeit(lambda: model.grip_force_scalar(0.3, 0.2, 0.1, 'rigid'),
                                              number=number) / number * 1e6,
        'current_for_force_scalar_us': timeit.timeit(
            lambda: model.current_for_force_scalar(force, 0.2, 0.1, 'rigid'), number=number // 10) / (number // 10) * 1e6,
    }
    stick = HystereticGripForce(model)
    swing = [0.3, 0.25, 0.1, 0.35] * (number // 4)          # loading, band, slip back, loading
    start = timeit.default_timer()
    update = stick.update
    for current in swing:
        update(current, 0.2, 0.1, 'rigid')
    out['hysteretic_update_us'] = (timeit.default_timer() - start) / len(swing) * 1e6
    out['current_for_force_unloading_us'] = timeit.timeit(
        lambda: stick.current_for_force(0.5 * force, 0.2, 0.1, 'rigid', 'unloading'),
        number=number // 10) / (number // 10) * 1e6
    history = 0.25 + 0.2 * np.sin(np.linspace(0, 60, 100_000))
    out['hysteretic_history_per_sample_us'] = timeit.timeit(
        lambda: hysteretic_grip_force(model, history, 0.2, 0.1, 'rigid'), number=3) / 3 / history.size * 1e6
    currents = np.linspace(0, 0.5, 100_000)
    out['forward_per_sample_us'] = timeit.timeit(lambda: model.forward(currents, 0.2, 0.1, 'rigid'),
                                                 number=3) / 3 / currents.size * 1e6
    return out


def main(argv: list[str] | None = None) -> int:
    paths = (argv if argv is not None else sys.argv[1:]) or [
        str(instrument_path()), str(instrument_path('four_pulley_needle_driver'))]
    for path in paths:
        figures = bench(path)
        print(path + ': ' + ', '.join(f'{k} = {v:.3g}' for k, v in figures.items()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
