"""Markdown report and PNG figures of the rig analysis (matplotlib, Agg backend)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from grip_force_ros.lab.plotting import pyplot, save
from grip_force_ros.lab.rig.analysis import FULL, LINEAR, holdout_split
from grip_force_ros.lab.rig.estimator import ObserverSettings, _signals, motor_side_inputs

#: Held-out runs drawn in the time-series figure (slowest and fastest, both test loads).
SHOWN_RUNS = ('01', '43')


def plot_timeseries(runs: Sequence, path: Path, cache: dict | None = None) -> Path:
    """Measured jaw torque vs the two estimators on held-out runs of the holdout split."""
    plt = pyplot()
    cache = {} if cache is None else cache
    train, test = holdout_split(runs)
    full = FULL.make().fit(train, cache=cache)
    lin = LINEAR.make().fit(train)
    shown = [r for r in test if r.name in SHOWN_RUNS] or test[:2]
    fig, axes = plt.subplots(len(shown), 1, figsize=(11, 3.4 * len(shown)), squeeze=False)
    for ax, r in zip(axes[:, 0], shown):
        ax.plot(r.t, r.jaw_torque * 1e3, color='k', lw=1.0, label='measured (jaw torque sensor)')
        ax.plot(r.t, lin.predict(r) * 1e3, color='tab:red', lw=0.5, alpha=0.6,
                label='linear a*I+b')
        ax.plot(r.t, full.predict(r, cache=cache) * 1e3, color='tab:blue', lw=1.0,
                label='cable friction observer')
        ax.set_title(f'held-out run {r.name}: {r.frequency_hz:g} Hz, '
                     f'{r.torque_level_percent:g} % resisting torque (fit on 10 % and 30 % runs)')
        ax.set_ylabel('jaw torque (mN m)')
        lo, hi = np.percentile(r.jaw_torque * 1e3, [0.5, 99.5])
        ax.set_ylim(lo - 20, hi + 20)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel('time (s)')
    axes[0, 0].legend(loc='lower right', fontsize=8)
    return save(fig, path, dpi=90)


def plot_friction_branches(runs: Sequence, result: dict, path: Path) -> Path:
    """Plot current against jaw torque while sliding: two friction branches and the fitted lines."""
    plt = pyplot()
    settings = ObserverSettings()
    fig, ax = plt.subplots(figsize=(8, 6))
    colours = {1: 'tab:orange', -1: 'tab:blue'}
    for r in runs:
        sig = _signals(motor_side_inputs(r), settings)
        for sign in (1, -1):
            m = (sig.sliding > 0) & (np.sign(sig.direction) == sign)
            idx = np.flatnonzero(m)[::25]
            ax.plot(r.jaw_torque[idx] * 1e3, sig.current[idx], '.', ms=1.5, color=colours[sign],
                    alpha=0.3)
    fwd = result['estimators'][1]['parameters']['forward_model']
    coef = {k: v['value'] for k, v in fwd.items()}
    tau = np.linspace(0.0, 0.06, 50)
    for sign, label in ((1, 'closing (motor drives)'), (-1, 'opening (load back-drives)')):
        alpha = coef['alpha0'] + sign * coef.get('alpha1', 0.0)
        quad = sign * coef.get('alpha1_quad', 0.0)
        beta = coef['offset'] + sign * coef.get('coulomb', 0.0)
        ax.plot(tau * 1e3, alpha * tau + quad * tau ** 2 + beta, color=colours[sign], lw=2.5,
                label=f'{label}: I = {alpha:.2f} A/(N m) * tau {quad:+.2f} A/(N m)^2 * tau^2 '
                      f'{beta:+.3f} A')
    phys = result['estimators'][1]['parameters']['physical']
    ax.set_title('Friction branches (sliding samples, all runs); lines: fit on the 10/30 % runs, '
                 'mid-stroke, v = 0\n'
                 f"efficiency {phys['efficiency']['value']:.2f} +- {phys['efficiency']['std']:.2f}, "
                 f"gain {phys['gain_Nm_per_A']['value']:.2f} +- {phys['gain_Nm_per_A']['std']:.2f} "
                 f"N m/A, Coulomb {phys['coulomb_Nm']['value'] * 1e3:.0f} mN m at the jaw",
                 fontsize=9)
    ax.set_xlabel('measured jaw torque (mN m)')
    ax.set_ylabel('back-end current, 10 Hz low-pass (A)')
    ax.legend(fontsize=8, loc='center right')
    ax.grid(alpha=0.3)
    return save(fig, path, dpi=90)


def plot_regions(result: dict, path: Path) -> Path:
    """Held-out RMSE per region (both estimators), one panel per family."""
    plt = pyplot()
    families = []
    for row in result['regions']:
        if row['family'] not in families:
            families.append(row['family'])
    lin = {row['where']: row for row in result['regions_linear']}
    fig, axes = plt.subplots(len(families), 1, figsize=(10, 2.3 * len(families)))
    for ax, fam in zip(np.atleast_1d(axes), families):
        rows = [r for r in result['regions'] if r['family'] == fam]
        rows.sort(key=lambda r: r['where'])
        y = np.arange(len(rows))
        ax.barh(y + 0.2, [r['rmse_mNm'] for r in rows], height=0.4, color='tab:blue',
                label='cable friction observer')
        ax.barh(y - 0.2, [lin[r['where']]['rmse_mNm'] if r['where'] in lin else 0 for r in rows],
                height=0.4, color='tab:red', alpha=0.5, label='linear')
        for yi, r in zip(y, rows):
            ax.text(r['rmse_mNm'] + 0.2, yi + 0.2, f"{100 * r['share_of_gap']:.0f} % of gap",
                    va='center', fontsize=7)
        ax.set_yticks(y)
        ax.set_yticklabels([r['where'].split(': ', 1)[1] for r in rows], fontsize=8)
        ax.axvline(result['published_rmse_mNm'], color='k', ls='--', lw=0.8)
        ax.set_title(fam, fontsize=9, loc='left')
        ax.set_xlim(0, 20)
    np.atleast_1d(axes)[0].legend(fontsize=7, loc='lower right')
    np.atleast_1d(axes)[-1].set_xlabel('held-out RMSE (mN m); dashed: published 4.42 mN m')
    return save(fig, path, dpi=90)


def plot_effects(result: dict, path: Path) -> Path:
    """Held-out RMSE of the ladder, drop-one and add-one variants."""
    plt = pyplot()
    rows = []
    for group in ('ladder', 'drop_one', 'add_one'):
        for r in result['effects'][group]:
            rows.append((group, r['name'], r['holdout_rmse_mNm'],
                         r['cv_rmse_mNm'].get('level', float('nan'))))
    fig, ax = plt.subplots(figsize=(10, 0.35 * len(rows) + 1.5))
    y = np.arange(len(rows))[::-1]
    colours = {'ladder': 'tab:blue', 'drop_one': 'tab:red', 'add_one': 'tab:green'}
    ax.barh(y, [min(r[2], 40) for r in rows], color=[colours[r[0]] for r in rows], height=0.6)
    for yi, r in zip(y, rows):
        ax.text(min(r[2], 40) + 0.3, yi, f'{r[2]:.2f} (level-CV {r[3]:.2f})', va='center', fontsize=7)
    ax.set_yticks(y)
    ax.set_yticklabels([f'{r[0]}: {r[1]}' for r in rows], fontsize=8)
    ax.axvline(result['published_rmse_mNm'], color='k', ls='--', lw=0.8)
    ax.set_xlabel('held-out RMSE, runs at 20 and 40 % (mN m; bars clipped at 40); '
                  'dashed: published 4.42')
    ax.set_xlim(0, 48)
    ax.set_title('What each effect is worth: ladder (blue), removed from the full model (red), '
                 'added to it (green)', fontsize=9)
    return save(fig, path, dpi=90)


def _fmt(value, std=None, scale=1.0, digits=3):
    if std is None:
        return f'{value * scale:.{digits}g}'
    return f'{value * scale:.{digits}g} +- {std * scale:.2g}'


def write_report(result: dict, runs: Sequence, out_dir, *, cache: dict | None = None) -> Path:
    """Write ``report.md`` and four PNG figures into ``out_dir``; return the report path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {
        'timeseries': plot_timeseries(runs, out / 'realdata_timeseries.png', cache),
        'branches': plot_friction_branches(runs, result, out / 'realdata_friction_branches.png'),
        'regions': plot_regions(result, out / 'realdata_regions.png'),
        'effects': plot_effects(result, out / 'realdata_effects.png'),
    }
    lin, full = result['estimators']
    ho = result['split']['holdout']
    lines = [
        '# Real instrument data: jaw torque from motor-side signals',
        '',
        f"{result['data']['attribution']}",
        '',
        '## Split',
        f"Held out: {ho['description']}. Train runs {', '.join(ho['train'])}; "
        f"test runs {', '.join(ho['test'])}.",
        'Cross-validation: ' + '; '.join(result['split']['cross_validation'].values()) + '.',
        f"Estimator inputs (motor side only): {', '.join(result['estimator_inputs'])}.",
        '',
        '## Held-out jaw torque RMSE (mN m)',
        '',
        '| estimator | holdout | holdout after 1 s | CV level | CV frequency | CV run |',
        '|---|---|---|---|---|---|',
    ]
    for e in (lin, full):
        cv = e['cv_rmse_mNm']
        lines.append(f"| {e['name']} | {e['holdout_rmse_mNm']:.2f} | "
                     f"{e['holdout_rmse_after_startup_mNm']:.2f} | {cv.get('level', float('nan')):.2f} | "
                     f"{cv.get('frequency', float('nan')):.2f} | {cv.get('run', float('nan')):.2f} |")
    lines += [f"| published (O'Neill et al. 2018, neural networks) | {result['published_rmse_mNm']:.2f} "
              '| | | | |', '',
              f"Beats the published figure on the holdout split: **{result['beats_published']}**.", '',
              '![time series](realdata_timeseries.png)', '',
              '## Fitted parameters (holdout training runs; +- leave-one-run-out jackknife)', '']
    phys = full['parameters']['physical']
    units = {'gain_Nm_per_A': ('gain G (loss-free current to jaw torque)', 'N m/A', 1.0),
             'efficiency': ('one-way efficiency eta (zero load)', '-', 1.0),
             'efficiency_at_100mNm': ('one-way efficiency eta at 100 mN m', '-', 1.0),
             'coulomb_Nm': ('Coulomb friction at the jaw', 'mN m', 1e3),
             'offset_Nm': ('offset at the jaw', 'mN m', 1e3),
             'viscous_Nms_per_rad': ('viscous friction', 'mN m s/rad', 1e3),
             'spring_span_Nm': ('position spring, peak-to-peak over the stroke', 'mN m', 1e3)}
    lines += ['| parameter | value | unit |', '|---|---|---|']
    for key, (label, unit, scale) in units.items():
        if key in phys:
            lines.append(f"| {label} | {_fmt(phys[key]['value'], phys[key]['std'], scale)} | {unit} |")
    lines += ['', 'Linear baseline: jaw torque = '
              f"{lin['parameters']['slope_Nm_per_A']:.3f} N m/A * I + "
              f"{lin['parameters']['intercept_Nm'] * 1e3:.2f} mN m.", '',
              '![friction branches](realdata_friction_branches.png)', '',
              '## Which effects (held-out RMSE on the 20/40 % runs, mN m)', '',
              '| group | variant | effect | holdout | CV level | change vs full |',
              '|---|---|---|---|---|---|']
    for group in ('ladder', 'drop_one', 'add_one'):
        for r in result['effects'][group]:
            ch = r.get('change_vs_full_mNm')
            lines.append(f"| {group} | {r['name']} | {r['effect']} | {r['holdout_rmse_mNm']:.2f} | "
                         f"{r['cv_rmse_mNm'].get('level', float('nan')):.2f} | "
                         f"{'' if ch is None else f'{ch:+.2f}'} |")
    lines += ['', '![effects](realdata_effects.png)', '',
              f"## Where the gap lies ({result['regions_basis']})", '',
              '| region | share of gap | share of samples | RMSE | bias |', '|---|---|---|---|---|']
    for r in result['regions']:
        lines.append(f"| {r['where']} | {100 * r['share_of_gap']:.0f} % | "
                     f"{100 * r['share_of_samples']:.0f} % | {r['rmse_mNm']:.2f} | {r['bias_mNm']:+.2f} |")
    off = result['run_offsets']
    lines += ['', f"Per-run bias: std {off['per_run_bias_std_mNm']:.2f} mN m, range "
              f"{off['per_run_bias_range_mNm'][0]:.2f}..{off['per_run_bias_range_mNm'][1]:.2f} mN m; "
              f"within-run trend {off['within_run_trend_mNm_per_10s']:+.2f} +- "
              f"{off['within_run_trend_std_mNm_per_10s']:.2f} mN m per 10 s.", '',
              '![regions](realdata_regions.png)', '']
    if 'sensitivity' in result:
        lines += ['## Sensitivity to the fixed settings (holdout RMSE, mN m)', '',
                  '| setting | value | holdout |', '|---|---|---|']
        for r in result['sensitivity']:
            lines.append(f"| {r['setting']} | {r['value']:g} | {r['holdout_rmse_mNm']:.2f} |")
        lines.append('')
    path = out / 'report.md'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    result['report'] = str(path)
    result['figures'] = {k: str(v) for k, v in figs.items()}
    return path
