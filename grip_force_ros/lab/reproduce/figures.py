"""Figures of the reproduction report (PNG, matplotlib Agg). Each function writes one file.

Every curve is computed by the model code from the instrument parameters.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from grip_force_ros.model import GripForceModel
from grip_force_ros.lab.plotting import pyplot, save
from grip_force_ros.lab.reproduce.rows import PAPER

plt = pyplot()

__all__ = ['grip_over_wrist_and_opening', 'grip_vs_current', 'needle_with_and_without_losses',
           'outputs_vs_cable_radius', 'efficiency_vs_current', 'make_all']

DPI = 110


def grip_over_wrist_and_opening(params, out: Path, current: float = 0.35, others=()) -> Path:
    """Rigid-object grip force over wrist angle x opening angle at a fixed current."""
    instruments = [params, *others]
    wrist = np.linspace(0.0, math.pi / 2, 61)
    opening = np.linspace(0.0, math.pi / 2, 61)
    wrist_grid, open_grid = np.meshgrid(wrist, opening, indexing='ij')
    fig, axes = plt.subplots(1, len(instruments), figsize=(5.2 * len(instruments), 4.3), squeeze=False)
    for ax, p in zip(axes[0], instruments):
        force = GripForceModel(p).forward(current, wrist_grid, open_grid, 'rigid').grip_force
        mesh = ax.contourf(wrist_grid, open_grid, force, levels=20, cmap='viridis')
        ax.contour(wrist_grid, open_grid, force, levels=8, colors='k', linewidths=0.4)
        fig.colorbar(mesh, ax=ax, label='grip force F_J [N]')
        ax.set_xlabel('wrist angle theta_32 [rad]')
        ax.set_ylabel('opening angle [rad]')
        ax.set_title(f'{p.instrument_name}\nrigid object, I = {current:g} A\n'
                     f'wrist_wrap_gain = {p.wrist_wrap_gain:g}', fontsize=9)
    return save(fig, out / 'grip_over_wrist_and_opening.png', DPI)


def grip_vs_current(params, out: Path, opening: float = math.pi / 6, others=()) -> Path:
    """Rigid-object grip force against current at a fixed opening angle."""
    current = np.linspace(0.0, 0.5, 101)
    fig, ax = plt.subplots(figsize=(6.4, 4.3))
    model = GripForceModel(params)
    ax.plot(current, model.forward(current, 0.0, opening, 'rigid').grip_force, 'C0', lw=2,
            label=f'model with losses ({params.instrument_name})')
    ax.plot(current, GripForceModel(params, losses=False).forward(current, 0.0, opening, 'rigid').grip_force,
            'C0--', label='model ideal (lambda = 1, no static M\')')
    paper = np.maximum(PAPER['torque_slope'] * current + PAPER['torque_offset'], 0.0) \
        / params.jaw_moment_arm_tip * math.cos(opening)
    ax.plot(current, paper, 'k:', lw=2, label="paper: (0.28 I - 12.44e-6)/l cos")
    for k, p in enumerate(others, start=1):
        ax.plot(current, GripForceModel(p).forward(current, 0.0, opening, 'rigid').grip_force, f'C{k}',
                label=f'model with losses ({p.instrument_name})')
    ax.set_xlabel('motor current I [A]')
    ax.set_ylabel('grip force F_J [N]')
    ax.set_title(f'Rigid object, opening angle pi/6 = {opening:.3f} rad, wrist 0')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, out / 'grip_vs_current.png', DPI)


def needle_with_and_without_losses(params, out: Path) -> Path:
    """Needle grip and pull-out force against current, with and without losses."""
    current = np.linspace(0.0, params.max_current, 101)
    lossy = GripForceModel(params).forward(current, 0.0, 0.0, 'needle')
    ideal = GripForceModel(params, losses=False).forward(current, 0.0, 0.0, 'needle')
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2))
    panels = [(axes[0], lossy.grip_force, ideal.grip_force, 'needle grip force F_J [N]',
               PAPER['needle_grip_losses'], PAPER['needle_grip_ideal']),
              (axes[1], lossy.pull_out_force, ideal.pull_out_force, 'pull-out force F_L [N]',
               PAPER['pull_out_losses'], PAPER['pull_out_ideal'])]
    for ax, with_loss, without, label, paper_loss, paper_ideal in panels:
        ax.plot(current, with_loss, 'C0', lw=2, label='model with losses')
        ax.plot(current, without, 'C1', lw=2, label='model without losses')
        ax.plot([current[-1]], [paper_loss], 'C0o', ms=9, mfc='none', mew=2,
                label=f'paper maximum with losses ({paper_loss:g} N)')
        ax.plot([current[-1]], [paper_ideal], 'C1s', ms=9, mfc='none', mew=2,
                label=f'paper maximum ideal ({paper_ideal:g} N)')
        ax.axhline(1.4, color='grey', ls=':', lw=1, label='typical suturing need (1.4 N)')
        ax.set_xlabel('motor current I [A]')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7.5)
    axes[0].set_title(f'0.5 mm needle, {params.instrument_name}')
    axes[1].set_title("pull-out F_L = (sqrt2 + 1) mu' F_J")
    return save(fig, out / 'needle_with_and_without_losses.png', DPI)


def outputs_vs_cable_radius(params, out: Path) -> Path:
    """lambda_3, torque slope, needle grip and creep coefficient against the unstated cable radius."""
    top = 0.95 * min(params.guide_pulley_radii)
    radii = np.linspace(2e-5, top, 80)
    lam, slope, grip, creep = [], [], [], []
    for r in radii:
        m = GripForceModel(params.replace(cable_radius=float(r)))
        lam.append(float(m.efficiency()))
        slope.append(float(m.forward(1.0, 0.0, 0.0, 'needle').jaw_torque))   # M at 1 A, at rest
        grip.append(float(m.forward(params.max_current, 0.0, 0.0, 'needle').grip_force))
        creep.append(m.creep_coefficient())
    mm = radii * 1e3
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    panels = [(axes[0, 0], lam, 'lambda_3 [-]', PAPER['lambda_3']),
              (axes[0, 1], slope, 'torque slope dM/dI [N*m/A]', PAPER['torque_slope']),
              (axes[1, 0], grip, f'needle grip at {params.max_current:g} A [N]', PAPER['needle_grip_losses']),
              (axes[1, 1], np.abs(creep), '|creep coefficient| [rad/A] (log)', -PAPER['current_coefficient'])]
    for ax, values, label, paper in panels:
        ax.plot(mm, values, 'C0', lw=2, label='model')
        ax.axhline(paper, color='k', ls=':', label=f'paper {paper:g}')
        ax.axvline(params.cable_radius * 1e3, color='C3', ls='--',
                   label=f'assumed r = {params.cable_radius * 1e3:g} mm')
        ax.set_xlabel('cable radius r [mm] (not in the paper)')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[1, 1].set_yscale('log')
    fig.suptitle(f'{params.instrument_name}: what the unstated cable radius changes '
                 f'(pulleys R = {min(params.guide_pulley_radii) * 1e3:g} mm)', fontsize=10)
    return save(fig, out / 'outputs_vs_cable_radius.png', DPI)


def efficiency_vs_current(params, out: Path, gains=(0.0, 2.5e-4, 5e-4, 1e-3, 2e-3)) -> Path:
    """Chain efficiency and needle grip against current for several tension-friction gains."""
    current = np.linspace(0.0, params.max_current, 101)
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.2))
    for k, gain in enumerate(gains):
        m = GripForceModel(params.replace(tension_friction_gain=gain))
        lam = m.efficiency(current)
        tag = 'constant mu (paper)' if gain == 0 else f'mu (1 + {gain:g}/N * F)'
        axes[0].plot(current, lam, f'C{k}', lw=2, label=tag)
        axes[1].plot(current, m.forward(current, 0.0, 0.0, 'needle').grip_force, f'C{k}', lw=2, label=tag)
    axes[0].axhline(PAPER['lambda_3'], color='k', ls=':', label='paper lambda_3 = 0.765')
    axes[0].axhline(1 - PAPER['efficiency_loss_max_current'], color='grey', ls='--',
                    label='25% loss (paper, at max current)')
    axes[0].axhline(params.drive_resistance_fraction, color='C3', ls='-.', lw=1,
                    label=f'drive_resistance_fraction = {params.drive_resistance_fraction:g} (no grip below)')
    axes[0].set_ylabel('chain efficiency lambda_3 [-]')
    axes[0].set_ylim(params.drive_resistance_fraction - 0.05, 1.1)
    axes[1].set_ylabel('needle grip force [N]')
    for ax in axes:
        ax.set_xlabel('motor current I [A]')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc='upper center', ncol=2)
    axes[1].legend(fontsize=7.5, loc='upper left')
    axes[0].set_title('efficiency against current: constant vs tension-dependent friction', fontsize=9)
    axes[1].set_title('needle grip force for the same friction laws', fontsize=9)
    return save(fig, out / 'efficiency_vs_current.png', DPI)


def make_all(params, out: Path, others=()) -> list[Path]:
    """Write every figure into ``out``; return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    return [grip_over_wrist_and_opening(params, out, others=others),
            grip_vs_current(params, out, others=others),
            needle_with_and_without_losses(params, out),
            outputs_vs_cable_radius(params, out),
            efficiency_vs_current(params, out)]
