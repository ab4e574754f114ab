"""One owner per concept: scan the package source and fail when a second owner appears.

In the style of python-control's ``kwargs_test.py``: instead of trusting review to
notice a copied list, the test reads every module of ``grip_force_ros`` (``ast``, no
import) and names each place that defines again what another module owns:

| concept | owner |
|---|---|
| object kinds ('free', 'rigid', 'tissue', 'needle') | ``grip_force_ros/objects.py`` |
| effect names | ``grip_force_ros/effects.py`` (the effect registry) |
| controller input sources | ``grip_force_ros/control/inputs.py`` (``SOURCES``) |
| QoS profiles (``QoSProfile(...)``) | ``grip_force_ros/nodes/common.py`` |
| the instrument file and its lookup | ``grip_force_ros/params/files.py`` |
| the parameter Markdown table | ``grip_force_ros/params/schema.py`` (``markdown_table``) |
| the loopback discovery setting | see :data:`DISCOVERY_RANGE_PLACES` |

A "literal list" is a tuple, list or set display holding at least :data:`MIN_NAMES`
names of one vocabulary (a pair like ``('instrument', 'actuator')`` is a choice, not a
list of the vocabulary). Docstrings are prose and are not scanned.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest
from _ast_tools import docstring_ids

from grip_force_ros.control.inputs import SOURCES
from grip_force_ros.effects import EFFECT_NAMES
from grip_force_ros.objects import OBJECTS
from grip_force_ros.params.files import DEFAULT_INSTRUMENT, SUFFIX

PACKAGE = Path(__file__).resolve().parents[1] / 'grip_force_ros'
#: Names of one vocabulary in one literal that make it a list of that vocabulary.
MIN_NAMES = 3

#: vocabulary name -> (its names, the module that owns them, relative to grip_force_ros/)
VOCABULARIES = {
    'object kinds': (OBJECTS, 'objects.py'),
    'effect names': (EFFECT_NAMES, 'effects.py'),
    'input sources': (SOURCES, 'control/inputs.py'),
}

#: The one module that sets ROS_AUTOMATIC_DISCOVERY_RANGE (``ros_environment`` and
#: ``ensure_local_discovery``); an entry that no longer sets it fails below too.
DISCOVERY_RANGE_PLACES = {'lab/processes.py'}


def _modules() -> dict[str, ast.Module]:
    """Relative path (posix) -> parsed module, for every .py file of the package."""
    return {p.relative_to(PACKAGE).as_posix(): ast.parse(p.read_text(encoding='utf-8'), str(p))
            for p in sorted(PACKAGE.rglob('*.py'))}


MODULES = _modules()


def _strings(tree: ast.Module):
    """(line, text) of every string constant that is not a docstring."""
    skip = docstring_ids(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            yield node.lineno, node.value


def _places(predicate) -> list[str]:
    """'path:line' of every node of the package for which ``predicate(path, node)`` holds."""
    return [f'{path}:{node.lineno}' for path, tree in MODULES.items() for node in ast.walk(tree)
            if predicate(path, node)]


def test_the_scan_sees_the_package():
    assert len(MODULES) > 50 and 'params/files.py' in MODULES and 'effects.py' in MODULES


@pytest.mark.parametrize('vocabulary', list(VOCABULARIES))
def test_a_vocabulary_is_listed_only_by_its_owner(vocabulary):
    names, owner = VOCABULARIES[vocabulary]

    def is_list(path, node):
        if path == owner or not isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return False
        found = {e.value for e in node.elts if isinstance(e, ast.Constant) and e.value in names}
        return len(found) >= MIN_NAMES

    assert MODULES[owner] is not None
    places = _places(is_list)
    assert not places, (f'{vocabulary} listed again at {places}: import them from '
                        f'grip_force_ros/{owner} instead')


def test_qos_profiles_are_built_only_in_nodes_common():
    def builds_qos(path, node):
        if path == 'nodes/common.py' or not isinstance(node, ast.Call):
            return False
        f = node.func
        return (isinstance(f, ast.Name) and f.id == 'QoSProfile') or \
            (isinstance(f, ast.Attribute) and f.attr == 'QoSProfile')

    places = _places(builds_qos)
    assert not places, f'QoSProfile(...) at {places}: name the profile in grip_force_ros/nodes/common.py'


def test_the_instrument_file_is_named_and_found_only_in_params_files():
    default_file = DEFAULT_INSTRUMENT + SUFFIX
    named = [f'{path}:{line}' for path, tree in MODULES.items() if path != 'params/files.py'
             for line, text in _strings(tree) if default_file in text]
    assert not named, (f'{default_file!r} named at {named}: use params.files.instrument_path() '
                       'or DEFAULT_INSTRUMENT')

    def finds_share(path, node):
        return path != 'params/files.py' and isinstance(node, ast.Name) and \
            node.id == 'get_package_share_directory'

    def imports_share(path, node):
        return path != 'params/files.py' and isinstance(node, ast.ImportFrom) and \
            any(a.name == 'get_package_share_directory' for a in node.names)

    finders = _places(finds_share) + _places(imports_share)
    assert not finders, f'a second config finder at {finders}: use grip_force_ros.params.files'


def test_the_parameter_table_is_generated_only_by_the_schema():
    header = '| name | group |'
    places = [f'{path}:{line}' for path, tree in MODULES.items() if path != 'params/schema.py'
              for line, text in _strings(tree) if text.startswith(header)]
    assert not places, f'a second parameter table at {places}: use params.markdown_table'


def test_discovery_range_is_set_only_in_the_known_places():
    setting = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
    places = {path for path, tree in MODULES.items()
              for _, text in _strings(tree) if setting in text}
    new = sorted(places - DISCOVERY_RANGE_PLACES)
    gone = sorted(DISCOVERY_RANGE_PLACES - places)
    assert not new, f'{setting} set again in {new}: use the one owner of the loopback setting'
    assert not gone, f'{setting} no longer set in {gone}: remove them from DISCOVERY_RANGE_PLACES'
