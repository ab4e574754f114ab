"""The one parameter schema of grip_force_ros.

>>> from grip_force_ros.params import load_params_file
>>> p = load_params_file('config/paper_needle_driver.yaml')   # doctest: +SKIP
>>> p.drum_radius                                              # doctest: +SKIP
0.004

Groups: 'instrument' (model geometry and materials, the dVRK's jaw conversion), 'limits'
(hardware limits, read-only), 'controller', 'sim', 'effects' (optional unmodelled effects
of the simulated instrument, all off by default), 'interface' (the topic profile, crtk or
dvrk, and the dVRK arm and master names; params/interface.py, which also holds the
defaults a profile changes), 'realtime' (memory locking and CPU affinity of the 1 kHz node
processes; params/realtime.py). Where the instrument files
are: :mod:`grip_force_ros.params.files` (``instrument_path``, ``list_instruments``).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from grip_force_ros.params.controller import CONTROLLER, check_controller
from grip_force_ros.params.files import DEFAULT_INSTRUMENT, instrument_path, list_instruments
from grip_force_ros.params.instrument import INSTRUMENT, LIMITS
from grip_force_ros.params.interface import (DVRK_CONTROLLER, INTERFACE, check_interface,
                                             with_profile_defaults)
from grip_force_ros.params.realtime import REALTIME
from grip_force_ros.params.schema import ParameterError, ParamSpec, markdown_table, validate
from grip_force_ros.params.sim import EFFECTS, SIM, check_sim

SCHEMA: tuple[ParamSpec, ...] = tuple(INSTRUMENT + LIMITS + CONTROLLER + DVRK_CONTROLLER + SIM
                                      + EFFECTS + INTERFACE + REALTIME)
SPECS: dict[str, ParamSpec] = {s.name: s for s in SCHEMA}
if len(SPECS) != len(SCHEMA):  # pragma: no cover - a programming error
    raise RuntimeError('duplicate parameter name in the schema')

__all__ = ['SCHEMA', 'SPECS', 'ParamSpec', 'ParamSet', 'ParameterError', 'make_params',
           'load_params_file', 'read_params_yaml', 'rewrite_instrument_file', 'specs_in', 'to_yaml',
           'check_consistency',
           'DEFAULT_INSTRUMENT', 'instrument_path', 'list_instruments', 'markdown_table']


class ParamSet(Mapping):
    """Validated parameter values with attribute access (``p.drum_radius``).

    Immutable. Build one with :func:`make_params` or :func:`load_params_file`; derive a
    changed copy with :meth:`replace`.
    """

    __slots__ = ('_values',)

    def __init__(self, values: Mapping[str, Any]):
        object.__setattr__(self, '_values', dict(values))

    def __getattr__(self, name: str) -> Any:
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f'no parameter {name!r}') from None

    def __setattr__(self, name, value):
        raise AttributeError('ParamSet is immutable; use replace()')

    def __getitem__(self, key: str) -> Any:
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def replace(self, **changes: Any) -> 'ParamSet':
        """Return a validated copy with ``changes`` applied."""
        return make_params({**self._values, **changes})

    def __repr__(self) -> str:
        return f'ParamSet({self._values!r})'


def specs_in(*groups: str) -> list[ParamSpec]:
    """Return the specs of the given groups (all groups if none given)."""
    return [s for s in SCHEMA if not groups or s.group in groups]


def make_params(values: Mapping[str, Any] | None = None, *,
                allow_unknown: bool = False) -> ParamSet:
    """Validate ``values`` (defaults for what is missing) into a :class:`ParamSet`.

    What is missing takes the default of the values' ``interface`` profile where it has
    one (:data:`~grip_force_ros.params.interface.PROFILE_DEFAULTS`), else the schema's.

    Raises
    ------
    ParameterError
        Naming the key, the value and the allowed range.
    """
    values = dict(values or {})
    if isinstance(values.get('interface'), str):
        values = with_profile_defaults(values, SPECS)
    checked = validate(SCHEMA, values, allow_unknown=allow_unknown)
    check_consistency(checked)
    return ParamSet(checked)


def check_consistency(values: Mapping[str, Any]) -> None:
    """Cross-parameter checks that per-key ranges cannot express.

    Raises
    ------
    ParameterError
        Naming the keys and values (e.g. a cable thicker than a pulley).
    """
    radii, wraps = values['guide_pulley_radii'], values['guide_pulley_wrap_angles']
    if len(radii) != len(wraps):
        raise ParameterError(
            f"'guide_pulley_radii' has {len(radii)} entries but 'guide_pulley_wrap_angles' has "
            f'{len(wraps)}; give one radius and one wrap angle per guide pulley')
    if values['cable_radius'] >= min(radii):
        raise ParameterError(
            f"'cable_radius' {values['cable_radius']} m must be smaller than every guide pulley "
            f"radius (smallest 'guide_pulley_radii' = {min(radii)} m)")
    if values['jaw_angle_min'] >= values['jaw_angle_max']:
        raise ParameterError(f"'jaw_angle_min' {values['jaw_angle_min']} rad must be below "
                             f"'jaw_angle_max' {values['jaw_angle_max']} rad")
    check_controller(values)
    check_sim(values)
    check_interface(values)


def read_params_yaml(path: str | Path) -> dict[str, Any]:
    """Read the ``ros__parameters`` of a ROS parameter file without validating.

    Accepts ``/**:`` or any single node name as the top-level key.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f'{path}: cannot read parameter file: {exc}') from exc
    if not isinstance(doc, dict) or not doc:
        raise ParameterError(f'{path}: not a ROS parameter file (expected "/**: ros__parameters: ...")')
    values: dict[str, Any] = {}
    for node, body in doc.items():
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ParameterError(f'{path}: section {node!r} has no "ros__parameters" mapping')
        values.update(body['ros__parameters'])
    return values


def load_params_file(path: str | Path, **overrides: Any) -> ParamSet:
    """Load and validate an instrument YAML (ROS ``/**: ros__parameters:`` format).

    Raises
    ------
    ParameterError
        One clear message with the file, the key, the value and the range.
    """
    values = read_params_yaml(path)
    values.update(overrides)
    try:
        return make_params(values)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from None


def to_yaml(params: Mapping[str, Any], groups: Iterable[str] = ('instrument', 'limits'),
            header: str = '') -> str:
    """Render parameters as a ROS parameter file (``/**: ros__parameters:``)."""
    body = {}
    for spec in specs_in(*groups):
        value = params.get(spec.name, spec.default)
        body[spec.name] = list(value) if isinstance(value, tuple) else value
    text = yaml.safe_dump({'/**': {'ros__parameters': body}}, sort_keys=False)
    return (header + text) if header else text


#: One parameter line of an instrument file: indent, key, value, comment.
_LINE = re.compile(r'^(?P<indent>\s+)(?P<key>\w+):\s*(?P<value>[^#\n]*?)\s*(#.*)?$')


def rewrite_instrument_file(base: str | Path, out: str | Path,
                            values: Mapping[str, tuple], header: str, *, replaces: str = '') -> None:
    """Write ``out``: the instrument file ``base`` with some parameters' values replaced.

    The line of each replaced parameter gets its new value and, as its comment, the unit
    and the value's source (as in the shipped files); a parameter the base does not have
    is added after the others; every other line stays as it is. ``header`` becomes the
    first line (a comment), replacing any line of the base that starts with ``replaces``.
    The result is validated against the schema before it replaces ``out``.

    Parameters
    ----------
    base, out : path-like
        The instrument YAML read, and the one written (its folder is made).
    values : mapping of str to (value, str)
        Parameter name -> (new value, where it comes from).
    header : str
        A comment line (starting with ``#``) saying how the file was made.
    replaces : str, optional
        Lines of the base starting with this are dropped (an earlier header of the same tool).

    Raises
    ------
    ParameterError
        The result is invalid (``out`` is then left as it was).
    """
    base, out = Path(base), Path(out)
    lines = [ln for ln in base.read_text().splitlines() if not (replaces and ln.startswith(replaces))]

    def line(indent: str, key: str) -> str:
        value, source = values[key]
        return f"{indent}{f'{key}: {value!r}':<34} # {SPECS[key].unit:<7} {source}"

    done = set()
    for i, text in enumerate(lines):
        m = _LINE.match(text)
        if m and m['key'] in values:
            lines[i] = line(m['indent'], m['key'])
            done.add(m['key'])
    # a new key goes with the parameters: the deepest indent (not ros__parameters' own)
    indent = max((m['indent'] for m in map(_LINE.match, lines) if m), key=len, default='    ')
    lines += [line(indent, key) for key in values if key not in done]
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + '.tmp')
    tmp.write_text('\n'.join([header] + lines) + '\n')
    try:
        load_params_file(tmp)
    except ParameterError:
        tmp.unlink()
        raise
    tmp.replace(out)
