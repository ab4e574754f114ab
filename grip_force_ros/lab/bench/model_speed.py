"""Speed of the model (numpy only, no rclpy).

* :func:`vectorised_ratios`: :meth:`GripForceModel.forward` and
  :meth:`~GripForceModel.inverse` over arrays of ``size`` samples, as a ratio to
  one ``numpy.exp`` over an array of the same size (goal: forward <= 10x); with
  the control step's share of the period (:mod:`.control_step`) it makes the
  ``model`` section of ``grip-force bench`` (:func:`run_model`);
* :func:`scalar_paths`: microseconds per call of the control loop's scalar fast
  paths, the stick band's update and inverse, and per sample of the hysteretic
  history and the vectorised forward. Printed by
  ``python -m grip_force_ros.lab.bench.model_speed [config.yaml ...]``.

Timings are the best of ``repeats`` (the least disturbed by other load).
"""
from __future__ import annotations

import sys
import time
import timeit

import numpy as np

from grip_force_ros.lab.bench.control_step import step_share
from grip_force_ros.model import GripForceModel, HystereticGripForce, hysteretic_grip_force
from grip_force_ros.params import instrument_path, load_params_file


def best_time(fn, repeats: int = 5, number: int = 1) -> float:
    """Best wall time of ``number`` calls of ``fn`` over ``repeats`` tries, per call (s)."""
    best = float('inf')
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def operating_arrays(model: GripForceModel, size: int, seed: int = 0) -> dict:
    """Random operating points in range: current (A), wrist (rad), jaw (rad), forces (N)."""
    rng = np.random.default_rng(seed)
    current = rng.uniform(0.05, 0.4, size)                       # A
    wrist = rng.uniform(-0.6, 0.6, size)                         # rad
    jaw = rng.uniform(0.0, 0.02, size)                           # rad, on the needle
    force = model.forward(current, wrist, jaw, 'needle').grip_force   # N, reachable by construction
    return {'current': current, 'wrist': wrist, 'jaw': jaw, 'force': force}


def vectorised_ratios(params, size: int = 100_000, repeats: int = 5, inverse_size: int | None = None) -> dict:
    """Forward and inverse time over ``size`` samples as ratios to one ``numpy.exp``.

    Parameters
    ----------
    params : ParamSet
        Instrument parameters.
    size : int
        Samples per array.
    repeats : int
        Timing tries; the best one counts.
    inverse_size : int, optional
        Samples for the inverse when it solves per sample (tension-dependent friction
        with a wrist-dependent wrap: vectorised Newton, slow); the ratio is scaled to
        the same per-sample basis. Other inverses run on all ``size`` samples.

    Returns
    -------
    dict
        ``forward_ratio``, ``inverse_ratio`` (-), ``exp_ns_per_sample``,
        ``forward_ns_per_sample``, ``inverse_ns_per_sample`` (ns), ``affine`` (bool:
        closed-form inverse), ``fitted`` (bool: the nonlinear maps come from fitted
        tables), ``setup_ms`` (construction and the first vectorised forward and
        inverse, which build the tables; not in the ratios), ``size``.
    """
    t0 = time.perf_counter()
    model = GripForceModel(params)
    a = operating_arrays(model, 8)                              # first forward
    model.inverse(a['force'], a['wrist'], a['jaw'], 'needle')   # first inverse
    setup = time.perf_counter() - t0                            # with the tables built on the way
    a = operating_arrays(model, size)
    x = a['current'] * 3.0
    t_exp = best_time(lambda: np.exp(x), repeats)
    t_fwd = best_time(lambda: model.forward(a['current'], a['wrist'], a['jaw'], 'needle'), repeats)
    per_sample = not model.affine and not model._one_dimensional    # vectorised Newton
    n_inv = min(size, inverse_size) if per_sample and inverse_size is not None else size
    f, w, j = a['force'][:n_inv], a['wrist'][:n_inv], a['jaw'][:n_inv]
    t_inv = best_time(lambda: model.inverse(f, w, j, 'needle'), repeats if n_inv == size else 1)
    back = model.forward(model.inverse(f[:1000], w[:1000], j[:1000], 'needle'), w[:1000], j[:1000],
                         'needle').grip_force
    per = 1e9 / size
    return {'size': size, 'affine': bool(model.affine), 'fitted': bool(model._one_dimensional),
            'setup_ms': setup * 1e3,
            'exp_ns_per_sample': t_exp * per,
            'forward_ns_per_sample': t_fwd * per,
            'inverse_ns_per_sample': t_inv * 1e9 / n_inv,
            'forward_ratio': t_fwd / t_exp,
            'inverse_ratio': (t_inv * size / n_inv) / t_exp,
            'inverse_round_trip_error_N': float(np.max(np.abs(back - f[:1000])))}


def run_model(config: str, size: int = 100_000, steps: int = 20_000, repeats: int = 5,
              other_configs: tuple = ()) -> dict:
    """Measure the ``model`` section of the bench for ``config`` (YAML path), plus others' ratios."""
    params = load_params_file(config)
    out = vectorised_ratios(params, size, repeats, inverse_size=2_000)
    out.update(step_share(params, steps, max(1, repeats // 2)))
    out['config'] = config
    out['goals'] = {'forward_ratio': 10.0, 'step_share': 0.05}
    if other_configs:
        out['other_configs'] = {}
        for path in other_configs:
            r = vectorised_ratios(load_params_file(path), size // 10, repeats, inverse_size=500)
            out['other_configs'][path] = {k: r[k] for k in ('forward_ratio', 'inverse_ratio', 'affine',
                                                            'fitted', 'setup_ms')}
    return out


def scalar_paths(path: str, number: int = 20000) -> dict:
    """Microseconds per call of the scalar paths and per sample of the vectorised forward.

    Parameters
    ----------
    path : str
        Instrument YAML.
    number : int
        Calls of the fastest path (the slower ones get a tenth).

    Returns
    -------
    dict
        ``grip_force_scalar_us``, ``current_for_force_scalar_us``,
        ``hysteretic_update_us``, ``current_for_force_unloading_us`` (us per call),
        ``hysteretic_history_per_sample_us``, ``forward_per_sample_us`` (us per sample).
    """
    model = GripForceModel(load_params_file(path))
    force = model.grip_force_scalar(0.3, 0.2, 0.1, 'rigid')
    out = {
        'grip_force_scalar_us': timeit.timeit(lambda: model.grip_force_scalar(0.3, 0.2, 0.1, 'rigid'),
                                              number=number) / number * 1e6,
        'current_for_force_scalar_us': timeit.timeit(
            lambda: model.current_for_force_scalar(force, 0.2, 0.1, 'rigid'),
            number=number // 10) / (number // 10) * 1e6,
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
    """Print :func:`scalar_paths` for each config (default: the paper and the four-pulley one)."""
    paths = (argv if argv is not None else sys.argv[1:]) or [
        str(instrument_path()), str(instrument_path('four_pulley_needle_driver'))]
    for path in paths:
        figures = scalar_paths(path)
        print(path + ': ' + ', '.join(f'{k} = {v:.3g}' for k, v in figures.items()))
    return 0


if __name__ == '__main__':
    sys.exit(main())
