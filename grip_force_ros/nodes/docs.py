"""Regenerate the parameter tables of docs/ros_interface.md from the schema.

    .venv/bin/python -m grip_force_ros.nodes.docs            # rewrite the tables in place
    .venv/bin/python -m grip_force_ros.nodes.docs --check    # exit 1 if they are out of date

Everything after the marker line :data:`MARKER` is generated; the text above it
is written by hand.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grip_force_ros.params import markdown_table, specs_in
from grip_force_ros.trajectories import MASTER_SPECS

DOC = Path(__file__).resolve().parents[2] / 'docs' / 'ros_interface.md'
MARKER = '<!-- generated below by `python -m grip_force_ros.nodes.docs`: do not edit by hand -->'
GROUPS = ('instrument', 'limits', 'controller', 'sim', 'effects', 'interface', 'realtime')


def generated() -> str:
    parts = [MARKER, '']
    for group in GROUPS:
        parts += [f'### Group `{group}`', '', markdown_table(specs_in(group)), '']
    parts += ['### Group `master` (node `master` only)', '',
              'Declared in `grip_force_ros/trajectories.py` (`MASTER_SPECS`), next to the '
              'trajectories they configure.', '', markdown_table(MASTER_SPECS), '']
    return '\n'.join(parts)


def render(text: str) -> str:
    """``text`` with everything after the marker regenerated."""
    head = text.split(MARKER)[0].rstrip('\n')
    return head + '\n\n' + generated()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--check', action='store_true', help='exit 1 if the tables are stale')
    args = parser.parse_args(argv)
    text = DOC.read_text()
    new = render(text)
    if args.check:
        if new != text:
            print(f'{DOC}: parameter tables are out of date; run python -m grip_force_ros.nodes.docs',
                  file=sys.stderr)
            return 1
        return 0
    DOC.write_text(new)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
