"""Interface profiles of the nodes (group 'interface'): which topics, types and units they speak.

``crtk``: this package's own names (``instrument/actuator/servo_jf`` carries a current in A),
as before. ``dvrk``: the da Vinci Research Kit's PSM and MTM topics under the arm's and the
master's names (``PSM1/jaw/servo_jf`` carries a jaw effort in N*m), the arm's operating
state, and the dVRK's 100 Hz topic rate (docs/dvrk.md). The topic names of both profiles
live in :mod:`grip_force_ros.topics`; the profile's choice and its defaults live here.
"""
from __future__ import annotations

import re
from typing import Any, Iterable, Mapping

from grip_force_ros.params.schema import ParameterError, ParamSpec

#: The interface profiles (the nodes' ``interface`` parameter, the launch files' ``interface:=``).
INTERFACES = ('crtk', 'dvrk')

#: Defaults that differ in a profile (used where the parameter file does not give the value):
#: the dVRK publishes its ROS topics at 100 Hz by default (the arm's own loop runs at 1.5 kHz).
PROFILE_DEFAULTS: dict[str, dict[str, Any]] = {
    'crtk': {},
    'dvrk': {'publish_rate': 100.0, 'expected_state_rate': 100.0, 'master_rate': 100.0},
}

#: A dVRK arm or master name: a ROS name token (it becomes the first part of every topic).
_ARM_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')

_P = ParamSpec

INTERFACE = [
    _P('interface', 'string', 'crtk', '',
       "Topic profile of the node: 'crtk' (this package's topics, current in A) or 'dvrk' (the "
       "dVRK's: <arm>/jaw/measured_js, <arm>/measured_js, <master>/gripper/measured_js, the jaw "
       'effort in N*m on <arm>/jaw/servo_jf, <arm>/operating_state; docs/dvrk.md).',
       choices=INTERFACES, read_only=True, group='interface'),
    _P('arm', 'string', 'PSM1', '',
       'dvrk profile: the arm whose topics the node uses (PSM1, PSM2, ...): the first part of '
       'every topic name of the arm, so two arms run side by side.',
       read_only=True, group='interface'),
    _P('master', 'string', 'MTML', '',
       'dvrk profile: the master whose gripper drives the jaw (MTML, MTMR): '
       '<master>/gripper/measured_js.', read_only=True, group='interface'),
]

#: The controller's part of the dvrk profile (declared by the controller only).
DVRK_CONTROLLER = [
    _P('dvrk_command', 'string', 'effort', '',
       "dvrk profile: how the controller drives the jaw. 'position': <arm>/jaw/servo_jp "
       "setpoints through the PSM's jaw position loop, the arm stays in position mode "
       "(teleoperation streams servo_cp beside it; with a load cell only for now). 'effort' "
       '(the default until the position path holds sensorless): <arm>/jaw/servo_jf, which puts '
       'the whole arm in Cartesian effort mode (its joints no longer held): for an arm that is '
       'not teleoperated (docs/dvrk.md).',
       choices=('position', 'effort'), read_only=True, group='controller'),
    _P('request_enable', 'bool', False, '',
       'dvrk profile: ask the arm to enable and home (state_command "enable", then "home") when '
       'it is not ENABLED and homed: at start-up when true, and again on every runtime set to '
       'true. Never on its own otherwise: an arm that is disabled later stays disabled (the '
       'controller holds its output safe until the arm is ENABLED and homed again).',
       group='controller'),
]


def profile_defaults(interface: str) -> dict[str, Any]:
    """Return the defaults of ``interface`` that differ from the schema's (empty if unknown)."""
    return dict(PROFILE_DEFAULTS.get(interface, {}))


def with_profile_defaults(values: Mapping[str, Any], names: Iterable[str]) -> dict[str, Any]:
    """Return ``values`` completed with the defaults of its ``interface`` profile.

    Parameters
    ----------
    values : mapping
        Parameter name -> value; the given values win over the profile's defaults.
    names : iterable of str
        The parameters the caller declares: only their profile defaults are added.
    """
    names = set(names)
    defaults = profile_defaults(values.get('interface', 'crtk'))
    return {**{k: v for k, v in defaults.items() if k in names}, **values}


def check_interface(values: Mapping[str, Any]) -> None:
    """Cross-parameter checks of the 'interface' group (called by ``check_consistency``).

    Raises
    ------
    ParameterError
        An arm or master name that cannot start a ROS topic name.
    """
    for key in ('arm', 'master'):
        name = values[key]
        if not _ARM_NAME.match(name):
            raise ParameterError(
                f"parameter '{key}': {name!r} is not a dVRK arm name (a letter, then letters, "
                'digits or _; e.g. PSM1, MTML)')
