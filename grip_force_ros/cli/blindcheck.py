"""`grip-force blindcheck`: diagnose simulated logs with hidden effects and score the verdicts."""
from __future__ import annotations

import json
import sys

HELP = 'blind check of the diagnosis on simulated logs with hidden effects (confusion matrix, scores)'


def add_arguments(parser) -> None:
    parser.add_argument('--json', action='store_true', help='print the result as one JSON object')
    parser.add_argument('--quick', action='store_true', help='the small CI set (about a minute)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the blind set (default 0)')
    parser.add_argument('--quiet', action='store_true', help='no progress on stderr')


def _table(result: dict) -> str:
    from grip_force_ros.diagnosis.effects import EFFECT_NAMES, NONE
    cols = list(EFFECT_NAMES) + [NONE]
    short = {c: ''.join(w[0] for w in c.split('_')) for c in cols}
    lines = ['confusion (rows: truth, columns: verdict): ' +
             ', '.join(f'{short[c]}={c}' for c in cols),
             f"{'':>28s} " + ' '.join(f'{short[c]:>4s}' for c in cols)]
    for truth, row in result['confusion'].items():
        if sum(row.values()):
            lines.append(f'{truth:>28s} ' + ' '.join(f'{row[c]:4d}' for c in cols))
    lines += [f"logs: {result['logs']}",
              f"named right: {100 * result['accuracy']:.0f} % (goal >= 90 %)",
              f"median held-out shrink: {100 * result['median_shrink']:.0f} % (goal >= 50 %)",
              f"effect-free logs reported none: {100 * result['none_accuracy']:.0f} % (goal >= 90 %)",
              f"time: {result['seconds']:.0f} s"]
    return '\n'.join(lines)


def run(args) -> int:
    from grip_force_ros.diagnosis.blind import run_blindcheck

    def say(msg):
        if not args.quiet:
            print(f'[blindcheck] {msg}', file=sys.stderr, flush=True)

    result = run_blindcheck(quick=args.quick, seed=args.seed, progress=say)
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        print(_table(result))
    goals = (result['accuracy'] >= 0.9 and result['median_shrink'] >= 0.5
             and result['none_accuracy'] >= 0.9)
    return 0 if goals else 1
