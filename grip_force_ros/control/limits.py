"""Current and slew limits of the motor current command."""
from __future__ import annotations

#: limits_hit tuples, indexed by bit mask (1 = current limit, 2 = slew limit); shared, never rebuilt
_HITS = ((), ('current_limit',), ('slew_limit',), ('current_limit', 'slew_limit'))


class CurrentLimiter:
    """Clamp a current command to |I| <= max_current and |dI| <= max_slew * dt per step.

    Parameters
    ----------
    max_current : float
        Current limit (A).
    max_slew : float
        Slew limit (A/s).
    period : float
        Nominal step time (s); the largest change of a step of ``dt`` s is
        ``max_slew * dt`` (A), ``dt`` = ``period`` when :meth:`apply` is given none.
    """

    __slots__ = ('max_current', 'max_slew', 'max_step')

    def __init__(self, max_current: float, max_slew: float, period: float):
        if not (max_current >= 0.0 and max_slew >= 0.0 and period > 0.0):
            raise ValueError('max_current, max_slew must be >= 0 and period > 0')
        self.max_current = float(max_current)
        self.max_slew = float(max_slew)
        self.max_step = self.max_slew * float(period)

    def apply(self, desired: float, previous: float, dt: float | None = None):
        """Return ``(command [A], limits_hit)``; limits_hit is a tuple of limit names.

        ``previous`` must already be within the current limit; ``dt`` (s) is the time since
        it was applied (default the nominal period). A non-finite ``desired`` is treated as
        a request for 0 A.
        """
        hit = 0
        if not (desired == desired and abs(desired) != float('inf')):
            desired = 0.0
        lim = self.max_current
        if desired > lim:
            desired, hit = lim, 1
        elif desired < -lim:
            desired, hit = -lim, 1
        step = self.max_step if dt is None else self.max_slew * dt
        if desired > previous + step:
            desired, hit = previous + step, hit | 2
        elif desired < previous - step:
            desired, hit = previous - step, hit | 2
        return desired, _HITS[hit]
