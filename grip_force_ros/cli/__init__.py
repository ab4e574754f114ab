"""The ``grip-force`` command: one subcommand per module in this package.

Each subcommand module defines ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> int``. Register it in :data:`COMMANDS` below; modules are
imported only when their subcommand runs, so a missing optional dependency of
one command never breaks the others.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from grip_force_ros.nodes.processes import ensure_local_discovery

#: subcommand -> module under grip_force_ros.cli
COMMANDS = {
    'params': 'params',
    'reproduce': 'reproduce',
    'predict': 'predict',
    'tune': 'tune',
    'demo': 'demo',
    'calibrate': 'calibrate',
    'monitor': 'monitor',
    'import-rig': 'import_rig',
    'import-dvrk-tool': 'import_dvrk_tool',
    'realdata': 'realdata',
    'diagnose': 'diagnose',
    'blindcheck': 'blindcheck',
    'faultcheck': 'faultcheck',
    'soak': 'soak',
    'bench': 'bench',
    'load': 'load',
    'loadcheck': 'loadcheck',
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='grip-force', description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f'grip_force_ros.cli.{module_name}')
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_module=module)
    return parser


def main(argv: list[str] | None = None) -> int:
    ensure_local_discovery()       # DDS on loopback unless the user chose a range
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, '_module', None):
        parser.print_help()
        return 2
    return int(args._module.run(args) or 0)


if __name__ == '__main__':
    sys.exit(main())
