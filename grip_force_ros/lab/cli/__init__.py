"""The ``grip-force`` command: one subcommand per module in this package.

Each subcommand module defines ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> int``. Register it in :data:`COMMANDS` below; modules are
imported only when their subcommand runs, so a missing optional dependency of
one command never breaks the others.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from contextlib import contextmanager

from grip_force_ros.lab.processes import ensure_local_discovery

#: subcommand -> module under grip_force_ros.lab.cli
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
    'twin': 'twin',
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
        module = importlib.import_module(f'grip_force_ros.lab.cli.{module_name}')
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_module=module)
    return parser


@contextmanager
def answer_only_on_stdout(enabled: bool):
    """While a ``--json`` command runs, keep everything but its Python output off stdout.

    Fast DDS writes its own log lines to file descriptor 1, in colour (e.g.
    ``[RTPS_TRANSPORT_SHM Error] ... open_and_lock_file failed``: the shared-memory transport
    fell back to UDP), and a child process started without a log file inherits descriptor 1
    too. Either would break ``json.loads`` of the command's output. Inside this block
    descriptor 1 is the process's stderr and ``sys.stdout`` writes to the real stdout, so
    the answer is the only thing there. Nothing happens unless ``sys.stdout`` is descriptor
    1 (a caller that captures ``sys.stdout``, as pytest's ``capsys``, keeps what it has).
    """
    try:
        swap = enabled and sys.stdout.fileno() == 1
    except (AttributeError, OSError, ValueError):   # a stream with no descriptor
        swap = False
    if not swap:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    python_stdout = sys.stdout
    sys.stdout = open(saved, 'w', encoding=python_stdout.encoding, errors=python_stdout.errors,
                      closefd=False, buffering=1)
    try:
        yield
    finally:
        sys.stdout.close()
        sys.stdout = python_stdout
        os.dup2(saved, 1)
        os.close(saved)


def main(argv: list[str] | None = None) -> int:
    ensure_local_discovery()       # DDS on loopback unless the user chose a range
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, '_module', None):
        parser.print_help()
        return 2
    with answer_only_on_stdout(bool(getattr(args, 'json', False))):
        return int(args._module.run(args) or 0)


if __name__ == '__main__':
    sys.exit(main())
