"""The step time a control step may use, computed independently of the controller (a test oracle).

The controller steps on the measured time since its previous step (docs/control.md, "Rate
independence"): the current may change by at most ``max_current_slew * dt`` in a step.
``dt`` is ``now - previous now`` when that is a usable step interval, 0 <= dt <=
``watchdog_timeout``; otherwise (the first step, a clock that is not finite or went
backwards) the step is safe and ramps by the nominal period ``1 / expected_state_rate``.
After a stall longer than the watchdog nobody knows what the drive did (a drive with a
command timeout cut the current, a dVRK held it): the controller restarts from the measured
current, so that step has no slew bound (``dt`` is infinite), only the current limit.
"""
import math


class StepClock:
    """Track the controller clock as the controller sees it; :meth:`dt` per step."""

    def __init__(self):
        self.last = -math.inf

    def dt(self, now, params) -> float:
        """Return the step time (s) of a step at ``now`` (call once per step, in order)."""
        nominal = 1.0 / params.expected_state_rate
        if not isinstance(now, float) or not math.isfinite(now):
            return nominal
        last, self.last = self.last, now
        if last == -math.inf:
            return nominal
        interval = now - last
        if interval > params.watchdog_timeout:
            return math.inf
        return interval if interval >= 0.0 else nominal
