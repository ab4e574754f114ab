"""Who may import what (docs/ARCHITECTURE.md, "Who owns what, who may import what")."""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'grip_force_ros'

#: Part of the package -> the parts it may import (docs/ARCHITECTURE.md, same table).
MAY_IMPORT = {
    'objects': set(),
    'effects': set(),
    'params': {'objects', 'effects'},
    'topics': set(),
    'plotting': set(),
    'model': {'objects', 'effects', 'params'},
    'logs': {'objects', 'effects', 'topics'},
    'trajectories': {'objects', 'effects', 'params', 'topics'},
    'control': {'objects', 'effects', 'model', 'params'},
    'sim': {'objects', 'effects', 'model', 'params'},
    'closed_loop': {'control'},
    'identify': {'objects', 'effects', 'model', 'params', 'logs'},
    'rig': {'plotting'},
    'diagnosis': {'objects', 'effects', 'model', 'sim', 'identify', 'logs', 'params', 'plotting'},
    'reproduce': {'objects', 'effects', 'model', 'params', 'plotting'},
    'figures': {'objects', 'effects', 'model', 'control', 'sim', 'closed_loop', 'trajectories', 'params',
                'plotting', 'topics'},
    'nodes': {'objects', 'effects', 'control', 'identify', 'model', 'sim', 'trajectories', 'params',
              'topics'},
    'demo': {'objects', 'effects', 'nodes', 'control', 'identify', 'model', 'logs', 'trajectories',
             'params', 'topics', 'plotting'},
    'faults': {'objects', 'effects', 'nodes', 'control', 'model', 'sim', 'params', 'topics'},
    'bench': {'nodes', 'control', 'model', 'sim', 'closed_loop', 'diagnosis', 'logs', 'params', 'topics',
              'objects', 'effects', 'demo', 'trajectories'},
    'cli': None,                                       # the command: anything
}
#: The only parts that import rclpy or ROS message packages.
ROS_PARTS = {'nodes', 'demo', 'faults', 'bench'}
ROS_MODULES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'sensor_msgs',
               'geometry_msgs', 'diagnostic_msgs', 'crtk_msgs', 'std_srvs', 'lifecycle_msgs'}


def part_of(path: Path) -> str:
    """'control' for grip_force_ros/control/pid.py, 'topics' for grip_force_ros/topics.py."""
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def imported(path: Path) -> list[tuple[int, str]]:
    """(line, dotted name) of every absolute import in ``path``, inside functions too;
    ``from grip_force_ros import topics`` gives 'grip_force_ros.topics'."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == 'grip_force_ros':
                out += [(node.lineno, f'grip_force_ros.{alias.name}') for alias in node.names]
            else:
                out.append((node.lineno, node.module))
    return out


def edges() -> list[tuple[str, str, str]]:
    """(importing part, imported part, 'file:line') for every import between parts."""
    out = []
    for path in sorted(PACKAGE.rglob('*.py')):
        if path.parent == PACKAGE and path.stem == '__init__':
            continue
        src = part_of(path)
        for line, name in imported(path):
            parts = name.split('.')
            if parts[0] == 'grip_force_ros' and len(parts) > 1 and parts[1] != src:
                out.append((src, parts[1], f'{path.relative_to(PACKAGE.parent)}:{line}'))
    return out


def module_name(path: Path) -> str:
    """'grip_force_ros.faults.dvrk' for faults/dvrk.py, 'grip_force_ros.faults' for faults/__init__.py."""
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def module_graph() -> dict[str, set[str]]:
    """Module of the package -> the package's modules it imports (at the top or in a function).

    ``from grip_force_ros.faults import runner`` imports the module ``grip_force_ros.faults.runner``;
    ``from grip_force_ros.faults.catalogue import FaultCase`` the module ``grip_force_ros.faults.catalogue``.
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
    assert len(graph) > 100 and 'grip_force_ros.faults.dvrk' in graph['grip_force_ros.faults.runner']
    assert cycles(graph) == []


def test_the_cycle_check_finds_a_loop():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}
    assert cycles(graph) == [['a', 'b', 'c']]


def test_every_part_is_in_the_table():
    parts = {part_of(p) for p in PACKAGE.rglob('*.py')
             if not (p.parent == PACKAGE and p.stem in ('__init__', '__main__'))}
    assert parts == set(MAY_IMPORT)


def test_parts_import_only_what_the_architecture_allows():
    wrong = [f'{where}: {src} imports {dst}' for src, dst, where in edges()
             if MAY_IMPORT[src] is not None and dst not in MAY_IMPORT[src]]
    assert wrong == []


def test_control_imports_only_the_model_and_the_schema():
    used = {dst for src, dst, _ in edges() if src == 'control'}
    assert 'model' in used and used <= {'model', 'params'}


def test_rclpy_and_messages_only_in_the_ros_parts():
    wrong = []
    for path in sorted(PACKAGE.rglob('*.py')):
        for line, name in imported(path):
            if name.split('.')[0] in ROS_MODULES and part_of(path) not in ROS_PARTS:
                wrong.append(f'{path.relative_to(PACKAGE.parent)}:{line}: {name}')
    assert wrong == []


def test_process_launching_has_no_rclpy():
    names = {name.split('.')[0] for _, name in imported(PACKAGE / 'nodes' / 'processes.py')}
    assert not names & ROS_MODULES
