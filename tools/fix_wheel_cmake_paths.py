"""Repoint the Python include paths baked into the ROS 2 wheels' CMake files.

The Jazzy wheels on PyPI were built in a manylinux container whose Python lives in
``/opt/python/cp3XX-cp3XX``; about 20 exported ``*.cmake`` files (the
``rosidl_generator_py`` targets of every message package) name its include
directory and numpy's include directory under that prefix. CMake refuses an
imported target whose include directory does not exist, so building any message
package against the wheels (crtk_msgs, composition_interfaces) fails until those
paths name this interpreter's directories.

Run it with the virtual environment's Python: ``.venv/bin/python
tools/fix_wheel_cmake_paths.py [PREFIX]`` (PREFIX defaults to ``sys.prefix``).
Idempotent: a second run finds nothing to change. Only ``*.cmake`` files under
``PREFIX/share`` and ``PREFIX/lib`` are touched; it prints how many it rewrote.
"""
from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

#: The build container's interpreter prefix, as the wheels spell it.
BUILD_PREFIX = re.compile(r'/opt/python/cp3\d+-cp3\d+')


def replacements() -> list[tuple[re.Pattern, str]]:
    """(pattern, this interpreter's path): numpy's include first, then Python's."""
    import numpy
    numpy_include = numpy.get_include()
    python_include = sysconfig.get_paths()['include']
    return [
        (re.compile(BUILD_PREFIX.pattern + r'/lib/python3\.\d+/site-packages/numpy/_core/include'),
         numpy_include),
        (re.compile(BUILD_PREFIX.pattern + r'/lib/python3\.\d+/site-packages/numpy/core/include'),
         numpy_include),
        (re.compile(BUILD_PREFIX.pattern + r'/include/python3\.\d+'), python_include),
    ]


def fix(prefix: Path) -> list[Path]:
    """Rewrite the CMake files under ``prefix``; return the ones that changed."""
    rules = replacements()
    changed = []
    for top in (prefix / 'share', prefix / 'lib'):
        if not top.is_dir():
            continue
        for path in sorted(top.rglob('*.cmake')):
            if path.is_symlink() or not path.is_file():
                continue
            text = path.read_text(encoding='utf-8', errors='surrogateescape')
            if not BUILD_PREFIX.search(text):
                continue
            new = text
            for pattern, repl in rules:
                new = pattern.sub(repl.replace('\\', r'\\'), new)
            if new != text:
                path.write_text(new, encoding='utf-8', errors='surrogateescape')
                changed.append(path)
    return changed


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    prefix = Path(argv[0]) if argv else Path(sys.prefix)
    changed = fix(prefix)
    print(f'fix_wheel_cmake_paths: {len(changed)} CMake file(s) repointed under {prefix}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
