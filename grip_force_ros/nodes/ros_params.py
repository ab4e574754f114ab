"""ROS parameters of a node, built from the one schema (``grip_force_ros.params``).

For each :class:`~grip_force_ros.params.ParamSpec` of the node's groups this
module declares a ROS parameter whose descriptor carries the type, the unit and
description, the range (``FloatingPointRange`` / ``IntegerRange``) and the
read-only flag, so that ``ros2 param describe`` shows the schema and rclpy
refuses out-of-range and read-only sets by itself.

What rclpy does not check is checked here, in the schema's own words:

* at start-up, every value of the parameter file (``--params-file``) is
  validated against the whole schema before anything is declared: unknown keys
  (typos), wrong types, out-of-range values, elements of double arrays, string
  choices, and the schema's cross-parameter rules (``params.check_consistency``); an
  instrument file (it names ``instrument_name``) must also describe an instrument that
  could be built (``model.physical.check_physical``: cable stress at ``max_current``
  below ``cable_yield_strength``, chain efficiency in (0, 1], a jaw torque that closes).
  A bad file raises :class:`~grip_force_ros.params.ParameterError` naming the key,
  the value and the range; the node's ``main`` turns that into a non-zero exit.
* at runtime, ``add_on_set_parameters_callback`` validates the candidate set
  (no side effects there); ``add_post_set_parameters_callback`` rebuilds the
  :class:`~grip_force_ros.params.ParamSet` and hands it to the node.
"""
from __future__ import annotations

import array
import sys
from typing import Any, Callable, Iterable, Mapping, Sequence

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.node import Node
from rclpy.parameter import Parameter

from grip_force_ros.model.contact import ModelError
from grip_force_ros.model.physical import check_physical
from grip_force_ros.params import SCHEMA, SPECS, ParameterError, ParamSet, ParamSpec, make_params
from grip_force_ros.params.interface import with_profile_defaults

#: Parameters every rclpy node may carry that are not ours.
ROS_BUILTIN = ('use_sim_time', 'start_type_description_service')

_ROS_TYPES = {
    'double': Parameter.Type.DOUBLE,
    'integer': Parameter.Type.INTEGER,
    'bool': Parameter.Type.BOOL,
    'string': Parameter.Type.STRING,
    'double_array': Parameter.Type.DOUBLE_ARRAY,
    'integer_array': Parameter.Type.INTEGER_ARRAY,
}

#: rcl_interfaces ranges must be finite; an open end of a schema range becomes this.
_BIG_DOUBLE = sys.float_info.max
_BIG_INT = 2 ** 62


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """Build the ROS parameter descriptor of one schema entry."""
    unit = f' [{spec.unit}]' if spec.unit else ''
    constraints = []
    if spec.min is not None or spec.max is not None:
        constraints.append(f'range [{spec.min}, {spec.max}]{unit}')
    if spec.type in ('double_array', 'integer_array'):
        constraints.append('applies to each element')
    if spec.choices:
        constraints.append('one of ' + ', '.join(spec.choices))
    desc = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.type].value,
        description=spec.description + unit,
        additional_constraints='; '.join(constraints),
        read_only=spec.read_only,
        dynamic_typing=False,
    )
    if spec.type == 'double' and (spec.min is not None or spec.max is not None):
        desc.floating_point_range = [FloatingPointRange(
            from_value=float(spec.min) if spec.min is not None else -_BIG_DOUBLE,
            to_value=float(spec.max) if spec.max is not None else _BIG_DOUBLE,
            step=0.0)]
    elif spec.type == 'integer' and (spec.min is not None or spec.max is not None):
        desc.integer_range = [IntegerRange(
            from_value=int(spec.min) if spec.min is not None else -_BIG_INT,
            to_value=int(spec.max) if spec.max is not None else _BIG_INT,
            step=1)]
    return desc


def _declared_value(spec: ParamSpec, value: Any) -> Any:
    """Return the value to declare ``spec`` with: a list for arrays, the ROS type for an empty one."""
    if isinstance(value, tuple):
        return list(value) if value else _ROS_TYPES[spec.type]
    return value


def plain(value: Any) -> Any:
    """Convert a ROS parameter value to a plain Python value (arrays become tuples)."""
    if isinstance(value, (array.array, list, tuple)):
        return tuple(value)
    return value


class NodeParameters:
    """Declare a node's parameters from the schema and keep them validated.

    Parameters
    ----------
    node : rclpy.node.Node
        The node; its parameter overrides (``--params-file``, ``-p``,
        ``parameter_overrides=``) are validated before anything is declared.
    groups : sequence of str
        Schema groups this node declares, e.g. ``('instrument', 'limits', 'controller')``.
    extra_specs : sequence of ParamSpec
        Node-only parameters outside the instrument schema (e.g. the master's
        trajectory), declared and validated the same way.
    on_update : callable, optional
        ``on_update(params, changed)`` after an accepted runtime change:
        ``params`` the new :class:`ParamSet`, ``changed`` the set of names.
    check : callable, optional
        ``check(values)`` raising :class:`ParameterError` for node-specific
        cross-parameter rules; runs at start-up and on every runtime set.
    known_elsewhere : iterable of str
        Names that other nodes of the package declare (accepted in a shared
        ``/**`` parameter file, ignored here).

    Raises
    ------
    ParameterError
        At construction, when an override is unknown, of the wrong type, out of
        range or inconsistent.
    """

    def __init__(self, node: Node, groups: Sequence[str], extra_specs: Sequence[ParamSpec] = (),
                 on_update: Callable[[ParamSet, set], None] | None = None,
                 check: Callable[[Mapping[str, Any]], None] | None = None,
                 known_elsewhere: Iterable[str] = ()):
        self._node = node
        self._specs = {s.name: s for s in SCHEMA if s.group in groups}
        self._specs.update({s.name: s for s in extra_specs})
        self._extra_names = {s.name for s in extra_specs}
        self._on_update = on_update
        self._check = check
        known = set(SPECS) | set(self._specs) | set(known_elsewhere) | set(ROS_BUILTIN)

        overrides = {name: plain(p.value) for name, p in node._parameter_overrides.items()}
        # what the file does not give takes its interface profile's default (dvrk: 100 Hz)
        overrides = with_profile_defaults(overrides, self._specs)
        unknown = sorted(n for n in overrides
                         if n not in known and not n.startswith('qos_overrides.'))
        if unknown:
            raise ParameterError(
                f'unknown parameter(s) {unknown}; known: see `grip-force params`')
        # An instrument file (it names its instrument) must state every hardware limit
        # of a node that enforces them: a missing one would silently take the schema
        # default, which belongs to another instrument.
        enforces_limits = any(s.group == 'limits' for s in self._specs.values())
        if 'instrument_name' in overrides and enforces_limits:
            missing = sorted(s.name for s in SCHEMA
                             if s.group == 'limits' and s.name not in overrides)
            if missing:
                raise ParameterError(
                    f"instrument {overrides['instrument_name']!r}: hardware limit(s) {missing} "
                    'missing from the parameter file; an instrument file must state every '
                    'read-only limit')
        # The whole file against the whole schema: a node must not start with an
        # invalid instrument file even where the bad key belongs to another node.
        schema_values = {n: v for n, v in overrides.items() if n in SPECS}
        checked = dict(make_params(schema_values))
        if 'instrument_name' in overrides:   # an instrument file: could it be built at all?
            try:
                check_physical(checked)
            except ModelError as exc:
                raise ParameterError(str(exc)) from None
        for name in self._extra_names:
            spec = self._specs[name]
            checked[name] = spec.check(overrides.get(name, spec.default))
        self._full_check(checked)

        self._values: dict[str, Any] = {n: checked[n] for n in self._specs}
        node.declare_parameters('', [
            (name, _declared_value(spec, value), descriptor_for(spec))
            for name, spec in self._specs.items()
            for value in (self._values[name],)
        ], ignore_override=True)
        for name, spec in self._specs.items():
            if _declared_value(spec, self._values[name]) is _ROS_TYPES[spec.type]:
                # rclpy infers a type from the value and reads an empty list as a byte array:
                # declared by type (uninitialised), the empty value is given here, typed.
                node._parameters[name] = Parameter(name, _ROS_TYPES[spec.type], [])
        self._params = self._make_param_set(self._values)
        # After declaring: the values are already checked, and the node's own
        # state may not exist yet while it is being constructed.
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._apply)

    # -- access -----------------------------------------------------------
    @property
    def params(self) -> ParamSet:
        """The current schema parameters (undeclared groups at their defaults)."""
        return self._params

    def value(self, name: str) -> Any:
        """Return the current value of any declared parameter (schema or extra)."""
        return self._values[name]

    @property
    def names(self) -> list[str]:
        """Names this node declares."""
        return list(self._specs)

    # -- callbacks --------------------------------------------------------
    def _validate(self, parameters: list[Parameter]) -> SetParametersResult:
        """on-set callback: validate only, never change state here."""
        try:
            candidate = dict(self._values)
            for p in parameters:
                spec = self._specs.get(p.name)
                if spec is None:
                    continue  # ROS built-ins such as use_sim_time
                if p.type_ == Parameter.Type.NOT_SET:
                    raise ParameterError(f"parameter '{p.name}' cannot be undeclared")
                candidate[p.name] = spec.check(plain(p.value))
            full = dict(self._make_param_set(candidate))
            full.update((n, candidate[n]) for n in self._extra_names)
            self._full_check(full)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply(self, parameters: list[Parameter]) -> None:
        """post-set callback: the change was accepted; update and notify."""
        changed = set()
        for p in parameters:
            spec = self._specs.get(p.name)
            if spec is not None:
                self._values[p.name] = spec.check(plain(p.value))
                changed.add(p.name)
        if not changed:
            return
        self._params = self._make_param_set(self._values)
        if self._on_update is not None:
            self._on_update(self._params, changed)

    # -- helpers ----------------------------------------------------------
    def _make_param_set(self, values: Mapping[str, Any]) -> ParamSet:
        return make_params({n: v for n, v in values.items() if n in SPECS})

    def _full_check(self, values: Mapping[str, Any]) -> None:
        # make_params has run the schema's own cross-checks (check_consistency).
        if self._check is not None:
            self._check(values)


def declare_node_parameters(node, *args, **kwargs) -> 'NodeParameters':
    """:class:`NodeParameters` for ``node``; on a bad value the half-made node is destroyed.

    So a node that refuses its parameters leaves nothing behind in the ROS graph.

    Raises
    ------
    ParameterError
        As :class:`NodeParameters`.
    """
    try:
        return NodeParameters(node, *args, **kwargs)
    except ParameterError:
        node.destroy_node()
        raise
