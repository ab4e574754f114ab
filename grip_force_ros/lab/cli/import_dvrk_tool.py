"""`grip-force import-dvrk-tool`: an instrument file with the jaw facts of a dVRK tool file."""
from __future__ import annotations

import json
import sys

HELP = ('import jaw limits, jaw effort limit and the jaw and pitch couplings of a dVRK tool file '
        'into an instrument YAML (cables and friction from --base)')


def add_arguments(parser) -> None:
    parser.add_argument('tool', metavar='FILE.json',
                        help="a dVRK tool file (sawIntuitiveResearchKit share/tool/*.json; "
                             "comments allowed), e.g. ../shared/vendor/dvrk-tools/"
                             "MARYLAND_BIPOLAR_FORCEPS_400172.json")
    parser.add_argument('--base', required=True, metavar='X.yaml',
                        help='instrument YAML whose other numbers (cables, friction, motor, '
                             'limits, gains) are kept')
    parser.add_argument('--out', required=True, metavar='Y.yaml', help='the new instrument YAML')
    parser.add_argument('--json', action='store_true', help='print the imported values as JSON')


def run(args) -> int:
    from grip_force_ros.params import ParameterError
    from grip_force_ros.params.dvrk_tool import import_tool
    try:
        facts = import_tool(args.tool, args.base, args.out)
    except (ParameterError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({k: {'value': v, 'source': s} for k, (v, s) in facts.items()}, indent=1))
    else:
        for key, (value, source) in facts.items():
            print(f'{key:<24}{value!r:<12}  {source}')
        print(f'wrote {args.out}')
    return 0
