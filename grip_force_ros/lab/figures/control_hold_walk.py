"""Figure of the sensorless hold current walking inside the stick band (docs/control.md).

    .venv/bin/python -m grip_force_ros.lab.figures.control_hold_walk [OUT.png] [--seeds 1-20]

Runs :class:`GripController` on :class:`~grip_force_ros.sim.plant.InstrumentSim`
(config/paper_needle_driver.yaml, sensorless as shipped, the demo's needle grasp:
``needle_grasp(time_scale=2)``, 1 kHz) once per sim seed, and prints per seed where the
hold current ended inside the pulleys' stick band, how low the current went after the
target passed 3.5 N, how many feedforward branch switches there were, the sim's grip
force in the hold against its target, and how far the estimate froze from the sim's force
when the drum stopped loading. Writes the PNG (default
docs/figures/control_hold_walk.png): one seed's run (the first whose current dipped to the
band's lower edge) and the per-seed summary.

Nothing here is tuned: the controller, its YAML and the sim are the shipped ones; the
seeds are every seed in the range.
"""
from __future__ import annotations

import sys

import numpy as np

from grip_force_ros.lab.closed_loop import closed_loop_step
from grip_force_ros.control import GripController
from grip_force_ros.control.controller import HOLD_BAND
from grip_force_ros.params import load_params_file
from grip_force_ros.lab.plotting import pyplot, save
from grip_force_ros.sim.plant import InstrumentSim
from grip_force_ros.trajectories import needle_grasp

PERIOD = 1e-3               # s, the controller's period
TIME_SCALE = 2.0            # the demo's needle grasp (close 1.6 s, hold 3 s)
HOLD = (3.0, 5.6)           # s, the steady part of the hold (the demo's hold is 2.6-5.6 s)
BRANCH_CODE = {'loading': 0, 'middle': 1, 'unloading': 2}


def hold_run(params, seed: int) -> tuple[np.ndarray, dict]:
    """Run the closed loop of the demo's needle grasp to the end of the hold.

    Returns
    -------
    log : ndarray
        Columns: t (s), target, sim grip force, estimate (N), command, measured current
        (A), feedforward (A), branch (0 loading, 1 middle, 2 unloading), estimate on the
        loading edge (1/0); one row per period.
    edges : dict
        The band's currents (A) for the hold target, from the controller's own model:
        ``loading``, ``middle``, ``unloading``; and ``hold_band`` (N).
    """
    sim = InstrumentSim(params, obj='needle', seed=seed)
    ctrl = GripController(params)
    inputs, traj, rows = ctrl.new_inputs(), needle_grasp(time_scale=TIME_SCALE), []
    for k in range(int(round(HOLD[1] / PERIOD))):
        t = k * PERIOD
        m, out = closed_loop_step(sim, ctrl, inputs, t, traj.angle(t), PERIOD)
        rows.append((t, out.target_force, sim.truth()['grip_force'], out.estimated_force,
                     out.current_command, m.current, out.feedforward_current,
                     BRANCH_CODE[ctrl.branch], float(ctrl.hysteresis.on_loading_edge)))
    log = np.array(rows)
    target = float(log[-1, 1])
    jaw = float(inputs.jaw_angle)
    edges = {branch: ctrl.hysteresis.current_for_force(target, 0.0, jaw, 'needle', branch)
             for branch in BRANCH_CODE}
    edges['hold_band'] = HOLD_BAND * ctrl.force_max
    return log, edges


def summarize(log: np.ndarray, edges: dict) -> dict:
    """Per-run figures: hold and lowest current as fractions of the loading current, etc."""
    hold = log[(log[:, 0] >= HOLD[0]) & (log[:, 0] < HOLD[1])]
    late = log[log[:, 1] > 3.5]                                     # from 3.5 N on
    grip = log[log[:, 1] > 0.0]
    leaving = np.flatnonzero((late[:-1, 8] == 1.0) & (late[1:, 8] == 0.0))
    freeze = late[leaving[0] + 1] if len(leaving) else late[-1]     # first step off the edge
    return {
        'hold_current_fraction': float(np.median(hold[:, 4]) / edges['loading']),
        'lowest_current_fraction': float(late[:, 4].min() / edges['loading']),
        'branch_switches': int(np.count_nonzero(np.diff(grip[:, 7]) != 0)),
        'hold_force_error': float(hold[:, 2].mean() - hold[:, 1].mean()),          # N, sim - target
        'frozen_estimate_offset': float(freeze[3] - freeze[2]),                    # N, estimate - sim
        'hold_estimate_offset': float(hold[:, 3].mean() - hold[:, 2].mean()),      # N
    }


def _seeds(text: str) -> list[int]:
    first, _, last = text.partition('-')
    return list(range(int(first), int(last or first) + 1))


def main(argv: list[str] | None = None) -> int:
    """Run every seed, print the per-seed table and write the figure."""
    plt = pyplot()
    from grip_force_ros.params import instrument_path
    argv = list(sys.argv[1:] if argv is None else argv)
    seeds = _seeds(argv.pop(argv.index('--seeds') + 1)) if '--seeds' in argv else _seeds('1-20')
    argv = [a for a in argv if a != '--seeds']
    out = argv[0] if argv else 'docs/figures/control_hold_walk.png'
    params = load_params_file(instrument_path())
    rows, shown = [], None
    print('seed  hold/I_load  lowest/I_load  switches  hold error (N)  frozen offset (N)  '
          'hold estimate offset (N)')
    for seed in seeds:
        log, edges = hold_run(params, seed)
        s = summarize(log, edges)
        rows.append((seed, s))
        print(f"{seed:4d}  {s['hold_current_fraction']:11.2f}  {s['lowest_current_fraction']:13.2f}  "
              f"{s['branch_switches']:8d}  {s['hold_force_error']:+14.3f}  "
              f"{s['frozen_estimate_offset']:+17.3f}  {s['hold_estimate_offset']:+24.3f}")
        if shown is None and s['lowest_current_fraction'] < 0.5:
            shown = (seed, log, edges)
    lam2 = edges['unloading'] / edges['loading']
    lam = edges['middle'] / edges['loading']
    hold_fr = np.array([s['hold_current_fraction'] for _, s in rows])
    low_fr = np.array([s['lowest_current_fraction'] for _, s in rows])
    err = np.array([s['hold_force_error'] for _, s in rows])
    frozen = np.array([s['frozen_estimate_offset'] for _, s in rows])
    print(f'{len(rows)} seeds: band edges lambda = {lam:.2f}, lambda^2 = {lam2:.2f} of the loading '
          f"current {edges['loading']:.3f} A; HOLD_BAND {edges['hold_band'] * 1e3:.0f} mN")
    print(f'hold current / loading current: mean {hold_fr.mean():.2f}, range {hold_fr.min():.2f}-'
          f'{hold_fr.max():.2f}; runs whose current reached the lower edge (< {lam2 + 0.05:.2f}): '
          f'{int(np.sum(low_fr < lam2 + 0.05))} of {len(rows)}')
    print(f'sim hold force - target: mean {err.mean() * 1e3:+.0f} mN, '
          f'worst {np.abs(err).max() * 1e3:.0f} mN; '
          f'frozen estimate - sim: mean {frozen.mean() * 1e3:+.0f} mN, '
          f'beyond HOLD_BAND in {int(np.sum(np.abs(frozen) > edges["hold_band"]))} of {len(rows)}')

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    if shown is not None:
        seed, log, edges = shown
        w = log[log[:, 0] > 2.0]
        ax = axes[0, 0]
        ax.plot(w[:, 0], w[:, 1], 'k--', label='target')
        ax.plot(w[:, 0], w[:, 2], label='sim grip force (truth)')
        ax.plot(w[:, 0], w[:, 3], label='controller estimate')
        ax.fill_between(w[:, 0], w[:, 1] - edges['hold_band'], w[:, 1] + edges['hold_band'],
                        color='0.85', label='target +- HOLD_BAND')
        ax.set_ylim(3.5, 4.2)
        ax.set_ylabel('force (N)')
        ax.set_title(f'seed {seed}: the estimate froze above the truth')
        ax.legend(fontsize=8)
        ax = axes[1, 0]
        ax.plot(w[:, 0], w[:, 4], label='current command')
        for name, style in (('loading', ':'), ('middle', '-.'), ('unloading', '--')):
            ax.axhline(edges[name], color='k', ls=style, lw=0.8, label=f'{name} current for the target')
        ax.set_ylabel('current (A)')
        ax.set_xlabel('t (s)')
        ax.legend(fontsize=8)
    seeds_arr = np.array([seed for seed, _ in rows])
    ax = axes[0, 1]
    ax.plot(seeds_arr, hold_fr, 'o', label='hold current (median over the hold)')
    ax.plot(seeds_arr, low_fr, 'v', label='lowest current after 3.5 N')
    ax.axhline(1.0, color='k', ls=':', lw=0.8, label='loading edge (the paper inverse)')
    ax.axhline(lam, color='k', ls='-.', lw=0.8, label='lambda (middle)')
    ax.axhline(lam2, color='k', ls='--', lw=0.8, label='lambda^2 (unloading edge)')
    ax.set_ylabel('current / loading current')
    ax.set_title('where the hold current ends, per sim seed')
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    ax.plot(seeds_arr, frozen * 1e3, 'o', label='estimate - sim when the drum stopped loading')
    ax.plot(seeds_arr, err * 1e3, 's', label='sim hold force - target')
    ax.axhspan(-edges['hold_band'] * 1e3, edges['hold_band'] * 1e3, color='0.85', label='+- HOLD_BAND')
    ax.set_ylabel('mN')
    ax.set_xlabel('sim seed')
    ax.legend(fontsize=8)
    fig.suptitle('Sensorless hold of the demo grasp (paper_needle_driver, 4 N): the current walks '
                 'inside the stick band, the force does not')
    print(f'wrote {save(fig, out, dpi=80)}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
