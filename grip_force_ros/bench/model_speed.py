"""Speed of the model and of the control step (numpy only, no rclpy).

* vectorised :meth:`GripForceModel.forward` and :meth:`~GripForceModel.inverse`
  over arrays of ``size`` samples, as a ratio to one ``numpy.exp`` over an array
  of the same size (goal: forward <= 10x);
* :meth:`GripController.step` in grip mode, model calls included (the force
  estimate and the feedforward inverse), as a share of the control period
  (goal <= 5 %); the input setters the node's callbacks call are timed beside it.

Timings are the best of ``repeats`` (the least disturbed by other load).
"""
from __future__ import annotations

import time

import numpy as np

from grip_force_ros.control import GripController
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import load_params_file


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
