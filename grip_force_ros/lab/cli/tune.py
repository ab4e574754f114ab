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


def figure_rates(params) -> tuple[float, ...]:
    """State rates (Hz) of the step figure: the expected one and the slowest of the range."""
    from grip_force_ros.params.controller import STATE_RATE_MIN
    return tuple(sorted({float(params.expected_state_rate), STATE_RATE_MIN}, reverse=True))


def plot_steps(params, path, title: str = '', model=None) -> dict:
    """Write the step-response figure (PNG) of :func:`grip_force_ros.lab.tune.step_responses`.

    One curve per loop at each rate of :func:`figure_rates` (solid: the first, dashed: the
    next), each with the gains the controller runs there (the schedule). Returns the 5%
    settling times (s): rate (Hz) -> curve name -> s.
    """
    from grip_force_ros.lab.tune import settling_time, step_responses
    from grip_force_ros.lab.plotting import pyplot
    plt = pyplot()
    fig, (ax_f, ax_j) = plt.subplots(2, 1, figsize=(8, 8), sharex=True)
    settling = {}
    for rate, style in zip(figure_rates(params), ('-', '--')):
        steps = step_responses(params, model=model, rate=rate, duration=0.3)
        settling[rate] = {name: settling_time(t, y) for name, (t, y) in steps.items()}
        for k, (name, (t, y)) in enumerate(steps.items()):
            ax = ax_j if name.startswith('jaw') else ax_f
            ax.plot(t * 1e3, y, style, color=f'C{k}', drawstyle='steps-post',
                    label=f'{rate:g} Hz, {name}; 5% settling {settling[rate][name] * 1e3:.0f} ms')
    for ax in (ax_f, ax_j):
        ax.axhline(1.0, color='k', lw=0.5, ls='--')
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    ax_f.set_ylabel('grip force / target (-)')
    ax_j.set_ylabel('jaw angle / target (-)')
    ax_j.set_xlabel('time (ms)')
    ax_f.set_title(title or 'closed-loop unit step responses (nominal linear plant, scheduled gains)')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return settling


def _rate_lines(result) -> list[str]:
    """One line per state rate: the schedule's scales, worst margins, nominal crossovers."""
    loops = ('force_sensor', 'force_estimate', 'jaw')
    head = (f'{"rate Hz":>8}{"scale F":>9}{"scale J":>9}'
            + ''.join(f'{loop + " GM/PM":>24}' for loop in loops) + f'{"xover F/J Hz":>14}  stable')
    lines = [head]
    for rate in sorted({r.rate_hz for r in result.reports}):
        rs = [r for r in result.reports if r.rate_hz == rate]
        scale = {loop: next(r.gain_scale for r in rs if r.loop == loop) for loop in loops}
        xover = {loop: next(r.crossover_hz for r in rs if r.loop == loop and r.variant == 'nominal')
                 for loop in loops}
        worst = {loop: result.worst(loop, rate) for loop in loops}
        cells = ''.join(f'{_fmt(worst[loop][0]) + " dB / " + _fmt(worst[loop][1]):>20} deg'
                        for loop in loops)
        lines.append(f'{rate:>8g}{scale["force_sensor"]:>9.3f}{scale["jaw"]:>9.3f}{cells}'
                     f'{xover["force_sensor"]:>8.1f} / {xover["jaw"]:<4.1f}  '
                     f'{"yes" if all(r.stable for r in rs) else "NO"}')
    return lines


def run(args) -> int:
    from grip_force_ros.lab import tune
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
    rates = ' and '.join(f'{r:g} Hz' for r in figure_rates(tuned))
    settling = plot_steps(tuned, png, title=(f'{params.instrument_name}: unit step responses at {rates} '
                                             'states\n(nominal linear plant, scheduled gains)'))
    ok = all(r.stable and r.gain_margin_db >= tune.CLAIM_GM_DB and r.phase_margin_deg >= tune.CLAIM_PM_DEG
             for r in result.reports)
    expected = float(params.expected_state_rate)
    if args.json:
        doc = result.to_dict()
        doc.update(instrument=params.instrument_name, config=str(args.config), plot=str(png),
                   settling_time_5pct_s=settling[expected],
                   settling_time_5pct_s_by_rate={f'{r:g}': v for r, v in settling.items()},
                   margins_met=ok)
        print(json.dumps(doc, indent=1))
        return 0 if ok else 1
    print(f'{params.instrument_name} ({args.config}), states expected at {expected:g} Hz')
    print('gains in the YAML (analysed):' if args.analyse_only
          else 'designed gains and schedule (controller parameters, paste into the YAML):')
    for name, value in result.gains.items():
        print(f'    {name}: {value:g}')
    print(f'the controller runs at {expected:g} Hz: {result.schedule.describe()}')
    print('worst case over the plant variants at each state rate, scheduled gains:')
    print('\n'.join(_rate_lines(result)))
    for loop in ('force_sensor', 'force_estimate', 'jaw'):
        gm, pm = result.worst(loop)
        print(f'worst {loop}: GM {_fmt(gm)} dB, PM {_fmt(pm)} deg '
              f'(claimed >= {tune.CLAIM_GM_DB:g} dB, >= {tune.CLAIM_PM_DEG:g} deg)')
    for rate, times in settling.items():
        for name, value in times.items():
            print(f'5% settling at {rate:g} Hz, {name}: {value * 1e3:.0f} ms')
    print(f'step plot: {png}')
    print('margins met' if ok else 'MARGINS NOT MET')
    return 0 if ok else 1
