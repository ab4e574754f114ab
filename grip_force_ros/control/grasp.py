"""A grasp goal (the GripperCommand actions): what to command, and when it is done.

Plain values in and out (SI units), no ROS: the controller node's action servers
(:mod:`grip_force_ros.nodes.controller_actions`) make one :class:`GraspGoal` per accepted
goal and hand it to :class:`~grip_force_ros.control.GripController` (``controller.goal``),
which asks it, instead of the master's force map, for the period's target.

A goal moves the jaw towards ``position`` (jaw opening angle, rad; 0 = closed) under the
jaw-angle loop. Closing, the jaw blocked by an object (stopped more than
``action_position_tolerance`` short of its target: ``|jaw velocity| < contact_jaw_speed``,
for ``contact_confirm_time``) is contact: from then on the
force loop holds ``force`` (N), the target rising to it at ``force_rate`` from the present
force. The goal is *settled* (done, succeeded) when the force has stayed within
``force_tolerance`` of ``force`` for ``settle_time``, or, with no contact, when the jaw has
stayed within ``position_tolerance`` of ``position`` for ``settle_time``. A settled goal goes
on holding what it reached until the master takes over or a newer goal comes
(:meth:`master_takes_over`). :meth:`release` (a cancel) drives the jaw open to
``release_angle`` with no force; it is released once the jaw got there, or after
``RELEASE_TIMEOUT``.
"""
from __future__ import annotations

import enum
import math

#: Least force tolerance (N): a goal of (nearly) 0 N has this band.
FORCE_TOLERANCE_FLOOR = 0.01
#: Time constant (s) of the low-pass on the force feedback that the settle test reads: the
#: load cell's noise and the loop's ripple are not a force that has not settled.
FORCE_FILTER_TIME = 0.02
#: A release (cancel) counts as done after this long (s) even if the jaw did not open that far.
RELEASE_TIMEOUT = 0.5


class GoalState(enum.StrEnum):
    """Where a goal is (a ``str``: /diagnostics shows the value).

    MOVING: the jaw moves towards the goal position (jaw-angle loop).
    GRIPPING: in contact, the force loop holds the goal's force (not settled yet).
    SETTLED: done (succeeded): the force settled, or the jaw reached the position; held on.
    RELEASING: cancelled: the jaw opens to the release angle with no force.
    ABORTED: ended by the controller (safe state, preemption, deactivation): ``reason``.
    """

    MOVING = 'moving'
    GRIPPING = 'gripping'
    SETTLED = 'settled'
    RELEASING = 'releasing'
    ABORTED = 'aborted'


_MOVING, _GRIPPING, _SETTLED = GoalState.MOVING, GoalState.GRIPPING, GoalState.SETTLED
_RELEASING, _ABORTED = GoalState.RELEASING, GoalState.ABORTED


def goal_refusal(position: float, force: float, params) -> str | None:
    """Return why a goal of ``position`` (rad) and ``force`` (N) is refused, or None.

    Refused: not finite, a force below 0 N or above ``max_grip_force`` (not clipped
    silently), a position outside [``jaw_angle_min``, ``jaw_angle_max``].
    """
    if not (math.isfinite(position) and math.isfinite(force)):
        return f'position {position!r} rad and max_effort {force!r} N must be finite'
    if force < 0.0:
        return f'max_effort {force:g} N is below 0 N'
    if force > params.max_grip_force:
        return (f'max_effort {force:g} N is above max_grip_force {params.max_grip_force:g} N '
                f'of {params.instrument_name}')
    if not params.jaw_angle_min <= position <= params.jaw_angle_max:
        return (f'position {position:g} rad is outside the jaw range [{params.jaw_angle_min:g}, '
                f'{params.jaw_angle_max:g}] rad')
    return None


class GraspGoal:
    """One grasp goal: close (or open) the jaw towards a position, then hold a force.

    Parameters
    ----------
    position : float
        Goal jaw opening angle (rad, 0 = closed), inside the jaw range (:func:`goal_refusal`).
    force : float
        Grip force to hold on contact (N), 0 to ``max_grip_force``.
    params : ParamSet
        The controller's parameters: ``action_force_tolerance`` (fraction of ``force``),
        ``action_settle_time`` (s), ``action_position_tolerance`` (rad),
        ``action_release_angle`` (rad), ``action_takeover_angle`` (rad), ``contact_jaw_speed``
        (rad/s), ``jaw_angle_min`` and ``jaw_angle_max`` (rad).
    force_rate : float
        Rate (N/s) at which the force target climbs to ``force`` after contact.
    contact_confirm_time : float
        How long (s) the jaw must stay blocked before that counts as contact.

    Attributes
    ----------
    state : GoalState
        Where the goal is.
    reason : str
        Why it was aborted ('' otherwise).
    stalled : bool
        In contact and holding: the force (low-passed, :data:`FORCE_FILTER_TIME`) within the
        tolerance of the goal's.
    reached_goal : bool
        The goal's force held within the tolerance (contact), or the jaw within the position
        tolerance of the goal position (no contact).
    force_target : float
        The force target of the last period (N; 0 while not in contact).
    """

    __slots__ = ('position', 'force', 'tolerance', 'settle_time', 'position_tolerance',
                 'release_angle', 'takeover_angle', 'contact_jaw_speed',
                 'contact_confirm_time', 'force_rate', 'state', 'reason', 'stalled',
                 'reached_goal', 'force_target', 'blocked_time', 'held_time', 'release_time',
                 'master_reference', 'contact', 'filtered_force')

    def __init__(self, position: float, force: float, params, *, force_rate: float,
                 contact_confirm_time: float):
        self.position = min(max(float(position), params.jaw_angle_min), params.jaw_angle_max)
        self.force = float(force)                                    # N
        self.tolerance = max(params.action_force_tolerance * self.force,
                             FORCE_TOLERANCE_FLOOR)                  # N
        self.settle_time = params.action_settle_time                 # s
        self.position_tolerance = params.action_position_tolerance   # rad
        self.release_angle = min(params.action_release_angle, params.jaw_angle_max)   # rad
        self.takeover_angle = params.action_takeover_angle           # rad
        self.contact_jaw_speed = params.contact_jaw_speed            # rad/s
        self.contact_confirm_time = float(contact_confirm_time)      # s
        self.force_rate = float(force_rate)                          # N/s
        self.state = _MOVING
        self.reason = ''
        self.stalled = False
        self.reached_goal = False
        self.contact = False             # the jaw met an object (force loop)
        self.force_target = 0.0          # N
        self.filtered_force = math.nan   # N, low-passed feedback (FORCE_FILTER_TIME)
        self.blocked_time = 0.0          # s the jaw has been blocked so far
        self.held_time = 0.0             # s within the tolerance so far
        self.release_time = 0.0          # s since the release began
        self.master_reference = math.nan  # rad, the master angle when the goal was done

    # ------------------------------------------------------------------ state
    @property
    def done(self) -> bool:
        """Whether the goal has its outcome (settled, released or aborted)."""
        state = self.state
        return (state is _SETTLED or state is _ABORTED
                or (state is _RELEASING and self.released))

    @property
    def released(self) -> bool:
        """Whether a release has opened the jaw (or timed out): the cancel is complete."""
        return self.state is _RELEASING and self.release_time < 0.0

    def abort(self, reason: str) -> None:
        """End the goal with ``reason`` (the controller then commands from the master)."""
        if self.state is not _ABORTED:
            self.state = _ABORTED
            self.reason = reason
            self.stalled = self.reached_goal = False

    def release(self) -> None:
        """Cancel: open the jaw to the release angle with no force (jaw-angle loop)."""
        if self.state is not _RELEASING and self.state is not _ABORTED:
            self.state = _RELEASING
            self.contact = self.stalled = self.reached_goal = False
            self.force_target = 0.0
            self.release_time = 0.0

    # ------------------------------------------------------------------ the period
    def update(self, jaw: float, jaw_velocity: float, force: float, dt: float):
        """Advance by one period; return ``(gripping, target)`` as the force map does.

        Parameters
        ----------
        jaw : float
            Measured jaw angle (rad).
        jaw_velocity : float
            Measured jaw velocity (rad/s).
        force : float
            Grip force feedback of the period (N: load cell or model estimate).
        dt : float
            Time since the previous period (s).

        Returns
        -------
        gripping : bool
            True: force control at ``target`` (N); False: jaw-angle control to ``target`` (rad).
        target : float
        """
        state = self.state
        if state is _RELEASING:
            if self.release_time >= 0.0:
                self.release_time += dt
                if (abs(jaw - self.release_angle) <= self.position_tolerance
                        or self.release_time >= RELEASE_TIMEOUT):
                    self.release_time = -1.0         # released
            return False, self.release_angle
        if self.contact:
            goal = self.force
            target = self.force_target
            if target < goal:
                target += self.force_rate * dt
                if target > goal:
                    target = goal
            elif target > goal:
                target = goal
            self.force_target = target
            filtered = self.filtered_force
            if filtered != filtered:
                filtered = force
            else:
                filtered += (1.0 - math.exp(-dt / FORCE_FILTER_TIME)) * (force - filtered)
            self.filtered_force = filtered
            holding = target == goal and abs(filtered - goal) <= self.tolerance
            self.stalled = holding
            if state is not _SETTLED:
                self.held_time = self.held_time + dt if holding else 0.0
                if self.held_time >= self.settle_time:
                    self.state = _SETTLED
                    self.reached_goal = True
            return True, target
        position = self.position
        if (state is not _SETTLED and jaw - position > self.position_tolerance
                and abs(jaw_velocity) < self.contact_jaw_speed):
            self.blocked_time += dt
            if self.blocked_time >= self.contact_confirm_time:
                self.contact = True
                self.state = _GRIPPING
                self.force_target = force if 0.0 < force < self.force else 0.0
                self.held_time = 0.0
                return True, self.force_target
        else:
            self.blocked_time = 0.0
        at = abs(jaw - position) <= self.position_tolerance
        if state is not _SETTLED:
            self.reached_goal = at
            self.held_time = self.held_time + dt if at else 0.0
            if self.held_time >= self.settle_time:
                self.state = _SETTLED
        return False, position

    def master_takes_over(self, master_angle: float) -> bool:
        """Whether a fresh master angle (rad) takes the jaw back from this done goal.

        The first master angle after the goal was done is the reference; the master takes
        over once it moved more than ``action_takeover_angle`` from it (the operator moves
        the gripper). An unfinished goal is never taken over.
        """
        if not self.done or self.state is _ABORTED:
            return self.state is _ABORTED
        reference = self.master_reference
        if reference != reference:
            self.master_reference = master_angle
            return False
        return abs(master_angle - reference) > self.takeover_angle
