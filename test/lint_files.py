"""The Python files the linter tests check."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Files left out of the linters (none: every file is checked).
EXCLUDED = ()


def lint_files() -> list[str]:
    """List the .py files the linters check (relative to the repository), without :data:`EXCLUDED`."""
    files = sorted(p.relative_to(ROOT).as_posix() for folder in ('grip_force_ros', 'test', 'launch', 'tools')
                   for p in (ROOT / folder).rglob('*.py'))
    return [f for f in files if f not in EXCLUDED]
