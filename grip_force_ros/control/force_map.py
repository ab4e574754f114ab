"""Force map: master gripper angle -> free jaw-angle target, or grip force target."""
from __future__ import annotations

import math

#: How long (s) the jaw must stay blocked before that counts as contact. A jaw that merely
#: rests above its target (at the open stop, or where friction left it after a safe state
#: at 0 A) starts moving within a few ms once the jaw loop pulls it; an object keeps it
#: blocked. Without it, a controller that starts or resumes with the jaw open wider than the
#: master asks read the resting jaw as an object and held a 0 N grip for as long as the
#: master stayed where it was (loaded ROS runs; offline: the jaw at its open stop, the
#: master at 0.8 rad).
CONTACT_CONFIRM_TIME = 0.02


class ForceMap:
    """Map the master gripper angle to a jaw target (free motion) or a force target (grip).

    Free motion: target jaw angle = ``master_to_jaw_gain * (master - master_angle_min)``
    clipped to [0, jaw_angle_max] (rad). The map switches to grip when the master closes
    below ``master_contact_angle``, or when contact is detected: the measured jaw stays more
    than ``contact_jaw_margin`` above its target while nearly still (``|jaw velocity| <
    contact_jaw_speed``) for ``contact_confirm_time`` (s), i.e. the jaw is blocked by an
    object. The master angle at that moment is the contact angle ``m_c``. In grip the target force is

        F = force_max * s**exponent,   s = clip((m_c - master) / (m_c - master_angle_min), 0, 1)

    so it rises from 0 at contact to ``force_max`` at the fully closed master. Grip ends when
    the master opens past ``m_c + release_hysteresis``.

    Parameters
    ----------
    master_angle_min : float
        Master angle when fully closed (rad).
    master_contact_angle : float
        Master angle below which the controller always grips (rad).
    master_to_jaw_gain : float
        Jaw rad per master rad in free motion.
    jaw_angle_max : float
        Largest jaw target (rad).
    force_max : float
        Force target at the fully closed master (N); already capped at max_grip_force.
    exponent : float
        Shape of the force rise (1 = linear).
    contact_jaw_margin : float
        Jaw-above-target margin that signals contact (rad).
    contact_jaw_speed : float
        Contact only while |jaw velocity| is below this (rad/s).
    release_hysteresis : float
        Master opening past the contact angle that ends the grip (rad).
    contact_confirm_time : float
        How long the jaw must stay blocked before contact (s, :data:`CONTACT_CONFIRM_TIME`).
    """

    __slots__ = ('master_angle_min', 'master_contact_angle', 'master_to_jaw_gain',
                 'jaw_angle_max', 'force_max', 'exponent', 'contact_jaw_margin',
                 'contact_jaw_speed', 'release_hysteresis', 'contact_angle', 'gripping',
                 'last_master', 'contact_confirm_time', 'blocked_time')

    def __init__(self, *, master_angle_min: float, master_contact_angle: float,
                 master_to_jaw_gain: float, jaw_angle_max: float, force_max: float,
                 exponent: float = 1.0, contact_jaw_margin: float = 0.05,
                 contact_jaw_speed: float = 0.5, release_hysteresis: float = 0.02,
                 contact_confirm_time: float = CONTACT_CONFIRM_TIME):
        if not force_max >= 0.0:
            raise ValueError(f'force_max must be >= 0 N, got {force_max!r}')
        self.master_angle_min = float(master_angle_min)
        self.master_contact_angle = float(master_contact_angle)
        self.master_to_jaw_gain = float(master_to_jaw_gain)
        self.jaw_angle_max = float(jaw_angle_max)
        self.force_max = float(force_max)
        self.exponent = float(exponent)
        self.contact_jaw_margin = float(contact_jaw_margin)
        self.contact_jaw_speed = float(contact_jaw_speed)
        self.release_hysteresis = float(release_hysteresis)
        self.contact_angle = math.nan    # m_c [rad] while gripping
        self.gripping = False
        self.last_master = math.inf      # rad, previous master angle
        self.contact_confirm_time = float(contact_confirm_time)
        self.blocked_time = 0.0          # s the jaw has been blocked so far

    @classmethod
    def from_params(cls, params) -> 'ForceMap':
        """Build the map of an instrument ``ParamSet``; force_max = min(grip_force_max, max_grip_force)."""
        return cls(master_angle_min=params.master_angle_min,
                   master_contact_angle=params.master_contact_angle,
                   master_to_jaw_gain=params.master_to_jaw_gain,
                   jaw_angle_max=params.jaw_angle_max,
                   force_max=min(params.grip_force_max, params.max_grip_force),
                   exponent=params.force_map_exponent,
                   contact_jaw_margin=params.contact_jaw_margin,
                   contact_jaw_speed=params.contact_jaw_speed,
                   release_hysteresis=params.grip_release_hysteresis)

    def jaw_target(self, master_angle: float) -> float:
        """Free-motion jaw angle target (rad) for a master angle (rad)."""
        jaw = self.master_to_jaw_gain * (master_angle - self.master_angle_min)
        if jaw < 0.0:
            return 0.0
        return jaw if jaw < self.jaw_angle_max else self.jaw_angle_max

    def force_target(self, master_angle: float) -> float:
        """Grip force target (N) for a master angle (rad) in grip; 0 when not gripping."""
        if not self.gripping:
            return 0.0
        span = self.contact_angle - self.master_angle_min
        closed = self.contact_angle - master_angle
        if span <= 1e-9:
            share = 1.0 if closed > 0.0 else 0.0
        else:
            share = closed / span
            share = 0.0 if share < 0.0 else (1.0 if share > 1.0 else share)
        if self.exponent != 1.0:
            share = share ** self.exponent
        return self.force_max * share

    def update(self, master_angle: float, jaw_angle: float, jaw_velocity: float = 0.0,
               dt: float | None = None):
        """Advance the map by one sample.

        Parameters
        ----------
        master_angle : float
            Master gripper angle (rad), already clamped to its range.
        jaw_angle : float
            Measured jaw angle (rad).
        jaw_velocity : float
            Measured jaw velocity (rad/s).
        dt : float, optional
            Time since the previous sample (s): a blocked jaw counts as contact once it has
            been blocked for ``contact_confirm_time``. None: at once (no timing).

        Returns
        -------
        gripping : bool
            True in grip (force control), False in free motion (jaw-angle control).
        target : float
            Grip force target (N) when gripping, else the jaw angle target (rad).
        """
        jaw_target = self.jaw_target(master_angle)
        opening = master_angle > self.last_master
        self.last_master = master_angle
        if self.gripping:
            if master_angle > self.contact_angle + self.release_hysteresis:
                self.gripping = False
                self.contact_angle = math.nan
                return False, jaw_target
            return True, self.force_target(master_angle)
        if master_angle < self.master_contact_angle:
            self.gripping = True
            self.contact_angle = self.master_contact_angle
            return True, self.force_target(master_angle)
        if (not opening and jaw_angle - jaw_target > self.contact_jaw_margin
                and abs(jaw_velocity) < self.contact_jaw_speed):
            self.blocked_time += dt if dt is not None else math.inf
            if self.blocked_time >= self.contact_confirm_time:
                self.gripping = True
                self.contact_angle = master_angle
                self.blocked_time = 0.0
                return True, 0.0
        else:
            self.blocked_time = 0.0
        return False, jaw_target

    def reset(self) -> None:
        """Back to free motion (no contact)."""
        self.gripping = False
        self.contact_angle = math.nan
        self.last_master = math.inf
        self.blocked_time = 0.0
