"""Who may import what (docs/ARCHITECTURE.md, "Who owns what, who may import what")."""
from __future__ import annotations

import ast
from pathlib import Path

from _ast_tools import docstring_ids

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / 'grip_force_ros'
#: The laboratory (docs/ARCHITECTURE.md): everything under grip_force_ros/lab/.
LAB = PACKAGE / 'lab'

#: Part of the package -> the parts it may import (docs/ARCHITECTURE.md, same table). The
#: product's parts are the top-level modules and subpackages of grip_force_ros/, the
#: laboratory's those of grip_force_ros/lab/ ('lab.bench' for lab/bench/, 'lab.processes'
#: for lab/processes.py).
MAY_IMPORT = {
    # the product: what ships in a robot
    'objects': set(),
    'effects': set(),
    'params': {'objects', 'effects'},
    'topics': set(),
    'model': {'objects', 'effects', 'params'},
    'logs': {'objects', 'effects', 'topics'},
    'trajectories': {'objects', 'effects', 'params', 'topics'},
    'control': {'objects', 'effects', 'model', 'params'},
    'sim': {'objects', 'effects', 'model', 'params'},
    'identify': {'objects', 'effects', 'model', 'params', 'logs'},
    'nodes': {'objects', 'effects', 'control', 'identify', 'model', 'sim', 'trajectories', 'params',
              'topics'},
    # the laboratory: everything around it
    'lab.plotting': set(),
    'lab.closed_loop': {'control'},
    'lab.tune': {'objects', 'effects', 'control', 'model', 'params'},
    'lab.node_process': {'nodes'},
    'lab.processes': {'lab.node_process'},
    'lab.harness': {'nodes', 'lab.processes'},
    'lab.rig': {'model', 'params', 'lab.plotting'},      # params: an instrument twin's file
    'lab.diagnosis': {'objects', 'effects', 'model', 'sim', 'identify', 'logs', 'params', 'lab.plotting'},
    'lab.reproduce': {'objects', 'effects', 'model', 'params', 'lab.plotting'},
    'lab.figures': {'objects', 'effects', 'model', 'control', 'sim', 'lab.closed_loop', 'trajectories',
                    'params', 'lab.plotting', 'topics'},
    'lab.demo': {'objects', 'effects', 'nodes', 'lab.processes', 'lab.harness', 'control', 'identify',
                 'model', 'logs', 'trajectories', 'params', 'topics', 'lab.plotting'},
    'lab.faults': {'objects', 'effects', 'nodes', 'lab.processes', 'lab.harness', 'control', 'model', 'sim',
                   'params', 'topics'},
    'lab.bench': {'nodes', 'lab.node_process', 'lab.processes', 'lab.harness', 'control', 'model', 'sim',
                  'lab.closed_loop', 'lab.diagnosis', 'logs', 'params', 'topics', 'objects', 'effects',
                  'lab.demo', 'trajectories'},
    'lab.cli': None,                                   # the command: anything
}
PRODUCT = {part for part in MAY_IMPORT if not part.startswith('lab.')}
#: The only parts that import rclpy or ROS message packages.
ROS_PARTS = {'nodes', 'lab.harness', 'lab.demo', 'lab.faults', 'lab.bench'}
ROS_MODULES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'sensor_msgs',
               'geometry_msgs', 'diagnostic_msgs', 'crtk_msgs', 'std_srvs', 'lifecycle_msgs'}


def part_name(dotted: str) -> str | None:
    """'control' for grip_force_ros.control.pid, 'lab.bench' for grip_force_ros.lab.bench.loop,
    'lab' for grip_force_ros.lab itself; None outside the package."""
    parts = dotted.split('.')
    if parts[0] != 'grip_force_ros' or len(parts) < 2:
        return None
    if parts[1] == 'lab':
        return f'lab.{parts[2]}' if len(parts) > 2 else 'lab'
    return parts[1]


def part_of(path: Path) -> str:
    """'control' for grip_force_ros/control/pid.py, 'topics' for grip_force_ros/topics.py,
    'lab.bench' for grip_force_ros/lab/bench/loop.py, 'lab.plotting' for lab/plotting.py."""
    return part_name(module_name(path))


def package_files() -> list[Path]:
    """Every module of the package but the two package docstrings (grip_force_ros/ and lab/)."""
    return [p for p in sorted(PACKAGE.rglob('*.py'))
            if not (p.parent in (PACKAGE, LAB) and p.stem == '__init__')]


def imported(path: Path, tree: ast.Module | None = None) -> list[tuple[int, str]]:
    """(line, dotted name) of every import in ``path``, inside functions too; relative
    imports resolved; ``from grip_force_ros import topics`` gives 'grip_force_ros.topics',
    ``from grip_force_ros.lab import plotting`` 'grip_force_ros.lab.plotting'."""
    tree = ast.parse(path.read_text(), str(path)) if tree is None else tree
    here = module_name(path).split('.') if path.is_relative_to(PACKAGE) else []
    package = here if path.stem == '__init__' else here[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                base = '.'.join(package[:len(package) - node.level + 1] + ([base] if base else []))
            if base in ('grip_force_ros', 'grip_force_ros.lab') or (node.level and not node.module):
                out += [(node.lineno, f'{base}.{alias.name}') for alias in node.names]
            elif base:
                out.append((node.lineno, base))
    return out


def edges() -> list[tuple[str, str, str]]:
    """(importing part, imported part, 'file:line') for every import between parts."""
    out = []
    for path in package_files():
        src = part_of(path)
        for line, name in imported(path):
            dst = part_name(name)
            if dst is not None and dst != src:
                out.append((src, dst, f'{path.relative_to(ROOT)}:{line}'))
    return out


def uses_of_the_lab(path: Path, source: str | None = None) -> list[str]:
    """'file:line: name' of every use of the laboratory in ``path``: an import of
    grip_force_ros.lab (at the top or in a function, absolute or relative), or a string that
    names one of its modules (``python -m grip_force_ros.lab.cli``, ``import_module``).
    Docstrings and comments are prose, not uses."""
    source = path.read_text() if source is None else source
    tree = ast.parse(source, str(path))
    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    found = [(line, name) for line, name in imported(path, tree)
             if name == 'grip_force_ros.lab' or name.startswith('grip_force_ros.lab.')]
    skip = docstring_ids(tree)
    found += [(node.lineno, node.value) for node in ast.walk(tree)
              if isinstance(node, ast.Constant) and isinstance(node.value, str)
              and id(node) not in skip and 'grip_force_ros.lab' in node.value]
    return [f'{where}:{line}: {name}' for line, name in sorted(found)]


def module_name(path: Path) -> str:
    """'grip_force_ros.lab.faults.dvrk' for lab/faults/dvrk.py, 'grip_force_ros.lab.faults' for
    lab/faults/__init__.py."""
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def module_graph() -> dict[str, set[str]]:
    """Module of the package -> the package's modules it imports (at the top or in a function).

    ``from grip_force_ros.lab.faults import runner`` imports the module
    ``grip_force_ros.lab.faults.runner``; ``from grip_force_ros.lab.faults.catalogue import
    FaultCase`` the module ``grip_force_ros.lab.faults.catalogue``.
    A package's ``__init__`` is a module of its own; importing a submodule runs it too, but that
    implicit step is left out (every ``__init__`` that re-exports its submodules would close a loop).
    """
    paths = {module_name(p): p for p in PACKAGE.rglob('*.py')}
    graph = {}
    for name, path in paths.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets |= {f'{node.module}.{alias.name}' if f'{node.module}.{alias.name}' in paths
                            else node.module for alias in node.names}
        graph[name] = {t for t in targets if t in paths and t != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One import loop per strongly connected component of ``graph`` with more than one module."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):                                   # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_package_has_no_import_cycle():
    graph = module_graph()
    assert len(graph) > 100 and 'grip_force_ros.lab.faults.dvrk' in graph['grip_force_ros.lab.faults.runner']
    assert cycles(graph) == []


def test_the_cycle_check_finds_a_loop():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}
    assert cycles(graph) == [['a', 'b', 'c']]


def product_files() -> list[Path]:
    """The product's modules (grip_force_ros/ outside lab/) and its launch files."""
    return [p for p in sorted(PACKAGE.rglob('*.py')) if not p.is_relative_to(LAB)] + \
        sorted((ROOT / 'launch').glob('*.launch.py'))


def test_the_product_never_imports_the_laboratory():
    files = product_files()
    assert PACKAGE / 'nodes' / 'controller.py' in files and ROOT / 'launch' / 'grasp.launch.py' in files
    assert not any(p.is_relative_to(LAB) for p in files)
    wrong = [use for path in files for use in uses_of_the_lab(path)]
    assert wrong == [], 'the product uses the laboratory (move what it needs to the product)'


def test_the_laboratory_check_finds_every_kind_of_use():
    source = """\"\"\"Prose may name grip_force_ros.lab.cli.\"\"\"
import grip_force_ros.lab.bench.run
from grip_force_ros import lab, topics
from grip_force_ros.lab import plotting
from ..lab.processes import NodeProcess
from . import common


def fit():
    from grip_force_ros.lab.cli import main
    return ['python', '-m', 'grip_force_ros.lab.cli', 'calibrate']
"""
    where = PACKAGE / 'nodes' / 'example.py'
    uses = [use.split(': ', 1)[1] for use in uses_of_the_lab(where, source)]
    assert uses == ['grip_force_ros.lab.bench.run', 'grip_force_ros.lab', 'grip_force_ros.lab.plotting',
                    'grip_force_ros.lab.processes', 'grip_force_ros.lab.cli', 'grip_force_ros.lab.cli']


def test_every_part_is_in_the_table():
    assert {part_of(p) for p in package_files()} == set(MAY_IMPORT)
    assert LAB.is_dir() and {'nodes', 'control', 'model', 'params', 'identify'} <= PRODUCT
    assert not (PRODUCT & {'plotting', 'closed_loop', 'demo', 'faults', 'bench', 'cli'})


def test_the_table_lets_the_product_import_only_the_product():
    wrong = {part: MAY_IMPORT[part] - PRODUCT for part in PRODUCT if MAY_IMPORT[part] - PRODUCT}
    assert wrong == {}


def test_parts_import_only_what_the_architecture_allows():
    wrong = [f'{where}: {src} imports {dst}' for src, dst, where in edges()
             if MAY_IMPORT[src] is not None and dst not in MAY_IMPORT[src]]
    assert wrong == []


def test_control_imports_only_the_model_and_the_schema():
    used = {dst for src, dst, _ in edges() if src == 'control'}
    assert 'model' in used and used <= {'model', 'params'}


def test_rclpy_and_messages_only_in_the_ros_parts():
    wrong = []
    for path in package_files():
        for line, name in imported(path):
            if name.split('.')[0] in ROS_MODULES and part_of(path) not in ROS_PARTS:
                wrong.append(f'{path.relative_to(ROOT)}:{line}: {name}')
    assert wrong == []


def test_process_launching_has_no_rclpy():
    for path in (LAB / 'processes.py', LAB / 'node_process.py'):
        names = {name.split('.')[0] for _, name in imported(path)}
        assert not names & ROS_MODULES, path
