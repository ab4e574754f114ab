"""Markdown report with PNG figures (matplotlib, Agg) of one diagnosis."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from grip_force_ros.lab.diagnosis.engine import Diagnosis
from grip_force_ros.lab.plotting import pyplot, save


def _binned(x, y, bins=20):
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    if edges.size < 3:
        return np.array([]), np.array([]), np.array([])
    idx = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, edges.size - 2)
    count = np.bincount(idx, minlength=edges.size - 1)
    keep = count > 0
    mean = np.bincount(idx, weights=y, minlength=edges.size - 1)[keep] / count[keep]
    rms = np.sqrt(np.bincount(idx, weights=y * y, minlength=edges.size - 1)[keep] / count[keep])
    centre = 0.5 * (edges[:-1] + edges[1:])[keep]
    return centre, mean, rms


def plot_regions(d: Diagnosis, path: Path) -> Path:
    """Bar chart: held-out share of the gap per operating region (top 14)."""
    plt = pyplot()
    regions = d.result['regions'][:14][::-1]
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(regions) + 1.5))
    y = np.arange(len(regions))
    ax.barh(y, [r['share_of_gap'] for r in regions], color='tab:red', label='share of the gap')
    ax.plot([r['share_of_samples'] for r in regions], y, 'k|', markersize=14, label='share of samples')
    ax.set_yticks(y, [r['where'] for r in regions], fontsize=8)
    ax.set_xlabel('share of held-out squared residual (calibrated model)')
    ax.set_xlim(0, 1)
    ax.legend(loc='lower right', fontsize=8)
    ax.set_title('Where the model disagrees with the log')
    return save(fig, path, dpi=110)


def plot_residuals(d: Diagnosis, path: Path) -> Path:
    """Held-out residual (binned mean and RMS) against six operating variables."""
    plt = pyplot()
    s = d.series
    unit = d.result['unit']
    panels = (('current', 'current (A)'), ('jaw', 'jaw angle (rad)'), ('wrist', 'wrist angle (rad)'),
              ('jaw_velocity', 'jaw velocity (rad/s)'), ('current_rate', 'current rate (A/s)'),
              ('load_time', 'time under load (s)'))
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5))
    for ax, (key, label) in zip(axes.ravel(), panels):
        for resid, name, colour in ((s['resid_before'], 'calibrated model', 'tab:red'),
                                    (s['resid_after'], f"+ {d.result['verdict']['effect']}", 'tab:green')):
            c, mean, rms = _binned(s[key], resid)
            ax.plot(c, mean, '-o', ms=3, color=colour, label=f'{name}: mean')
            ax.plot(c, rms, '--', color=colour, label=f'{name}: rms')
        ax.axhline(0, color='k', lw=0.5)
        ax.set_xlabel(label)
        ax.set_ylabel(f'residual ({unit})')
    axes[0, 0].legend(fontsize=7)
    fig.suptitle('Held-out residual over operating regions (binned by quantiles)')
    return save(fig, path, dpi=110)


def plot_timeseries(d: Diagnosis, path: Path, seconds: float = 30.0) -> Path:
    """Held-out stretch of the first log: measured, calibrated model, model + effect."""
    plt = pyplot()
    s = d.series
    sel = s['log_index'] == s['log_index'][0]
    t = s['t'][sel]
    keep = t <= t[0] + seconds
    unit = d.result['unit']
    fig, (a, b) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    idx = np.arange(keep.sum())
    a.plot(idx, s['y'][sel][keep], color='0.3', lw=1, label=f"measured {d.result['measured']}")
    a.plot(idx, s['calibrated'][sel][keep], color='tab:red', lw=1, label='calibrated model')
    a.plot(idx, s['after'][sel][keep], color='tab:green', lw=1,
           label='model + ' + ' + '.join(d.result['verdict'].get('effects', [d.result['verdict']['effect']])))
    a.set_ylabel(f"{d.result['measured']} ({unit})")
    a.legend(fontsize=8)
    b.plot(idx, s['resid_before'][sel][keep], color='tab:red', lw=1, label='residual, calibrated model')
    b.plot(idx, s['resid_after'][sel][keep], color='tab:green', lw=1, label='residual, + named effect(s)')
    b.axhline(0, color='k', lw=0.5)
    b.set_ylabel(f'residual ({unit})')
    b.set_xlabel('held-out sample (analysis rate; held-out blocks joined)')
    b.legend(fontsize=8)
    fig.suptitle('Held-out data the fits never saw')
    return save(fig, path, dpi=110)


def plot_ranking(d: Diagnosis, path: Path) -> Path:
    """Held-out score of every effect (lower is better; `none` marks the naming threshold)."""
    plt = pyplot()
    ranking = d.result['ranking'][::-1]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(ranking) + 1.5))
    y = np.arange(len(ranking))
    colours = ['tab:gray' if r['effect'] == 'none' else 'tab:blue' for r in ranking]
    ax.barh(y, [r['score'] for r in ranking], color=colours)
    ax.set_yticks(y, [r['effect'] for r in ranking], fontsize=8)
    ax.axvline(0, color='k', lw=0.5)
    ax.set_xlabel('held-out score: log loss ratio (force Huber + angle MSE) + parameter penalty')
    ax.set_title('Which effect (lower = explains more of the held-out gap)')
    return save(fig, path, dpi=110)


def _fmt(x, digits=4):
    if x is None:
        return '-'
    if isinstance(x, str):
        return x
    return f'{x:.{digits}g}'


def _param_text(name: str, p: dict, play: bool) -> str:
    """One fitted parameter as 'name = value ± std unit', with the play's signal when ``play``."""
    text = f"{name} = {_fmt(p['value'])}"
    if p.get('std') is not None:
        text += f" ± {_fmt(p['std'], 2)}"
    text += f" {p['unit']}"
    if play and 'direction_state_of' in p:
        text += f" (play on {p['direction_state_of']})"
    return text


def write_report(d: Diagnosis, out_dir, *, title: str = 'Sim-to-real gap diagnosis',
                 sources=()) -> Path:
    """Write ``report.md`` and its PNG figures into ``out_dir``; return the Markdown path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {'regions': plot_regions(d, out / 'regions.png'),
            'residuals': plot_residuals(d, out / 'residuals.png'),
            'timeseries': plot_timeseries(d, out / 'timeseries.png'),
            'ranking': plot_ranking(d, out / 'ranking.png')}
    r = d.result
    v = r['verdict']
    unit = r['unit']
    lines = [f'# {title}', '']
    if sources:
        lines += ['Logs: ' + ', '.join(f'`{s}`' for s in sources), '']
    named = ' + '.join(f'`{e}`' for e in v.get('effects', [v['effect']]))
    first = (f" ({_fmt(v['gap_after_first'])} {unit} with `{v['effect']}` alone)"
             if len(v.get('effects', [])) > 1 and 'gap_after_first' in v else '')
    lines += [f"**Verdict: {named}** - held-out RMS gap of {r['measured']} "
              f"{_fmt(v['gap_before'])} {unit} -> {_fmt(v['gap_after'])} {unit}{first} "
              f"(shrink {100 * v['shrink']:.0f} %); jaw angle {_fmt(v['angle_gap_before'])} -> "
              f"{_fmt(v['angle_gap_after'])} rad. Runner-up: `{v['runner_up']}`.", '',
              f"Split: {r['split'].get('description', r['split']['method'])}; "
              f"{r['samples']['train']} training and {r['samples']['test']} held-out samples at "
              f"{_fmt(r['split']['analysis_rate_hz'])} Hz.", '',
              '## 1. Nominal model and calibration', '',
              'The instrument\'s own parameters, re-identified on the training part before any effect '
              '(not unmodelled effects):', '',
              '| parameter | YAML | fitted | std | unit | off |', '|---|---|---|---|---|---|']
    calibration = r['calibration']
    for name, c in calibration.get('parameters', {}).items():
        off = 'yes' if c.get('off') else c.get('note', 'no')
        lines.append(f"| {name} | {_fmt(c['yaml'])} | {_fmt(c['fitted'])} | {_fmt(c['std'], 2)} | "
                     f"{c['unit']} | {off} |")
    lines += ['', 'Then calibrated as a lab would:', '',
              '| quantity | value | std | unit | meaning |', '|---|---|---|---|---|']
    for name, c in calibration.items():
        if isinstance(c, dict) and 'value' in c:
            lines.append(f"| {name} | {_fmt(c['value'])} | {_fmt(c['std'], 2)} | {c['unit']} | "
                         f"{c['meaning']} |")
    lines += ['', 'Held-out RMS gap of the YAML model, uncalibrated: '
              f"{_fmt(calibration['gap_uncalibrated'])} {unit}; re-identified: "
              f"{_fmt(calibration.get('gap_reidentified'))} {unit}.", '',
              '## 2. Where', '', f"![regions]({figs['regions'].name})", '',
              '| region | share of gap | share of samples | rms | mean |', '|---|---|---|---|---|']
    for g in r['regions'][:12]:
        lines.append(f"| {g['where']} | {g['share_of_gap']:.2f} | {g['share_of_samples']:.2f} | "
                     f"{_fmt(g['rms'])} | {_fmt(g['mean'])} |")
    lines += ['', f"![residuals]({figs['residuals'].name})", '',
              '## 3. Which effect', '', f"![ranking]({figs['ranking'].name})", '',
              f'| effect | held-out rmse ({unit}) | held-out angle rmse (rad) | score | parameters |',
              '|---|---|---|---|---|']
    for e in r['ranking']:
        ps = '; '.join(_param_text(k, p, play=True) for k, p in e['params'].items())
        lines.append(f"| {e['effect']} | {_fmt(e['holdout_rmse'])} | {_fmt(e['holdout_angle_rmse'])} | "
                     f"{e['score']:.3f} | {ps} |")
    lines += ['', f"Rule: {v['rule']}.", '', '## 4. How far', '',
              f"![timeseries]({figs['timeseries'].name})", '',
              f"Held-out RMS gap {_fmt(v['gap_before'])} -> {_fmt(v['gap_after'])} {unit}.", '']
    second = v.get('second_effect_params')
    if second is not None and len(v.get('effects', [])) > 1:
        ps = '; '.join(_param_text(k, p, play=False) for k, p in second.items())
        lines += [f"Second effect `{v['effects'][1]}`, fitted beside `{v['effect']}` on the training "
                  f"samples: {ps}.", '']
    path = out / 'report.md'
    path.write_text('\n'.join(lines))
    return path
