"""Figures and numbers of docs/sim.md: step response, loops of every effect.

Run: ``.venv/bin/python -m grip_force_ros.lab.figures.sim_response --out docs/figures``
(prints the step-response metrics; writes ``sim_step_response.png`` and
``sim_effects.png``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from grip_force_ros.model import GripForceModel
from grip_force_ros.params import make_params
from grip_force_ros.lab.plotting import pyplot, save
from grip_force_ros.sim.offline import simulate
from grip_force_ros.sim.plant import InstrumentSim
from grip_force_ros.sim.step_response import metrics_of_signal

QUIET = {name: 0.0 for name in ('current_noise_std', 'motor_angle_noise_std', 'motor_velocity_noise_std',
                                'wrist_angle_noise_std', 'jaw_angle_noise_std', 'jaw_velocity_noise_std',
                                'grip_force_noise_std')}
#: Strengths used in the effects figure (medium, in each effect's unit).
SHOWN = {'pivot_coulomb_friction': 0.005, 'viscous_friction': 0.01, 'cable_hysteresis': 0.1,
         'backlash': 0.05, 'tension_dependent_friction': 4e-4, 'viscoelastic_creep': 0.2,
         'sensor_delay': 0.02, 'torque_constant_drift': 0.2, 'force_sensor_offset': 0.3}


def step_record(current=0.35, obj='needle', pre=0.05, duration=0.2, dt=1e-4):
    """Noise-free step 0 -> ``current`` (A) at ``pre`` (s) with the jaw resting on ``obj``."""
    p = make_params(QUIET)
    contact = {'needle': p.needle_contact_angle, 'rigid': p.rigid_contact_angle,
               'tissue': p.tissue_contact_angle}[obj]
    sim = InstrumentSim(p.replace(initial_jaw_angle=contact), obj=obj)
    rows = []
    for _ in range(int(round((pre + duration) / dt))):
        sim.step(0.0 if sim.t < pre - 1e-12 else current, dt)
        tr = sim.truth()
        rows.append((tr['t'], tr['grip_force'], tr['drum_tension'], tr['jaw_tension'], tr['jaw_angle'],
                     tr['current'], tr['efficiency']))
    return p, np.array(rows)


def step_figure(out: Path, current=0.35) -> dict:
    """Write the step-response figure; return the metrics per object."""
    plt = pyplot()

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    numbers = {}
    for obj, colour in (('needle', 'C0'), ('rigid', 'C1'), ('tissue', 'C2')):
        p, rec = step_record(current, obj)
        t = rec[:, 0] - 0.05
        m = metrics_of_signal(rec[:, 0], rec[:, 1], t_step=0.05)
        static = float(GripForceModel(p).forward(current, 0.0, rec[-1, 4], obj).grip_force)
        numbers[obj] = (m, static)
        axes[0].plot(t * 1e3, rec[:, 1], colour, label=f'{obj}: sim')
        axes[0].axhline(static, color=colour, ls='--', lw=0.8, label=f'{obj}: model (quasi-static)')
        if obj == 'needle':
            axes[1].plot(t * 1e3, rec[:, 2], 'k', label='drum-side tension T0')
            axes[1].plot(t * 1e3, rec[:, 3], 'C3', label='jaw-side tension Tn')
            axes[1].plot(t * 1e3, rec[:, 6] * rec[:, 2], 'C3', ls=':', lw=0.8,
                         label='lambda * T0 (slipping, loading)')
        axes[2].plot(t * 1e3, rec[:, 4], colour, label=obj)
    axes[0].set(xlabel='time after the step (ms)', ylabel='grip force (N)',
                title=f'load cell, current step 0 -> {current} A')
    axes[1].set(xlabel='time after the step (ms)', ylabel='cable tension (N)', title='needle: cable tensions')
    axes[2].set(xlabel='time after the step (ms)', ylabel='jaw angle (rad)', title='jaw angle')
    for ax in axes:
        ax.axvline(100, color='grey', lw=0.6)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    save(fig, out / 'sim_step_response.png', dpi=80)
    return numbers


def effects_figure(out: Path) -> None:
    """Write grip force vs current loops (needle, slow sine) for no effect and each effect."""
    plt = pyplot()

    p = make_params(QUIET)
    model = GripForceModel(p)
    t = np.arange(7000) * 1e-3
    current = 0.25 + 0.15 * np.sin(2 * np.pi * 0.5 * t)
    current[:500] = np.linspace(0.0, 0.25, 500)
    keep = t > 2.5                      # after the first closing transient: steady loops
    fig, axes = plt.subplots(2, 5, figsize=(20, 7.5), sharex=True)
    for ax, (name, strength) in zip(axes.flat, [('none', None), *SHOWN.items()]):
        log = simulate(p, current, 1e-3, obj='needle', effects=None if strength is None else {name: strength})
        ax.plot(log['current'][keep], log['grip_force'][keep], lw=0.8, label='sim (load cell)')
        ax.plot(log['current'][keep],
                model.forward(log['current'][keep], 0.0, log['jaw_angle'][keep]).grip_force,
                'k--', lw=0.8, label='model forward')
        ax.set_title(name if strength is None else f'{name} = {strength:g}', fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel('measured current (A)')
    for ax in axes[:, 0]:
        ax.set_ylabel('grip force (N)')
    axes[0, 0].legend(fontsize=8)
    fig.suptitle('needle, current 0.25 + 0.15 sin(2 pi 0.5 t) A, 6 s: grip force vs current per effect')
    save(fig, out / 'sim_effects.png', dpi=70)


def main(argv: list[str] | None = None) -> int:
    """Write both figures into ``--out`` and print the step-response metrics."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default='docs/figures', help='output folder')
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    numbers = step_figure(out)
    print('current step 0 -> 0.35 A, jaw resting on the object, noise off, sim_rate default')
    print(f'{"object":8s} {"rise 10-90% (ms)":>17s} {"overshoot (%)":>14s} {"settling 2% (ms)":>17s} '
          f'{"final (N)":>10s} {"model static (N)":>17s}')
    for obj, (m, static) in numbers.items():
        print(f'{obj:8s} {m.rise_time * 1e3:17.1f} {m.overshoot * 100:14.2f} {m.settling_time * 1e3:17.1f} '
              f'{m.final_value:10.3f} {static:17.3f}')
    effects_figure(out)
    print(f'wrote {out / "sim_step_response.png"} and {out / "sim_effects.png"}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
