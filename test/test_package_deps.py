"""package.xml declares every dependency the package and its tests import, by rosdep key."""
from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Top-level import name -> rosdep key. None: no rosdep key exists; the name is then
#: installed with pip (requirements.txt) and package.xml says so in a comment.
ROSDEP_KEYS = {
    'rclpy': 'rclpy',
    'crtk_msgs': 'crtk_msgs',           # the dvrk interface profile (imported lazily)
    'control_msgs': 'control_msgs',     # the controller's grasp actions (imported lazily)
    'action_msgs': 'action_msgs',       # test/test_grip_action.py: GoalStatus
    'builtin_interfaces': 'builtin_interfaces',
    'rcl_interfaces': 'rcl_interfaces',
    'sensor_msgs': 'sensor_msgs',
    'geometry_msgs': 'geometry_msgs',
    'diagnostic_msgs': 'diagnostic_msgs',
    'std_srvs': 'std_srvs',
    'ament_index_python': 'ament_index_python',
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'matplotlib': 'python3-matplotlib',
    'yaml': 'python3-yaml',
    'psutil': 'python3-psutil',
    'control': None,                 # python-control
    'rosbags': None,
    'pytest': 'python3-pytest',
    'hypothesis': 'python3-hypothesis',
    'setuptools': 'python3-setuptools',
    'launch': 'launch',
    'launch_ros': 'launch_ros',
}
#: PyPI name of each import without a rosdep key (as pinned in requirements.txt).
PIP_NAMES = {'control': 'control', 'rosbags': 'rosbags'}
#: Declared keys no import names, and why they are needed.
NOT_IMPORTED = {
    'std_msgs': 'the Header of every stamped message',
    'python3-pytest-timeout': "pytest.ini's --timeout",
    'python3-colcon-common-extensions': 'test/test_colcon_build.py runs colcon',
    'ros2launch': 'the `ros2 launch` verb of launch/*.launch.py',
    'ros2action': 'the `ros2 action` verb of test/test_grip_action.py',
}
RUNTIME_TAGS = ('depend', 'exec_depend')
TEST_TAGS = RUNTIME_TAGS + ('test_depend',)
BUILD_TAGS = ('buildtool_depend', 'build_depend', 'depend')


def third_party_imports(*paths: Path, root: Path = ROOT) -> dict[str, set[str]]:
    """Top-level names imported (anywhere in a file) that are neither stdlib nor ours.

    Returns
    -------
    dict
        Import name -> the files (relative to ``root``) that import it.
    """
    files = [f for p in paths for f in ([p] if p.is_file() else sorted(p.rglob('*.py')))]
    local = {'grip_force_ros', 'conftest'} | {f.stem for f in (ROOT / 'test').glob('*.py')}
    found: dict[str, set[str]] = {}
    for f in files:
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top not in sys.stdlib_module_names and top not in local:
                    found.setdefault(top, set()).add(str(f.relative_to(root)))
    return found


def declared() -> dict[str, set[str]]:
    """package.xml: dependency tag -> the keys it declares."""
    out: dict[str, set[str]] = {}
    for element in ET.parse(ROOT / 'package.xml').getroot():
        if element.tag.endswith('depend'):
            out.setdefault(element.tag, set()).add(element.text.strip())
    return out


def keys_in(tags: tuple[str, ...]) -> set[str]:
    deps = declared()
    return set().union(*(deps.get(tag, set()) for tag in tags))


def check(imports: dict[str, set[str]], tags: tuple[str, ...]) -> list[str]:
    """Problems: imports without a table entry, keys not declared under ``tags``, pip-only
    names not pinned in requirements.txt or not explained in a package.xml comment."""
    keys = keys_in(tags)
    text = (ROOT / 'package.xml').read_text()
    comments = ' '.join(re.findall(r'<!--(.*?)-->', text, re.S))
    pinned = {re.split(r'[\[=<>~ ]', line.strip())[0].lower()
              for line in (ROOT / 'requirements.txt').read_text().splitlines()
              if line.strip() and not line.startswith('#')}
    problems = []
    for name, files in sorted(imports.items()):
        where = ', '.join(sorted(files)[:3])
        if name not in ROSDEP_KEYS:
            problems.append(f'{name} (imported by {where}) has no rosdep key in ROSDEP_KEYS: '
                            'declare it in package.xml and add it to the table')
        elif ROSDEP_KEYS[name] is None:
            pip = PIP_NAMES[name]
            if pip not in pinned:
                problems.append(f'{name}: no rosdep key, and {pip} is not in requirements.txt')
            if pip not in comments:
                problems.append(f'{name}: no rosdep key, and no package.xml comment says so')
        elif ROSDEP_KEYS[name] not in keys:
            problems.append(f'{name} (imported by {where}): {ROSDEP_KEYS[name]} is not declared '
                            f'as one of {tags} in package.xml')
    return problems


def test_every_import_of_the_package_is_a_declared_runtime_dependency():
    imports = third_party_imports(ROOT / 'grip_force_ros', ROOT / 'launch')
    assert {'rclpy', 'numpy', 'control', 'rosbags'} <= set(imports)      # the scan sees them
    assert check(imports, RUNTIME_TAGS) == []


def test_every_import_of_the_tests_is_declared_for_them():
    imports = third_party_imports(ROOT / 'test')
    assert {'pytest', 'hypothesis'} <= set(imports)
    assert check(imports, TEST_TAGS) == []


def test_the_build_script_imports_are_build_dependencies():
    imports = third_party_imports(ROOT / 'setup.py')
    assert set(imports) == {'setuptools'}
    assert check(imports, BUILD_TAGS) == []


def test_every_declared_key_is_used():
    used = {ROSDEP_KEYS.get(name) for name in third_party_imports(
        ROOT / 'grip_force_ros', ROOT / 'launch', ROOT / 'test', ROOT / 'setup.py')}
    unused = keys_in(BUILD_TAGS + TEST_TAGS) - used - set(NOT_IMPORTED)
    assert unused == set(), f'declared in package.xml but imported nowhere: {sorted(unused)}'


def test_the_check_finds_an_undeclared_import(tmp_path):
    module = tmp_path / 'uses_pandas.py'
    module.write_text('import os\nimport numpy\n\n\ndef f():\n    from pandas.api import types\n')
    imports = third_party_imports(module, root=tmp_path)
    assert imports == {'numpy': {'uses_pandas.py'}, 'pandas': {'uses_pandas.py'}}
    problems = check(imports, RUNTIME_TAGS)
    assert len(problems) == 1 and problems[0].startswith('pandas (imported by uses_pandas.py)')
