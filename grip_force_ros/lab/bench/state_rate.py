"""Rate independence: the needle grasp with the controller stepping at 100 .. 1500 Hz states.

ROS-free (:func:`offline_grasp`): the real :class:`~grip_force_ros.control.GripController`
steps once per instrument state of the simulated instrument
(:class:`~grip_force_ros.sim.InstrumentSim`, integrated at its own ``sim_rate`` between
states with the last command held), on the time measured between states. Seeded noise: the
sim's sensor noise (``sim_seed``) and a jitter of the state times (each interval uniform
within +-``jitter`` of the period, numpy ``default_rng(seed)``). The master runs the needle
grasp; the hold error, overshoot and settling are those of the demo
(:func:`grip_force_ros.lab.demo.analysis.force_metrics`: the load cell against the target).

``python -m grip_force_ros.lab.bench.state_rate [--config YAML] [--rates ...] [--seeds N]
[--outside]`` prints the table of docs/control.md ("Rate independence"); ``--outside`` adds
rates outside the designed range (the controller then runs with ``expected_state_rate`` at
the nearest end of its range, as the node would refuse to start). One real-node run per
rate confirms it: ``grip_force_ros.lab.bench.state_rate_nodes``.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from grip_force_ros.lab.closed_loop import closed_loop_step
from grip_force_ros.control import GripController, Mode
from grip_force_ros.lab.demo import analysis
from grip_force_ros.params import load_params_file
from grip_force_ros.params.controller import STATE_RATE_MAX, STATE_RATE_MIN
from grip_force_ros.params.files import instrument_path
from grip_force_ros.sim import InstrumentSim
from grip_force_ros.trajectories import make_trajectory

#: The state rates of the table (Hz): the dVRK's ROS rate to its arm loop's rate.
RATES = (100.0, 250.0, 500.0, 1000.0, 1500.0)
#: Rates outside the designed range shown by ``--outside`` (Hz).
OUTSIDE_RATES = (50.0, 3000.0)
#: Jitter of the state intervals (share of the period, uniform +-).
JITTER = 0.1
#: Time scale of the needle grasp (1: the scripted task, 5 s).
TIME_SCALE = 1.0


def offline_grasp(params, rate: float, seed: int = 0, jitter: float = JITTER,
                  time_scale: float = TIME_SCALE) -> dict:
    """Run the needle grasp with states at ``rate`` Hz; return the series and the figures.

    Parameters
    ----------
    params : ParamSet
        Instrument, controller and sim parameters (``expected_state_rate`` is set to
        ``rate`` clipped to the designed range).
    rate : float
        State rate (Hz): the controller steps once per state.
    seed : int
        Seed of the sim's sensor noise and of the state-time jitter.
    jitter : float
        Each state interval is ``(1 + u) / rate``, ``u`` uniform in ``[-jitter, jitter]``.
    time_scale : float
        Duration multiplier of the needle grasp.

    Returns
    -------
    dict
        ``metrics`` (:func:`~grip_force_ros.lab.demo.analysis.force_metrics` plus
        ``overshoot``: the peak load-cell force over the hold and pull phases above the
        steady target, as a share of it), ``safe_steps``, ``steps`` and ``series``
        (the arrays per state).
    """
    expected = min(max(rate, STATE_RATE_MIN), STATE_RATE_MAX)
    p = params.replace(expected_state_rate=expected, sim_seed=seed)
    traj = make_trajectory('needle_grasp', '', master_open_angle=0.8, master_closed_angle=0.0,
                           time_scale=time_scale)
    sim = InstrumentSim(p, obj='needle', seed=seed)
    ctrl = GripController(p)
    inputs = ctrl.new_inputs()
    rng = np.random.default_rng(seed)
    n = int(math.ceil((traj.duration + 0.2) * rate))
    intervals = (1.0 + rng.uniform(-jitter, jitter, n)) / rate
    rows = []
    t = 0.0
    safe = 0
    for k in range(n):
        master = float(traj.angle(t))
        m, out = closed_loop_step(sim, ctrl, inputs, t, master, float(intervals[k]), stamped=True)
        safe += out.mode is Mode.SAFE
        rows.append((t, master, out.target_force, m.grip_force, out.estimated_force,
                     out.current_command, m.jaw_angle, out.target_jaw_angle,
                     out.mode is Mode.FREE))
        t += float(intervals[k])
    a = np.array(rows)
    series = {'t': a[:, 0], 'master_angle': a[:, 1], 'target_force': a[:, 2],
              'measured_force': a[:, 3], 'estimated_force': a[:, 4], 'current_command': a[:, 5],
              'jaw_angle': a[:, 6], 'target_jaw_angle': a[:, 7]}
    windows = analysis.phase_windows(traj, 0.0)
    metrics = analysis.force_metrics(series, windows)
    loaded = (series['t'] >= windows['hold'][0]) & (series['t'] <= windows['pull'][1])
    metrics['overshoot'] = float(np.max(series['measured_force'][loaded]) / metrics['target_force']
                                 - 1.0)
    # free motion while the master closes: how well the jaw follows its target (rad)
    closing = (a[:, 8] > 0.5) & (series['t'] >= windows['close'][0]) & \
        (series['t'] <= windows['close'][1])
    jaw_error = series['jaw_angle'][closing] - series['target_jaw_angle'][closing]
    metrics['jaw_rms_free'] = float(np.sqrt(np.mean(jaw_error ** 2))) if jaw_error.size else math.nan
    return {'metrics': metrics, 'safe_steps': safe, 'steps': n, 'series': series,
            'expected_state_rate': expected}


def rate_table(params, rates=RATES, seeds: int = 3, **kwargs) -> list[dict]:
    """One row per rate: the figures as mean and worst over ``seeds`` seeded runs."""
    out = []
    for rate in rates:
        runs = [offline_grasp(params, rate, seed=s, **kwargs) for s in range(seeds)]
        m = [r['metrics'] for r in runs]

        def worst(key, m=m):
            return max(abs(x[key]) for x in m)
        out.append({'rate_hz': rate, 'expected_state_rate': runs[0]['expected_state_rate'],
                    'hold_error_rel_mean': float(np.mean([x['hold_error_rel'] for x in m])),
                    'hold_error_rel_worst': worst('hold_error_rel'),
                    'hold_error_rms_n': float(np.mean([x['hold_error_rms'] for x in m])),
                    'overshoot_mean': float(np.mean([x['overshoot'] for x in m])),
                    'overshoot_worst': max(x['overshoot'] for x in m),
                    'settling_s_mean': float(np.mean([x['settling_time'] for x in m])),
                    # nan: a seed never within 5 % for good during the hold (max() would skip it)
                    'settling_s_worst': float(np.max([x['settling_time'] for x in m])),
                    'jaw_rms_free_rad': float(np.mean([x['jaw_rms_free'] for x in m])),
                    'safe_steps': sum(r['safe_steps'] for r in runs), 'seeds': seeds})
    return out


def _ms(seconds: float) -> str:
    """Format a settling time (s) in ms, or 'never' (nan: not within 5 % for good during the hold)."""
    return 'never' if math.isnan(seconds) else f'{1e3 * seconds:.0f} ms'


def format_table(rows: list[dict]) -> str:
    """Markdown table of :func:`rate_table` (docs/control.md)."""
    lines = ['| state rate | hold error (mean of seeds, worst) | hold rms | overshoot (mean, worst) '
             '| settling to 5 % (mean, worst) | jaw rms, free | safe steps |',
             '|---|---|---|---|---|---|---|']
    for r in rows:
        note = '' if r['rate_hz'] == r['expected_state_rate'] else \
            f" (expected_state_rate {r['expected_state_rate']:g})"
        lines.append(
            f"| {r['rate_hz']:g} Hz{note} | {100 * r['hold_error_rel_mean']:+.2f} %, "
            f"{100 * r['hold_error_rel_worst']:.2f} % | {1e3 * r['hold_error_rms_n']:.1f} mN | "
            f"{100 * r['overshoot_mean']:.1f} %, {100 * r['overshoot_worst']:.1f} % | "
            f"{_ms(r['settling_s_mean'])}, {_ms(r['settling_s_worst'])} | "
            f"{1e3 * r['jaw_rms_free_rad']:.0f} mrad | {r['safe_steps']} |")
    return '\n'.join(lines)


def main(argv=None) -> int:
    """Print the rate table (``python -m grip_force_ros.lab.bench.state_rate``)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--config', default=None, help='instrument YAML (default: the paper)')
    parser.add_argument('--rates', type=float, nargs='+', default=list(RATES))
    parser.add_argument('--seeds', type=int, default=3)
    parser.add_argument('--outside', action='store_true',
                        help=f'also the rates {OUTSIDE_RATES} Hz outside the designed range')
    args = parser.parse_args(argv)
    config = instrument_path(args.config)
    params = load_params_file(config)
    rates = list(args.rates) + (list(OUTSIDE_RATES) if args.outside else [])
    print(f'{params.instrument_name} ({config}), needle grasp, sensorless, {args.seeds} seeds, '
          f'state jitter +-{100 * JITTER:g} %')
    print(format_table(rate_table(params, rates, seeds=args.seeds)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
