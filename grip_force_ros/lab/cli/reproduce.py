"""`grip-force reproduce`: the paper's numbers against the model, as a report with figures."""
from __future__ import annotations

import json
import sys

HELP = "reproduce the paper's results with the model: Markdown report + PNG figures (--json: rows)"


def add_arguments(parser) -> None:
    parser.add_argument('--json', action='store_true',
                        help='print {"rows": [{quantity, paper, model, rel_err, status, note}, ...]}')
    parser.add_argument('--out', default='out/reproduce', metavar='DIR',
                        help='directory for report.md and the PNG figures (default: out/reproduce)')
    parser.add_argument('--config', default=None, metavar='YAML',
                        help="instrument YAML (default: the paper's needle driver in config/)")


def run(args) -> int:
    from grip_force_ros.model import ModelError
    from grip_force_ros.params import ParameterError
    from grip_force_ros.lab.reproduce.report import build_report, rows_json
    try:
        rows, report = build_report(args.out, args.config)
    except (ParameterError, ModelError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(rows_json(rows), indent=1))
    else:
        width = max(len(r.quantity) for r in rows)
        for r in rows:
            print(f'{r.quantity:{width}s}  paper {r.paper:<11.4g} model {r.model:<11.4g} '
                  f'{r.rel_err:+8.1%}  {r.status}')
        print(f'report: {report}')
    return 0
