"""`grip-force tune`: design the PID gains of an instrument on its linear plant model."""
from __future__ import annotations

import json
import math
from pathlib import Path

HELP = 'design PID gains with python-control; print gains, gain/phase margins, write a step plot'


def add_arguments(parser) -> None:
    parser.add_argument('--config', required=True, metavar='YAML', help='instrument parameter file')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--out', metavar='DIR', default='.',
                        help='directory for the step-response PNG (default: current directory)')
    parser.add_argument('--analyse-only', action='store_true',
                        help='analyse the gains already in the YAML instead of designing new ones')


def _fmt(x: float) -> str:
    return 'inf' if not math.isfinite(x) else f'{x:.1f}'


def plot_steps(params, path, title: str = '', model=None) -> None:
    """Write the step-response figure (PNG) of :func:`grip_force_ros.control.tune.step_responses`."""
    from grip_force_ros.control.tune import settling_time, step_responses
    from grip_force_ros.plotting import pyplot
    plt = pyplot()
    steps = step_responses(params, model=model)
    fig, (ax_f, ax_j) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for name, (t, y) in steps.items():
        ax = ax_j if name.startswith('jaw') else ax_f
        ax.plot(t * 1e3, y, label=f'{name}; 5% settling {settling_time(t, y) * 1e3:.0f} ms')
    ax_f.axhline(1.0, color='k', lw=0.5, ls='--')
    ax_j.axhline(1.0, color='k', lw=0.5, ls='--')
    ax_f.set_ylabel('grip force / target (-)')
    ax_j.set_ylabel('jaw angle / target (-)')
    ax_j.set_xlabel('time (ms)')
    ax_f.legend(fontsize=8)
    ax_j.legend(fontsize=8)
    ax_f.set_title(title or 'closed-loop unit step responses (nominal linear plant, 1 kHz PID)')
    ax_f.grid(alpha=0.3)
    ax_j.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args) -> int:
    from grip_force_ros.control import tune
    from grip_force_ros.params import ParameterError, load_params_file
    try:
        params = load_params_file(args.config)
        result = tune.analyse(params) if args.analyse_only else tune.design(params)
    except (ParameterError, ValueError) as exc:
        print(f'error: {exc}')
        return 1
    tuned = params.replace(**result.gains)
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    png = out_dir / f'tune_{params.instrument_name}.png'
    plot_steps(tuned, png, title=(f'{params.instrument_name}: unit step responses '
                                  '(nominal linear plant, 1 kHz PID)'))
    steps = tune.step_responses(tuned)
    settling = {name: tune.settling_time(t, y) for name, (t, y) in steps.items()}
    ok = all(r.stable and r.gain_margin_db >= tune.CLAIM_GM_DB and r.phase_margin_deg >= tune.CLAIM_PM_DEG
             for r in result.reports)
    if args.json:
        doc = result.to_dict()
        doc.update(instrument=params.instrument_name, config=str(args.config), plot=str(png),
                   settling_time_5pct_s=settling, margins_met=ok)
        print(json.dumps(doc, indent=1))
        return 0 if ok else 1
    print(f'{params.instrument_name} ({args.config}), control period {result.period * 1e3:.3g} ms')
    print('gains in the YAML (analysed):' if args.analyse_only
          else 'designed gains (controller parameters, paste into the YAML):')
    for name, value in result.gains.items():
        print(f'    {name}: {value:g}')
    print(f'{"loop":<16}{"plant":<16}{"GM dB":>7}{"PM deg":>8}{"xover Hz":>10}{"BW Hz":>8}  stable')
    for r in result.reports:
        print(f'{r.loop:<16}{r.variant:<16}{_fmt(r.gain_margin_db):>7}{_fmt(r.phase_margin_deg):>8}'
              f'{r.crossover_hz:>10.1f}{r.bandwidth_hz:>8.1f}  {"yes" if r.stable else "NO"}')
    for loop in ('force_sensor', 'force_estimate', 'jaw'):
        gm, pm = result.worst(loop)
        print(f'worst {loop}: GM {_fmt(gm)} dB, PM {_fmt(pm)} deg '
              f'(claimed >= {tune.CLAIM_GM_DB:g} dB, >= {tune.CLAIM_PM_DEG:g} deg)')
    for name, value in settling.items():
        print(f'5% settling, {name}: {value * 1e3:.0f} ms')
    print(f'step plot: {png}')
    print('margins met' if ok else 'MARGINS NOT MET')
    return 0 if ok else 1
