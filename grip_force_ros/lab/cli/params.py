"""`grip-force params`: list the parameter schema, or check an instrument YAML."""
from __future__ import annotations

import json

HELP = 'list the parameter schema (name, type, unit, default, range) or validate a YAML'


def add_arguments(parser) -> None:
    parser.add_argument('--check', metavar='YAML', help='validate an instrument YAML and exit')
    parser.add_argument('--group', action='append', help='only these groups (repeatable)')
    parser.add_argument('--markdown', action='store_true', help='print a Markdown table (for docs)')
    parser.add_argument('--json', action='store_true', help='print JSON')


def run(args) -> int:
    from grip_force_ros.params import ParameterError, load_params_file, markdown_table, specs_in
    if args.check:
        from grip_force_ros.model import ModelError
        from grip_force_ros.model.physical import cable_load, check_physical
        try:
            p = load_params_file(args.check)
            check_physical(p)
        except (ParameterError, ModelError) as exc:
            print(f'error: {args.check}: {exc}' if isinstance(exc, ModelError) else f'error: {exc}')
            return 1
        load = cable_load(p)
        print(f"{args.check}: ok ({p.instrument_name}, {len(p)} parameters; cable "
              f"{load['stress'] / 1e9:.2f} GPa at max_current {load['current']:g} A, "
              f"{load['share']:.0%} of its yield strength)")
        return 0
    specs = specs_in(*(args.group or ()))
    if args.json:
        print(json.dumps([{**s.__dict__, 'default': list(s.default) if isinstance(s.default, tuple)
                           else s.default} for s in specs], indent=1))
        return 0
    if args.markdown:
        print(markdown_table(specs))
        return 0
    for s in specs:
        rng = '' if s.min is None and s.max is None else f' [{s.min}, {s.max}]'
        print(f'{s.name:32s} {s.group:10s} {s.type:12s} {s.unit:8s} {s.default!s:24s}{rng}')
    return 0
