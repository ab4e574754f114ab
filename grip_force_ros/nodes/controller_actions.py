"""The controller node's grasp actions (control_msgs), the way ROS grippers are commanded.

``grip_command`` (control_msgs/action/GripperCommand)
    Goal ``command.position``: jaw opening angle (rad, 0 = closed; the ``jaw`` joint of
    ``instrument/measured_js``); ``command.max_effort``: the grip force to hold on contact
    (N). Feedback and result: ``position`` = measured jaw angle (rad), ``effort`` =
    estimated grip force (N: the load cell or the model estimate, as configured),
    ``stalled`` = in contact and holding the force within ``action_force_tolerance``,
    ``reached_goal`` = the goal achieved (the force held, or the jaw at the position).
``parallel_grip_command`` (control_msgs/action/ParallelGripperCommand)
    The same goal as a sensor_msgs/JointState: joint ``jaw`` (or no name), ``position``
    (rad), ``effort`` the grip force (N; empty: ``min(grip_force_max, max_grip_force)``,
    the force of the fully closed master). Feedback and result ``state``: joint ``jaw``,
    position (rad), velocity (rad/s), effort = estimated grip force (N).

The dvrk profile puts both under the arm (``PSM1/grip_command``), as its grip topics.
What a goal commands, and when it is done, is :mod:`grip_force_ros.control.grasp`
(rclpy-free); this module only wires it: the goal goes to the controller core
(``GripController.start_goal``), and the loop's reduced-rate path (:meth:`ControllerActions.tick`,
beside the force outputs) sends the feedback at ``action_feedback_rate`` and the outcome:

* succeeded: the force settled within the tolerance (or the jaw reached the position);
  the goal holds on after its result;
* canceled: a cancel opens the jaw to ``action_release_angle`` with no force, then answers;
* aborted: a safe state (lost or invalid input, interlock; the reason is logged and shown
  on /diagnostics), a newer goal (preemption), or the controller leaving the active state.

Refused (with the reason in the log and on /diagnostics, ``action_last_refusal``): a goal
while the controller is not active or a service's procedure runs, a force below 0 N or above
``max_grip_force``, a position outside the jaw range, a parallel goal without the ``jaw``.

Who commands the jaw: an accepted goal takes over from the master until it ends. A goal
that is done (settled or cancelled) goes on holding until the master gripper moves more than
``action_takeover_angle`` from where it was then, or a newer goal comes; an aborted goal
hands back at once. The master then resumes bumplessly (the current continues from its last
value, the force target ramps from the present force). /diagnostics says who commands
(``commander``: ``master`` or ``action (<goal state>)``).
"""
from __future__ import annotations

import functools

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future

from grip_force_ros import topics
from grip_force_ros.control.force_map import CONTACT_CONFIRM_TIME
from grip_force_ros.control.grasp import GoalState, GraspGoal, goal_refusal

_GRIPPER, _PARALLEL = 'grip_command', 'parallel_grip_command'
#: How often the loop looks at a running goal (s): its cancel, its outcome, its feedback.
TICK_PERIOD = 0.01


def control_msgs_actions():
    """Return (GripperCommand, ParallelGripperCommand), or None when control_msgs is missing."""
    try:
        from control_msgs.action import GripperCommand, ParallelGripperCommand
    except ImportError:
        return None
    return GripperCommand, ParallelGripperCommand


class _Goal:
    """One accepted goal: its handle, its grasp goal, and the future its outcome completes."""

    __slots__ = ('kind', 'handle', 'grasp', 'finished', 'result')

    def __init__(self, kind: str, handle, grasp: GraspGoal):
        self.kind = kind
        self.handle = handle
        self.grasp = grasp
        self.finished = Future()
        self.result = None


class ControllerActions:
    """The controller node's two grasp action servers (none without control_msgs).

    Parameters
    ----------
    node : ControllerNode
        The node: its ``params``, ``controller``, ``inputs``, ``active``, ``procedure``.
    """

    def __init__(self, node):
        self.node = node
        self.current: _Goal | None = None   # the goal that runs (not yet answered)
        self._accepted: dict = {}           # goal id (bytes) -> _Goal, until its execute runs
        self.last_refusal = 'none'
        self.last_outcome = 'none'
        self._next_feedback_ns = 0
        self.due_ns = 0                     # controller clock (ns) of the next tick
        self.servers: list = []
        self.types = control_msgs_actions()
        if self.types is None:
            node.get_logger().info('control_msgs is not importable: no grasp actions')
            return
        params = node.params
        names = topics.action_names(params.interface, params.arm)
        for kind, action_type, name in zip((_GRIPPER, _PARALLEL), self.types, names):
            self.servers.append(ActionServer(
                node, action_type, name,
                execute_callback=self._execute,
                goal_callback=functools.partial(self._on_goal, kind),
                handle_accepted_callback=functools.partial(self._on_accepted, kind),
                cancel_callback=self._on_cancel))
        self.names = names

    def destroy(self) -> None:
        """Destroy the action servers."""
        for server in self.servers:
            server.destroy()
        self.servers = []

    # ------------------------------------------------------------------ goals
    def _parse(self, kind: str, request):
        """Return ``(position [rad], force [N], refusal or None)`` of a goal request."""
        params = self.node.params
        if kind == _GRIPPER:
            position, force = request.command.position, request.command.max_effort
        else:
            state = request.command
            names = list(state.name)
            if names and topics.JAW_JOINT not in names:
                return 0.0, 0.0, (f'no joint {topics.JAW_JOINT!r} in the goal (joints: {names})')
            i = names.index(topics.JAW_JOINT) if names else 0
            if len(state.position) <= i:
                return 0.0, 0.0, f'no position for joint {topics.JAW_JOINT!r}'
            position = state.position[i]
            force = (state.effort[i] if len(state.effort) > i
                     else min(params.grip_force_max, params.max_grip_force))
        node = self.node
        if not node.active:
            return position, force, (f'the controller is {node.lifecycle_state}: goals are '
                                     'accepted only while it is active')
        if node.procedure is not None:
            return position, force, f'a service runs ({node.procedure.status()})'
        return position, force, goal_refusal(position, force, params)

    def _on_goal(self, kind: str, request) -> GoalResponse:
        position, force, why = self._parse(kind, request)
        if why is not None:
            self.last_refusal = f'{kind}: {why}'
            self.node.get_logger().warning(f'{kind} goal refused: {why}')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_accepted(self, kind: str, handle) -> None:
        node = self.node
        position, force, why = self._parse(kind, handle.request)
        controller = node.controller
        grasp = GraspGoal(position, force, node.params,
                          force_rate=controller.resume_ramp_rate if controller else 0.0,
                          contact_confirm_time=CONTACT_CONFIRM_TIME)
        entry = _Goal(kind, handle, grasp)
        previous, self.current = self.current, entry
        if previous is not None:
            previous.grasp.abort('preempted by a newer goal')
            self._finish(previous)
        self._accepted[bytes(handle.goal_id.uuid)] = entry
        if why is not None:             # the node left the active state in between
            grasp.abort(why)
        else:
            controller.start_goal(grasp)
            node.get_logger().info(f'{kind} goal: jaw to {position:g} rad, hold {force:g} N')
        self._next_feedback_ns = self.due_ns = 0
        handle.execute()

    def _on_cancel(self, handle) -> CancelResponse:
        entry = self.current
        if entry is None or entry.handle is not handle:
            return CancelResponse.REJECT
        return CancelResponse.ACCEPT

    async def _execute(self, handle):
        entry = self._accepted.pop(bytes(handle.goal_id.uuid), None)
        if entry is None:               # not ours (cannot happen): abort
            handle.abort()
            return self.types[0].Result()
        if self.current is not entry and not entry.finished.done():
            self._finish(entry)
        return await entry.finished

    # ------------------------------------------------------------------ the loop's side
    def tick(self, out, now_ns: int) -> None:
        """Advance the running goal: cancel, outcome, feedback (the reduced-rate path).

        Parameters
        ----------
        out : ControlOutput
            The step's output.
        now_ns : int
            The controller clock at the step (ns).
        """
        entry = self.current
        if entry is None:
            return
        self.due_ns = now_ns + int(TICK_PERIOD * 1e9)
        grasp = entry.grasp
        if entry.handle.is_cancel_requested:
            grasp.release()
        if grasp.done:
            self._finish(entry, out)
            return
        if now_ns >= self._next_feedback_ns:
            self._next_feedback_ns = now_ns + int(1e9 / self.node.params.action_feedback_rate)
            entry.handle.publish_feedback(self._message(entry, out, feedback=True))

    def stop(self, why: str) -> None:
        """Abort the running goal (the node leaves the active state) and hand back to the master."""
        entry = self.current
        if entry is not None:
            entry.grasp.abort(why)
            self._finish(entry)
        controller = self.node.controller
        if controller is not None:
            controller.end_goal()

    def _finish(self, entry: _Goal, out=None) -> None:
        """Answer ``entry`` with its grasp goal's outcome."""
        if self.current is entry:
            self.current = None
        if entry.finished.done():
            return
        grasp, handle = entry.grasp, entry.handle
        result = self._message(entry, out, feedback=False)
        if grasp.state is GoalState.SETTLED:
            outcome = 'succeeded'
            handle.succeed()
        elif grasp.state is GoalState.RELEASING and handle.is_cancel_requested:
            outcome = 'canceled'
            handle.canceled()
        else:
            outcome = f'aborted: {grasp.reason}'
            if handle.is_active:
                handle.abort()
        self.last_outcome = f'{entry.kind} {outcome}'
        log = self.node.get_logger()
        text = (f'{entry.kind} goal {outcome} (jaw {self._jaw():.3f} rad, force '
                f'{self._force(out):.3f} N)')
        if outcome in ('succeeded', 'canceled'):     # one severity per call site (rclpy)
            log.info(text)
        else:
            log.warning(text)
        entry.result = result
        entry.finished.set_result(result)

    def _jaw(self) -> float:
        inputs = self.node.inputs
        jaw = inputs.jaw_angle if inputs is not None else 0.0
        return jaw if jaw == jaw else 0.0

    def _force(self, out) -> float:
        if out is None:
            out = self.node.last_output
        return out.estimated_force if out is not None else 0.0

    def _message(self, entry: _Goal, out, *, feedback: bool):
        """Build the feedback or result of ``entry`` (jaw, estimated force, stalled, reached)."""
        action = self.types[0] if entry.kind == _GRIPPER else self.types[1]
        msg = action.Feedback() if feedback else action.Result()
        grasp, jaw, force = entry.grasp, self._jaw(), self._force(out)
        if entry.kind == _GRIPPER:
            msg.position, msg.effort = jaw, force
        else:
            inputs = self.node.inputs
            velocity = inputs.jaw_velocity if inputs is not None else 0.0
            msg.state.header.stamp = self.node.get_clock().now().to_msg()
            msg.state.name = [topics.JAW_JOINT]
            msg.state.position = [jaw]
            msg.state.velocity = [velocity if velocity == velocity else 0.0]
            msg.state.effort = [force]
        if entry.kind == _GRIPPER or not feedback:   # the parallel feedback has only the state
            msg.stalled = grasp.stalled
            msg.reached_goal = grasp.reached_goal
        return msg

    def status(self) -> dict[str, str]:
        """Key/value strings for /diagnostics: the running goal, the last refusal and outcome."""
        entry = self.current
        return {'action_goal': (f'{entry.kind}: {entry.grasp.state}' if entry is not None
                                else 'none'),
                'action_last_refusal': self.last_refusal,
                'action_last_outcome': self.last_outcome}
