"""The parameter schema mechanism: one declaration per parameter.

Every parameter of the package is declared once, as a :class:`ParamSpec`
(name, type, unit, default, range, description, read-only). From that one list
come the ROS parameter descriptors of the nodes (``nodes/``), the validation of
instrument YAML files, the CLI and the parameter table in the docs. Nothing
else repeats a parameter list.

Values are SI (REP 103): m, rad, N, A, s, kg, Pa.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence


class ParameterError(ValueError):
    """A parameter value is missing, of the wrong type or out of range."""


#: Parameter types, named as in ROS (rcl_interfaces/ParameterType).
TYPES = ('double', 'integer', 'bool', 'string', 'double_array', 'integer_array')


@dataclass(frozen=True)
class ParamSpec:
    """Declaration of one parameter.

    Parameters
    ----------
    name : str
        ROS parameter name (flat, snake_case).
    type : str
        One of :data:`TYPES`.
    default : Any
        Default value (SI units).
    unit : str
        Unit of the value, '' for dimensionless, e.g. 'm', 'N*m/A'.
    description : str
        What it is, and where its default comes from.
    min, max : float, optional
        Inclusive range for 'double', 'integer' and each element of
        'double_array' and 'integer_array'.
    read_only : bool
        Hardware limits and geometry: refused at runtime by the nodes.
    group : str
        'instrument', 'limits', 'controller', 'sim', 'effects', 'interface' or 'realtime'.
    choices : tuple of str, optional
        Allowed values of a 'string' parameter.
    """

    name: str
    type: str
    default: Any
    unit: str
    description: str
    min: float | None = None
    max: float | None = None
    read_only: bool = False
    group: str = 'instrument'
    choices: tuple[str, ...] | None = None

    def check(self, value: Any) -> Any:
        """Return ``value`` normalised to this parameter's type.

        Raises
        ------
        ParameterError
            With the key, the value and the allowed range in the message.
        """
        where = f"parameter '{self.name}'"
        if self.type == 'double':
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParameterError(f'{where}: expected a number ({self.unit or "-"}), got {value!r}')
            value = float(value)
            self._check_range(value, where)
            return value
        if self.type == 'integer':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ParameterError(f'{where}: expected an integer, got {value!r}')
            self._check_range(value, where)
            return value
        if self.type == 'bool':
            if not isinstance(value, bool):
                raise ParameterError(f'{where}: expected true or false, got {value!r}')
            return value
        if self.type == 'string':
            if not isinstance(value, str):
                raise ParameterError(f'{where}: expected a string, got {value!r}')
            if self.choices is not None and value not in self.choices:
                raise ParameterError(f'{where}: {value!r} is not one of {list(self.choices)}')
            return value
        if self.type == 'double_array':
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
                raise ParameterError(f'{where}: expected a list of numbers, got {value!r}')
            out = []
            for i, v in enumerate(value):
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise ParameterError(f"parameter '{self.name}[{i}]': expected a number, got {v!r}")
                self._check_range(float(v), f"parameter '{self.name}[{i}]'")
                out.append(float(v))
            if not out:
                raise ParameterError(f'{where}: the list is empty')
            return tuple(out)
        if self.type == 'integer_array':     # may be empty (e.g. cpu_affinity: no pinning)
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
                raise ParameterError(f'{where}: expected a list of integers, got {value!r}')
            out = []
            for i, v in enumerate(value):
                if isinstance(v, bool) or not isinstance(v, int):
                    raise ParameterError(f"parameter '{self.name}[{i}]': expected an integer, "
                                         f'got {v!r}')
                self._check_range(v, f"parameter '{self.name}[{i}]'")
                out.append(int(v))
            return tuple(out)
        raise ParameterError(f'{where}: unknown type {self.type!r}')

    def _check_range(self, value: float, where: str) -> None:
        if not math.isfinite(value):
            raise ParameterError(f'{where}: {value!r} is not finite')
        if (self.min is not None and value < self.min) or (self.max is not None and value > self.max):
            raise ParameterError(
                f'{where}: {value!r} {self.unit} is outside the allowed range '
                f'[{self.min}, {self.max}] {self.unit}')


def validate(specs: Iterable[ParamSpec], values: Mapping[str, Any], *,
             allow_unknown: bool = False) -> dict[str, Any]:
    """Check ``values`` against ``specs`` and fill in defaults.

    Parameters
    ----------
    specs : iterable of ParamSpec
        The declarations to check against.
    values : mapping
        Parameter name to value; missing names take their default.
    allow_unknown : bool
        If False (default), a key that no spec declares is an error
        (catches typos such as ``drum_raduis``).

    Returns
    -------
    dict
        Every declared parameter with a checked value.

    Raises
    ------
    ParameterError
        The first problem found, naming the key, the value and the range.
    """
    by_name = {s.name: s for s in specs}
    if not allow_unknown:
        unknown = sorted(set(values) - set(by_name))
        if unknown:
            raise ParameterError(f'unknown parameter(s) {unknown}; known: see `grip-force params`')
    return {name: spec.check(values.get(name, spec.default)) for name, spec in by_name.items()}


def markdown_table(specs: Iterable[ParamSpec]) -> str:
    """Render the parameter table of the docs: one Markdown row per spec.

    Columns: name, group, type, unit, default, range (inclusive), read-only,
    description (with the allowed values of a 'string' parameter). The one
    generator: ``docs/ros_interface.md`` (``python -m grip_force_ros.nodes.docs``) and
    ``grip-force params --markdown`` both print it.

    Parameters
    ----------
    specs : iterable of ParamSpec
        One row each, in this order.

    Returns
    -------
    str
        The table, lines joined by newlines (no trailing newline).
    """
    lines = ['| name | group | type | unit | default | range | read-only | description |',
             '|---|---|---|---|---|---|---|---|']
    for s in specs:
        rng = '' if s.min is None and s.max is None else f'[{s.min}, {s.max}]'
        choices = f' One of: {", ".join(s.choices)}.' if s.choices else ''
        default = list(s.default) if isinstance(s.default, tuple) else s.default
        lines.append(f'| `{s.name}` | {s.group} | {s.type} | {s.unit} | {default!r} | {rng} | '
                     f'{"yes" if s.read_only else ""} | {s.description}{choices} |')
    return '\n'.join(lines)
