"""PID with back-calculation anti-windup, filtered derivative on the measurement, bumpless preset.

Every time-dependent term steps on the time ``dt`` (s) the caller measured since the last
step (default: the nominal ``period``), so the same gains behave the same at any state rate
(docs/control.md, "Rate independence").
"""
from __future__ import annotations

import math


class PID:
    """Discrete PID on the measured step time, for one loop (force or jaw angle).

    ``u = kp*e + integral - sign*kd*d_filtered(measurement)/dt``, ``e = sign*(setpoint -
    measurement)``. The derivative acts on the measurement (no kick on setpoint steps),
    low-passed by a first-order filter of time constant ``derivative_filter_time`` (backward
    Euler). Anti-windup by back-calculation: after the caller limits the total command it
    calls :meth:`track` with the unlimited and the applied output, and the integrator moves
    toward the applied one with time constant ``tracking_time``.

    Parameters
    ----------
    kp : float
        Proportional gain (output unit per error unit, e.g. A/N).
    ki : float
        Integral gain (output unit per error unit per s).
    kd : float
        Derivative gain (output unit * s per error unit).
    derivative_filter_time : float
        Time constant of the derivative filter (s).
    period : float
        Nominal step time (s): the ``dt`` of :meth:`update` and :meth:`track` when the caller
        gives none.
    tracking_time : float
        Back-calculation time constant (s); raised to the step time if smaller (the
        back-calculation is stable for ``dt <= tracking_time``).
    sign : float
        +1 when the output must rise with ``setpoint - measurement`` (force loop), -1 when it
        must rise with ``measurement - setpoint`` (jaw angle: positive current closes).
    integral_limit : float
        Hard bound on |integral| (output unit), a second guard against windup.
    bumpless_time : float
        Time constant (s) with which the transfer offset of :meth:`preset` decays.

    Notes
    -----
    Bumpless transfer (:meth:`preset`) zeroes the integral and stores the difference
    between the wanted output and the PID's own output as an offset that decays
    exponentially with ``bumpless_time``: the output is continuous at the switch and
    becomes the plain PID output within a few ``bumpless_time``, without the integral
    having to unwind a proportional term (which would take ``kp/ki`` seconds).

    Time steps: the integral is forward Euler in ``dt``, the derivative filter backward
    Euler, ``d <- (tf*d + (m - m_last)) / (tf + dt)``, which never divides by ``dt`` (a
    step of ``dt = 0`` leaves the integral and moves the derivative by the measurement
    change only), and the bumpless offset decays by ``exp(-dt/bumpless_time)``.
    """

    __slots__ = ('kp', 'ki', 'kd', 'filter_time', 'period', 'tracking_time', 'sign',
                 'integral_limit', 'integral', 'derivative', 'last_measurement', 'primed',
                 'error', 'offset', 'bumpless_time')

    def __init__(self, kp: float, ki: float, kd: float, derivative_filter_time: float,
                 period: float, tracking_time: float = 0.01, sign: float = 1.0,
                 integral_limit: float = 1.0, bumpless_time: float = 0.02):
        if not period > 0.0:
            raise ValueError(f'period must be > 0 s, got {period!r}')
        self.kp, self.ki, self.kd = float(kp), float(ki), float(kd)
        self.filter_time = float(derivative_filter_time)
        self.period = float(period)
        self.tracking_time = float(tracking_time)
        self.sign = 1.0 if sign >= 0 else -1.0
        self.integral_limit = float(integral_limit)
        self.bumpless_time = max(float(bumpless_time), 1e-9)
        self.reset()

    def reset(self) -> None:
        """Zero integral and derivative state."""
        self.integral = 0.0             # output unit
        self.derivative = 0.0           # filtered d(measurement)/dt, measurement unit / s
        self.last_measurement = 0.0
        self.primed = False             # last_measurement valid
        self.error = 0.0
        self.offset = 0.0               # output unit, bumpless transfer offset (decays)

    def update(self, setpoint: float, measurement: float, dt: float | None = None) -> float:
        """One step of ``dt`` s (default the nominal period): the unlimited output.

        Call :meth:`track` with the same ``dt`` after limiting.
        """
        if dt is None:
            dt = self.period
        if self.primed:
            tf = self.filter_time
            self.derivative = (tf * self.derivative + (measurement - self.last_measurement)) / (tf + dt)
        self.last_measurement = measurement
        self.primed = True
        error = self.sign * (setpoint - measurement)
        self.error = error
        offset = self.offset
        if offset:
            self.offset = offset * math.exp(-dt / self.bumpless_time)
        return self.kp * error + self.integral + offset - self.sign * self.kd * self.derivative

    def track(self, unlimited: float, applied: float, dt: float | None = None) -> None:
        """Integrate the error over ``dt`` s, with back-calculation toward the applied output."""
        if dt is None:
            dt = self.period
        tracking = self.tracking_time if self.tracking_time > dt else dt
        integral = self.integral + dt * (self.ki * self.error
                                         + (applied - unlimited) / tracking)
        lim = self.integral_limit
        self.integral = lim if integral > lim else (-lim if integral < -lim else integral)

    def preset(self, output: float, setpoint: float, measurement: float) -> None:
        """Bumpless transfer: make the next :meth:`update` at these values return ``output``.

        The integral restarts at 0, the derivative at this measurement (no derivative
        kick); the difference is an offset that decays with ``bumpless_time``.
        """
        self.derivative = 0.0
        self.last_measurement = measurement
        self.primed = True
        error = self.sign * (setpoint - measurement)
        self.error = error
        self.integral = 0.0
        self.offset = output - self.kp * error
