"""The controller in a launch description, plain or managed (launch/*.launch.py).

``autostart:=true`` (the default): a plain ``launch_ros`` ``Node``; the controller
configures and activates itself (its ``autostart`` parameter), as ``ros2 run`` does.
``autostart:=false``: a ``launch_ros`` ``LifecycleNode`` action with ``autostart: false``:
the controller waits unconfigured, sending no command, until ``ros2 lifecycle set
<ns>/controller configure`` and ``activate`` (or a ``launch_ros.events.lifecycle.ChangeState``
event of an including launch file); launch logs every transition it reports
(``OnStateTransition``). The vendored launch_ros (jazzy) has no ``autostart`` argument on
``LifecycleNode``: the node's own parameter is what keeps it unconfigured.
"""
from __future__ import annotations

from launch.actions import LogInfo, OpaqueFunction, RegisterEventHandler
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition

from grip_force_ros.nodes.lifetime import leave_after_environment

PACKAGE = 'grip_force_ros'


def _log_transition(context):
    event = context.locals.event
    return [LogInfo(msg=f'{event.action.node_name}: {event.start_state} -> {event.goal_state} '
                        f'({event.transition})')]


def controller_actions(namespace: str, parameters: list, autostart: bool,
                       leave_after: tuple[str, ...] = ()) -> list:
    """Return the launch actions of the controller node.

    Parameters
    ----------
    namespace : str
        The node's namespace ('' for the root).
    parameters : list
        Its parameter files and dicts, in order (``autostart`` is added last).
    autostart : bool
        True: a plain node that brings itself up; False: a managed LifecycleNode that waits.
    leave_after : tuple of str
        Nodes of the same launch (names in ``namespace``) whose leaving the controller waits
        for at Ctrl-C before its own teardown (``lifetime.LEAVE_AFTER_ENV``).
    """
    parameters = list(parameters) + [{'autostart': autostart}]
    common = dict(executable='controller', name='controller', namespace=namespace,
                  parameters=parameters, output='screen',
                  additional_env=leave_after_environment(leave_after))
    if autostart:
        return [Node(package=PACKAGE, **common)]
    node = LifecycleNode(package=PACKAGE, **common)
    return [node, RegisterEventHandler(OnStateTransition(
        target_lifecycle_node=node, entities=[OpaqueFunction(function=_log_transition)]))]
