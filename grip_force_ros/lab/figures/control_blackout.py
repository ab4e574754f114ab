"""Figure of the stick-band fix (docs/control.md): a watchdog trip in a sensorless grip, before and after.

    .venv/bin/python -m grip_force_ros.lab.figures.control_blackout [OUT.png]

Runs :class:`GripController` on :class:`~grip_force_ros.sim.plant.InstrumentSim`
(config/paper_needle_driver.yaml, needle_grasp, a 50 ms blackout of every input at
t = 1.5 s) twice: as it was (loading-branch estimate and feedforward, no force ramp on
resume: ``resume_ramp_time=0``) and as it is. Prints the hold force over 2.3-2.8 s;
writes the PNG (default docs/figures/control_blackout_stick_band.png).
"""
from __future__ import annotations

import sys

import numpy as np

from grip_force_ros.lab.closed_loop import NO_FORCE_SENSOR, NO_SOURCES, closed_loop_step
from grip_force_ros.control import GripController
from grip_force_ros.model import GripForceModel
from grip_force_ros.params import load_params_file
from grip_force_ros.lab.plotting import pyplot, save
from grip_force_ros.sim.plant import InstrumentSim
from grip_force_ros.trajectories import needle_grasp

BLACKOUT = (1.5, 0.05)      # s: start, length
SECONDS = 2.8               # s


class _LoadingBranchOnly:
    """The model's loading branch alone (what the controller used before the stick band).

    It offers the two scalar paths, not :attr:`GripForceModel.supports_stick_band`, so
    the controller uses it as the loading branch only.
    """

    def __init__(self, model):
        self.grip_force_scalar = model.grip_force_scalar
        self.current_for_force_scalar = model.current_for_force_scalar


def blackout_run(params, stick_band: bool, seed: int = 3) -> np.ndarray:
    """Run the closed loop with the blackout, as it is (``stick_band``) or as it was.

    As it was: the model's loading branch only and no force ramp on resume.

    Returns
    -------
    ndarray
        Columns: t (s), target, sim grip force, estimate (N), command, actual current
        (A), drum tension, jaw-side tension (N), efficiency (-); one row per 1 ms.
    """
    model = GripForceModel(params)
    if stick_band:
        ctrl = GripController(params, model)
    else:
        ctrl = GripController(params, _LoadingBranchOnly(model), resume_ramp_time=0.0)
    sim = InstrumentSim(params, obj='needle', seed=seed)
    inputs, traj, rows = ctrl.new_inputs(), needle_grasp(), []
    for k in range(int(round(SECONDS / 1e-3))):
        t = k * 1e-3
        dark = BLACKOUT[0] <= t < BLACKOUT[0] + BLACKOUT[1]
        _, out = closed_loop_step(sim, ctrl, inputs, t, traj.angle(t), 1e-3,
                                  sources=NO_SOURCES if dark else NO_FORCE_SENSOR)
        tr = sim.truth()
        rows.append((t, out.target_force, tr['grip_force'], out.estimated_force, out.current_command,
                     tr['current'], tr['drum_tension'], tr['jaw_tension'], tr['efficiency']))
    return np.array(rows)


def main(argv: list[str] | None = None) -> int:
    """Run both loops, print their hold forces and write the figure (argument: output PNG)."""
    plt = pyplot()
    from grip_force_ros.params import instrument_path
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv else 'docs/figures/control_blackout_stick_band.png'
    params = load_params_file(instrument_path())
    before = blackout_run(params, stick_band=False)
    after = blackout_run(params, stick_band=True)
    fig, axes = plt.subplots(3, 2, figsize=(12, 9), sharex=True)
    for col, (title, log) in enumerate((('before: loading-branch estimate', before),
                                        ('after: stick-band estimate + force ramp on resume', after))):
        hold = log[(log[:, 0] > 2.3) & (log[:, 0] < 2.8)]
        print(f'{title}: hold {hold[:, 2].mean():.3f} N (sim), estimate {hold[:, 3].mean():.3f} N, '
              f'target {hold[:, 1].mean():.3f} N')
        w = log[(log[:, 0] > 1.4)]
        ax = axes[0, col]
        ax.plot(w[:, 0], w[:, 1], 'k--', label='target')
        ax.plot(w[:, 0], w[:, 2], label='sim grip force (truth)')
        ax.plot(w[:, 0], w[:, 3], label='controller estimate')
        ax.set_ylabel('force (N)')
        ax.set_title(f'{title}\nhold {hold[:, 2].mean():.2f} N for {hold[:, 1].mean():.2f} N')
        ax.legend(fontsize=8)
        ax = axes[1, col]
        ax.plot(w[:, 0], w[:, 4], label='command')
        ax.plot(w[:, 0], w[:, 5], label='actual current')
        ax.set_ylabel('current (A)')
        ax.legend(fontsize=8)
        ax = axes[2, col]
        ax.plot(w[:, 0], w[:, 7], label='jaw-side tension Tn')
        ax.plot(w[:, 0], w[:, 8] * w[:, 6], ':', label='lambda T0 (loading edge)')
        ax.plot(w[:, 0], w[:, 6] / w[:, 8], ':', label='T0 / lambda (unloading edge)')
        ax.set_ylabel('tension (N)')
        ax.set_xlabel('t (s)')
        ax.legend(fontsize=8)
    fig.suptitle('Sensorless grip, 50 ms blackout of every input at t = 1.5 s '
                 '(paper_needle_driver, needle_grasp, sim seed 3)')
    print(f'wrote {save(fig, out, dpi=80)}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
