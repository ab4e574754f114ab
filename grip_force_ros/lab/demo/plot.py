"""The summary plot of a demo run (PNG, matplotlib Agg). No ROS."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from grip_force_ros.lab.plotting import pyplot

_PHASE_COLOURS = {'approach': '#f0f0f0', 'close': '#e3ecf7', 'hold': '#e6f4e6',
                  'pull': '#fbeede', 'release': '#f3e6f3'}


def summary_plot(data: Mapping[str, np.ndarray], windows: Mapping[str, tuple[float, float]],
                 metrics: Mapping[str, float], path: str | Path, title: str = '',
                 clocks: Mapping[str, str] | None = None) -> Path:
    """Write the summary figure of one run.

    Panels: master gripper angle and jaw angle (rad); target, estimated and
    measured grip force and the estimated needle pull-out force (N), with the estimate's
    band (``estimate_band_low`` .. ``estimate_band_high``, N) shaded where it has a width
    (an instrument with jaw friction terms, sensorless; the panel's scale is the forces',
    so a far edge may leave it); current command and measured current (A). Phases are shaded; the steady hold
    window is marked. Every trace is drawn as ``data`` holds it: on one time axis
    (s), NaN where a topic was silent (a gap in its line).

    Parameters
    ----------
    data : mapping
        't' (s since the master started its task) and the series on it.
    windows : mapping
        Phase -> (start, end) on that axis (s).
    metrics : mapping
        The run's figures (N, s, A) shown in the force panel.
    path : path
        The PNG to write.
    title : str
        Figure title.
    clocks : mapping, optional
        Topic -> the clock of its samples (:func:`grip_force_ros.lab.demo.series.sample_clock`);
        the figure's footnote names the time base, and each topic not on its header stamps.

    Returns
    -------
    Path
        The PNG written.
    """
    plt = pyplot()

    from grip_force_ros.lab.demo.analysis import steady_window

    path = Path(path)
    t = data['t']
    nan = np.full(t.shape, np.nan)
    fig, axes = plt.subplots(3, 1, figsize=(10, 8.5), sharex=True,
                             gridspec_kw={'height_ratios': [1, 1.6, 1]})
    for ax in axes:
        for name, (a, b) in windows.items():
            ax.axvspan(a, b, color=_PHASE_COLOURS.get(name, '#f7f7f7'), zorder=0)
        ax.grid(True, alpha=0.3)
    for name, (a, b) in windows.items():
        axes[0].text(0.5 * (a + b), 1.0, name, transform=axes[0].get_xaxis_transform(),
                     ha='center', va='bottom', fontsize=9)

    ax = axes[0]
    ax.plot(t, data.get('master_angle', nan), label='master gripper angle', color='tab:blue')
    ax.plot(t, data.get('jaw_angle', nan), label='jaw angle (measured)', color='tab:gray', lw=1)
    ax.set_ylabel('angle [rad]')
    ax.legend(loc='upper right', fontsize=8)

    ax = axes[1]
    low, high = data.get('estimate_band_low'), data.get('estimate_band_high')
    if has_band(low, high):
        ax.fill_between(t, low, high, where=np.isfinite(low) & np.isfinite(high) & (high > low),
                        color='tab:orange', alpha=0.22, lw=0, zorder=1,
                        label='estimate band (jaw friction: held inside while the jaw sticks)')
    ax.plot(t, data.get('target_force', nan), label='target grip force', color='black', lw=2)
    ax.plot(t, data.get('estimated_force', nan), label='estimated grip force (model)',
            color='tab:orange', lw=1.2)
    ax.plot(t, data.get('measured_force', nan), label='measured grip force (load cell)',
            color='tab:green', lw=1.2, alpha=0.9)
    ax.plot(t, data.get('pull_out_force', nan), label='needle pull-out force (estimated)',
            color='tab:purple', lw=1.2, ls='--')
    if 'hold' in windows:
        a, b = steady_window(windows)
        ax.axvspan(a, b, ymin=0, ymax=0.04, color='tab:green', alpha=0.6)
        ax.annotate('steady hold', ((a + b) / 2, 0.05), xycoords=('data', 'axes fraction'),
                    ha='center', fontsize=8)
    ax.set_ylabel('force [N]')
    if has_band(low, high):     # the forces set the scale: the band's far edge may be off it
        forces = np.concatenate([np.asarray(data.get(k, nan), dtype=float).ravel() for k in
                                 ('target_force', 'estimated_force', 'measured_force',
                                  'pull_out_force')])
        forces = forces[np.isfinite(forces)]
        if forces.size and forces.max() > 0.0:
            ax.set_ylim(min(0.0, forces.min()) - 0.05 * forces.max(), 1.6 * forces.max())
    ax.legend(loc='upper left', fontsize=8)
    if metrics:
        ax.text(0.99, 0.97,
                'steady hold: target {:.3f} N, measured {:.3f} N\n'
                'error mean {:+.3f} N, rms {:.3f} N, max {:.3f} N'.format(
                    metrics.get('target_force', np.nan), metrics.get('measured_force', np.nan),
                    metrics.get('hold_error_mean', np.nan), metrics.get('hold_error_rms', np.nan),
                    metrics.get('hold_error_max', np.nan)),
                transform=ax.transAxes, ha='right', va='top', fontsize=8,
                bbox={'facecolor': 'white', 'alpha': 0.8, 'edgecolor': '#cccccc'})

    ax = axes[2]
    ax.plot(t, data.get('current_command', nan), label='current command', color='tab:red')
    ax.plot(t, data.get('current', nan), label='measured current', color='tab:brown', lw=1,
            alpha=0.8)
    ax.set_ylabel('current [A]')
    ax.set_xlabel('time since the master started the task [s]')
    ax.legend(loc='upper right', fontsize=8)

    fig.suptitle(title or 'grip-force demo: needle grasp')
    if clocks is not None:
        fig.text(0.01, 0.005, time_base_note(clocks), fontsize=7, color='#555555',
                 ha='left', va='bottom')
    fig.tight_layout(rect=(0, 0.02, 1, 1) if clocks is not None else (0, 0, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def has_band(low, high) -> bool:
    """Tell whether the series ``low``, ``high`` (N, or None) hold an estimate band of some width."""
    if low is None or high is None:
        return False
    width = np.asarray(high, dtype=float) - np.asarray(low, dtype=float)
    return bool(np.any(width[np.isfinite(width)] > 0.0))


def time_base_note(clocks: Mapping[str, str]) -> str:
    """Say which clock the figure's traces are on (header stamps; exceptions by topic)."""
    from grip_force_ros.lab.demo.series import CLOCK_STAMP, SHOWN_GAP
    others = [f'{topic}: {clock}' for topic, clock in clocks.items() if clock != CLOCK_STAMP]
    where = ', except ' + '; '.join(others) if others else ' (every topic)'
    return (f"time: the samples' header stamps{where}. A gap in a line: its topic silent "
            f'for more than {SHOWN_GAP * 1e3:.0f} ms')


def compare_plot(report: Mapping, path: str | Path) -> Path:
    """Bar chart of ``--compare-instruments``; returns the PNG written.

    Steady hold force / target per instrument and condition, with each condition's
    spread in its label. A run that was not completed (``completed`` false) has no bar
    but a "not completed" mark where its bar would be.
    """
    plt = pyplot()

    conditions = ('controlled', 'uncalibrated', 'sensor', 'naive')
    labels = {'controlled': 'calibrated model, no sensor',
              'uncalibrated': 'shipped YAML, no sensor',
              'sensor': 'load-cell feedback', 'naive': 'naive (current ~ master, one gain)'}
    names = [i['name'] for i in report['instruments']]
    x = np.arange(len(names))
    width = 0.2
    fig, ax = plt.subplots(figsize=(10, 5))
    for k, c in enumerate(conditions):
        ratios = [i['runs'][c]['steady_ratio'] for i in report['instruments']]
        ratios = [np.nan if r is None else r for r in ratios]
        spread = report.get(f'spread_{c}')
        spread_text = 'n/a' if spread is None else f'{spread:.3f}'
        ax.bar(x + (k - 1.5) * width, ratios, width, label=f'{labels[c]}: spread {spread_text}')
        for j, inst in enumerate(report['instruments']):
            if not inst['runs'][c].get('completed', True):
                ax.text(x[j] + (k - 1.5) * width, 0.02, 'not completed', rotation=90,
                        ha='center', va='bottom', fontsize=7, color='tab:red')
    ax.axhline(1.0, color='black', lw=1)
    ax.set_xticks(x, names)
    ax.set_ylabel('steady hold grip force / target [-]')
    target = next((i['runs'][c]['target_force'] for c in conditions for i in report['instruments']
                   if i['runs'][c].get('target_force')), 0.0)
    error = report.get('plant_error')
    plants = (f'plants {error:.0%} off their YAML' if error is not None else
              'plants as given (--plants)')
    ax.set_title(f'same master trajectory, {len(names)} instruments, {plants} (target {target:.1f} N)',
                 fontsize=10)
    ax.legend(fontsize=8, loc='upper left')
    ax.grid(True, axis='y', alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
