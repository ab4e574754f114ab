"""`grip-force blindcheck`: diagnose simulated logs with hidden effects and score the verdicts."""
from __future__ import annotations

import json
import sys

HELP = 'blind check of the diagnosis on simulated logs with hidden effects (confusion matrix, scores)'

#: Goals on the mean over seeds, and the floor of the worst seed's share named right.
GOALS = {'accuracy': 0.9, 'median_shrink': 0.5, 'none_accuracy': 0.9}
WORST_ACCURACY = 0.85


def add_arguments(parser) -> None:
    from grip_force_ros.lab.diagnosis.blind import DEVELOPMENT_SEEDS, HELD_OUT_SEEDS
    parser.add_argument('--json', action='store_true', help='print the result as one JSON object')
    parser.add_argument('--quick', action='store_true', help='the small CI set (about a minute a seed)')
    parser.add_argument('--seed', type=int, default=HELD_OUT_SEEDS[0],
                        help=f'first seed of the blind sets (default {HELD_OUT_SEEDS[0]}: held-out seeds '
                             f'{HELD_OUT_SEEDS[0]}-{HELD_OUT_SEEDS[-1]}; seeds {DEVELOPMENT_SEEDS[0]}-'
                             f'{DEVELOPMENT_SEEDS[-1]} are the development seeds the diagnosis was tuned on)')
    parser.add_argument('--seeds', type=int, default=1, metavar='N',
                        help='number of seeds, from --seed on: the mean and the worst seed (default 1)')
    parser.add_argument('--workers', type=int, default=1, metavar='N',
                        help='diagnose N seeds at once, one process each (same figures; default 1)')
    parser.add_argument('--quiet', action='store_true', help='no progress on stderr')


def _pct(x) -> str:
    return 'n/a' if x is None else f'{100 * x:.0f} %'


def _table(result: dict) -> str:
    from grip_force_ros.lab.diagnosis.effects import EFFECT_NAMES, NONE
    cols = list(EFFECT_NAMES) + [NONE]
    short = {c: ''.join(w[0] for w in c.split('_')) for c in cols}
    lines = ['confusion (rows: truth, columns: first named effect): ' +
             ', '.join(f'{short[c]}={c}' for c in cols),
             f"{'':>28s} " + ' '.join(f'{short[c]:>4s}' for c in cols)]
    for truth, row in result['confusion'].items():
        if sum(row.values()):
            lines.append(f'{truth:>28s} ' + ' '.join(f'{row[c]:4d}' for c in cols))
    worst, mismatch = result['worst'], result['mismatch']
    seeds = result['settings']['seeds']
    lines += [f"logs: {result['logs']} ({seeds} seed(s) from {result['settings']['seed']}; "
              'mean over seeds, worst seed in brackets)',
              f"named right: {_pct(result['accuracy'])} [{_pct(worst['accuracy'])}] "
              f'(goal >= 90 %, worst >= {100 * WORST_ACCURACY:.0f} %; a pair needs both effects)',
              f"median held-out shrink: {_pct(result['median_shrink'])} [{_pct(worst['median_shrink'])}] "
              '(goal >= 50 %)',
              f"effect-free logs reported none: {_pct(result['none_accuracy'])} "
              f"[{_pct(worst['none_accuracy'])}] (goal >= 90 %)",
              f"pairs with both effects named: {_pct(result['pair_accuracy'])} "
              f"[{_pct(worst['pair_accuracy'])}]",
              f"off parameters named and within 5 % (effect-free logs): {_pct(result['mismatch_recovered'])} "
              f"[{_pct(worst['mismatch_recovered'])}]",
              f"friction or stiffness >= 10 % off: effect-free {mismatch['logs']} logs, none "
              f"{_pct(mismatch['none'])} [{_pct(worst['mismatch']['none'])}]; with an effect "
              f"{mismatch['effect_logs']} logs, named right {_pct(mismatch['effect_named'])} "
              f"[{_pct(worst['mismatch']['effect_named'])}]",
              f"time: {result['seconds']:.0f} s"]
    return '\n'.join(lines)


def meets_goals(result: dict) -> bool:
    """Tell whether the mean figures meet :data:`GOALS` and the worst seed :data:`WORST_ACCURACY`."""
    return (all(result[k] is not None and result[k] >= goal for k, goal in GOALS.items())
            and result['worst']['accuracy'] >= WORST_ACCURACY)


def run(args) -> int:
    from grip_force_ros.lab.diagnosis.blind import run_blindcheck

    def say(msg):
        if not args.quiet:
            print(f'[blindcheck] {msg}', file=sys.stderr, flush=True)

    if args.seeds < 1:
        print('error: --seeds must be at least 1', file=sys.stderr)
        return 2
    result = run_blindcheck(quick=args.quick, seed=args.seed, seeds=args.seeds, progress=say,
                            workers=args.workers)
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        print(_table(result))
    return 0 if meets_goals(result) else 1
