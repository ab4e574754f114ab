"""Controller inputs: the latest good sample of each source, validated in one place.

The ROS node fills a :class:`ControlInputs` from its subscription callbacks (cheap:
a few float assignments and comparisons, no allocation on the good path); the
controller reads it once per period. Every sample carries its receive time (s, on the
controller's clock) so the watchdog is ROS-free.
"""
from __future__ import annotations

import math
import re

#: numbers in a rejection reason, replaced by '#' in the counter key (bounded set of keys)
_NUMBER = re.compile(r'[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?|nan|inf', re.IGNORECASE)
#: largest number of distinct counter keys kept; further kinds count as '<source>: other'
MAX_REJECTION_KINDS = 64

#: Input sources, in the order the controller checks them.
SOURCES = ('master', 'instrument', 'actuator', 'force')
#: The sources an instrument (or its simulation) publishes; the master is the console.
INSTRUMENT_SOURCES = SOURCES[1:]
#: The schema parameter of each source's watchdog timeout (s): older than it by receive time,
#: the input is lost and the output goes to the safe state (docs/control.md).
TIMEOUT_PARAMS = {'master': 'master_watchdog_timeout', 'instrument': 'watchdog_timeout',
                  'actuator': 'actuator_watchdog_timeout', 'force': 'force_watchdog_timeout'}
#: An input older than this many of its own sample intervals (and not lost) is late: control
#: goes on with its last value and the controller counts it (at least two samples in a row
#: missed: one missed sample is the jitter of a 1 kHz stream on a loaded machine).
LATE_FACTOR = 3.0
#: Gain of the running estimate of each source's sample interval (per sample; ~10 samples).
INTERVAL_GAIN = 0.1
#: A gap enters the interval estimate at most this many times the estimate (a stall or a lost
#: input moves it by 30 % at most; after a 10x burst, normal gaps count late for ~5 samples).
INTERVAL_CLIP = 4.0

_NAN = math.nan
_isfinite = math.isfinite
#: What a ``set_*`` returns: (fresh, rejection reason); constant tuples, no allocation.
_FRESH = (True, None)
_DUPLICATE = (False, None)
_REJECTED = False


def source_timeouts(params) -> dict:
    """Return source -> watchdog timeout (s) of a ``ParamSet`` (:data:`TIMEOUT_PARAMS`)."""
    return {source: float(params[name]) for source, name in TIMEOUT_PARAMS.items()}


def next_interval(interval: float, gap: float) -> float:
    """Update a running estimate of a stream's sample interval (s) with one gap (s).

    The first gap starts it (``interval`` NaN); then an exponential average with gain
    :data:`INTERVAL_GAIN` of the gaps, each clipped to :data:`INTERVAL_CLIP` times the
    estimate. A NaN or non-positive gap (the first sample, the same receive time) leaves it.
    """
    if not gap > 0.0:
        return interval
    if interval != interval:
        return gap
    if gap > INTERVAL_CLIP * interval:
        gap = INTERVAL_CLIP * interval
    return interval + INTERVAL_GAIN * (gap - interval)


class ControlInputs:
    """Latest accepted sample of each input source, with its receive time and fault state.

    Parameters
    ----------
    master_angle_min, master_angle_max : float
        Range of the master gripper angle (rad); outside it the angle is clamped and flagged.
    master_angle_tolerance : float
        How far outside its range a master angle may be before it is invalid (rad).
    jaw_angle_min, jaw_angle_max : float
        Plausible measured jaw angles (rad).
    wrist_angle_limit : float
        Largest plausible |wrist pitch| (rad).
    current_limit : float
        Largest plausible |measured current| (A).
    force_limit : float
        Largest plausible |measured grip force| (N).
    stamp_future_tolerance : float
        A stamp more than this ahead of the receive time is invalid (s).

    Notes
    -----
    Each ``set_*`` method returns ``(fresh, reason)``: ``fresh`` (bool) is True when the
    sample was accepted as a new one (stored, its receive time refreshed), ``reason`` is None
    or why the sample was rejected (str). A rejected sample (``(False, reason)``) is not
    stored; the source is marked faulted (its ``*_fault`` attribute holds the reason) until
    the next accepted sample. A sample whose stamp equals the previous stamp is a duplicate:
    ignored without refreshing the receive time (``(False, None)``). A stamp of NaN or 0.0
    (an unset ROS header) skips the stamp checks.
    """

    __slots__ = (
        'master_angle_min', 'master_angle_max', 'master_angle_tolerance', 'jaw_angle_min',
        'jaw_angle_max', 'wrist_angle_limit', 'current_limit', 'force_limit',
        'stamp_future_tolerance',
        # master: gripper angle [rad] (clamped to its range), flag set when clamped
        'master_angle', 'master_clamped', 'master_time', 'master_stamp', 'master_fault',
        # instrument joints: wrist pitch [rad], jaw angle [rad], jaw velocity [rad/s]
        'wrist_angle', 'jaw_angle', 'jaw_velocity', 'instrument_time', 'instrument_stamp',
        'instrument_fault',
        # actuator: measured motor current [A], drum angle [rad], drum velocity [rad/s]
        'measured_current', 'motor_angle', 'motor_velocity', 'actuator_time', 'actuator_stamp',
        'actuator_fault',
        # force sensor: measured grip force [N]
        'measured_force', 'force_time', 'force_stamp', 'force_fault',
        # running estimate of each source's sample interval [s] (next_interval)
        'master_interval', 'instrument_interval', 'actuator_interval', 'force_interval',
        'rejected',
    )

    def __init__(self, *, master_angle_min, master_angle_max, master_angle_tolerance,
                 jaw_angle_min, jaw_angle_max, wrist_angle_limit,
                 current_limit, force_limit, stamp_future_tolerance):
        # no defaults here: the ranges come from the parameter schema (from_params)
        self.master_angle_min = float(master_angle_min)
        self.master_angle_max = float(master_angle_max)
        self.master_angle_tolerance = float(master_angle_tolerance)
        self.jaw_angle_min = float(jaw_angle_min)
        self.jaw_angle_max = float(jaw_angle_max)
        self.wrist_angle_limit = float(wrist_angle_limit)
        self.current_limit = float(current_limit)
        self.force_limit = float(force_limit)
        self.stamp_future_tolerance = float(stamp_future_tolerance)
        self.master_angle = self.master_angle_max
        self.master_clamped = False
        self.wrist_angle = self.jaw_angle = self.jaw_velocity = 0.0
        self.measured_current = self.motor_angle = self.motor_velocity = 0.0
        self.measured_force = 0.0
        for source in SOURCES:
            setattr(self, f'{source}_time', _NAN)    # never received
            setattr(self, f'{source}_stamp', _NAN)
            setattr(self, f'{source}_fault', None)
            setattr(self, f'{source}_interval', _NAN)
        #: reason with its numbers replaced by '#' -> number of samples rejected for it
        #: (for /diagnostics; at most MAX_REJECTION_KINDS keys + one 'other' per source)
        self.rejected: dict[str, int] = {}

    @classmethod
    def from_params(cls, params) -> 'ControlInputs':
        """Build inputs with the plausibility ranges of an instrument ``ParamSet``."""
        return cls(master_angle_min=params.master_angle_min,
                   master_angle_max=params.master_angle_max,
                   master_angle_tolerance=params.master_angle_tolerance,
                   jaw_angle_min=params.jaw_angle_min, jaw_angle_max=params.jaw_angle_max,
                   wrist_angle_limit=params.wrist_angle_limit,
                   # measured current may overshoot the command; 2x + 0.1 A is implausible
                   current_limit=2.0 * params.max_current + 0.1,
                   force_limit=10.0 * max(params.max_grip_force, 1.0),
                   stamp_future_tolerance=params.stamp_future_tolerance)

    # ------------------------------------------------------------------ helpers
    def reject(self, source: str, receive_time: float, reason: str) -> str:
        """Record a rejected sample of ``source`` (also for malformed messages).

        Returns the full reason string, e.g. ``'instrument: jaw angle nan not finite'``.
        """
        if source not in SOURCES:
            raise ValueError(f'unknown input source {source!r}; one of {SOURCES}')
        text = f'{source}: {reason}'
        setattr(self, f'{source}_fault', text)
        key = _NUMBER.sub('#', text)
        counts = self.rejected
        if key not in counts and len(counts) >= MAX_REJECTION_KINDS:
            key = f'{source}: other'
        counts[key] = counts.get(key, 0) + 1
        return text

    def _check_times(self, source: str, receive_time: float, stamp: float, last_stamp: float):
        """None if the times are acceptable, 'duplicate', or a rejection reason."""
        if not _isfinite(receive_time):
            return f'receive time {receive_time!r} not finite'
        if stamp != stamp or stamp == 0.0:   # nan, or 0 = unset header stamp: no stamp checks
            return None
        if not _isfinite(stamp):
            return f'stamp {stamp!r} not finite'
        if stamp - receive_time > self.stamp_future_tolerance:
            return f'stamp {stamp - receive_time:.3f} s ahead of the receive time'
        if last_stamp == last_stamp:
            if stamp == last_stamp:
                return 'duplicate'
            if stamp < last_stamp:
                return f'stamp went backwards by {last_stamp - stamp:.6f} s'
        return None

    # ------------------------------------------------------------------ setters
    def set_master(self, receive_time: float, master_angle: float, stamp: float = _NAN):
        """Master gripper opening angle (rad). Returns ``(fresh, reason)`` (class notes)."""
        try:
            receive_time, master_angle, stamp = float(receive_time), float(master_angle), float(stamp)
        except (TypeError, ValueError):
            return _REJECTED, self.reject('master', receive_time, 'a value is not a number')
        why = self._check_times('master', receive_time, stamp, self.master_stamp)
        if why is not None:
            if why == 'duplicate':
                return _DUPLICATE
            if stamp == stamp and _isfinite(stamp):
                self.master_stamp = stamp     # a jump back is rejected once, not forever
            return _REJECTED, self.reject('master', receive_time, why)
        angle = master_angle
        if not _isfinite(angle):
            return _REJECTED, self.reject('master', receive_time, f'gripper angle {angle!r} not finite')
        lo, hi, tol = self.master_angle_min, self.master_angle_max, self.master_angle_tolerance
        if angle < lo - tol or angle > hi + tol:
            return _REJECTED, self.reject('master', receive_time,
                                          f'gripper angle {angle:.3f} rad outside '
                                          f'[{lo - tol:.3f}, {hi + tol:.3f}]')
        clamped = False
        if angle < lo:
            angle, clamped = lo, True
        elif angle > hi:
            angle, clamped = hi, True
        self.master_angle = angle
        self.master_clamped = clamped
        self.master_interval = next_interval(self.master_interval, receive_time - self.master_time)
        self.master_time = receive_time
        self.master_stamp = stamp
        self.master_fault = None
        return _FRESH

    def set_instrument(self, receive_time: float, wrist_angle: float, jaw_angle: float,
                       jaw_velocity: float = 0.0, stamp: float = _NAN):
        """Wrist pitch (rad), jaw angle (rad, 0 = closed), jaw velocity (rad/s)."""
        try:
            receive_time, stamp = float(receive_time), float(stamp)
            wrist_angle, jaw_angle, jaw_velocity = float(wrist_angle), float(jaw_angle), float(jaw_velocity)
        except (TypeError, ValueError):
            return _REJECTED, self.reject('instrument', receive_time, 'a value is not a number')
        why = self._check_times('instrument', receive_time, stamp, self.instrument_stamp)
        if why is not None:
            if why == 'duplicate':
                return _DUPLICATE
            if stamp == stamp and _isfinite(stamp):
                self.instrument_stamp = stamp
            return _REJECTED, self.reject('instrument', receive_time, why)
        if not (_isfinite(wrist_angle) and _isfinite(jaw_angle) and _isfinite(jaw_velocity)):
            return _REJECTED, self.reject('instrument', receive_time,
                                          f'non-finite value (wrist {wrist_angle!r}, jaw {jaw_angle!r}, '
                                          f'jaw velocity {jaw_velocity!r})')
        if abs(wrist_angle) > self.wrist_angle_limit:
            return _REJECTED, self.reject('instrument', receive_time,
                                          f'wrist angle {wrist_angle:.3f} rad beyond '
                                          f'+-{self.wrist_angle_limit:.3f}')
        if jaw_angle < self.jaw_angle_min or jaw_angle > self.jaw_angle_max:
            return _REJECTED, self.reject('instrument', receive_time,
                                          f'jaw angle {jaw_angle:.3f} rad outside '
                                          f'[{self.jaw_angle_min:.3f}, {self.jaw_angle_max:.3f}]')
        self.wrist_angle = wrist_angle
        self.jaw_angle = jaw_angle
        self.jaw_velocity = jaw_velocity
        self.instrument_interval = next_interval(self.instrument_interval,
                                                 receive_time - self.instrument_time)
        self.instrument_time = receive_time
        self.instrument_stamp = stamp
        self.instrument_fault = None
        return _FRESH

    def set_actuator(self, receive_time: float, measured_current: float, motor_angle: float = 0.0,
                     motor_velocity: float = 0.0, stamp: float = _NAN):
        """Measured motor current (A), drum angle (rad), drum velocity (rad/s)."""
        try:
            receive_time, stamp = float(receive_time), float(stamp)
            measured_current = float(measured_current)
            motor_angle, motor_velocity = float(motor_angle), float(motor_velocity)
        except (TypeError, ValueError):
            return _REJECTED, self.reject('actuator', receive_time, 'a value is not a number')
        why = self._check_times('actuator', receive_time, stamp, self.actuator_stamp)
        if why is not None:
            if why == 'duplicate':
                return _DUPLICATE
            if stamp == stamp and _isfinite(stamp):
                self.actuator_stamp = stamp
            return _REJECTED, self.reject('actuator', receive_time, why)
        if not (_isfinite(measured_current) and _isfinite(motor_angle) and _isfinite(motor_velocity)):
            return _REJECTED, self.reject('actuator', receive_time,
                                          f'non-finite value (current {measured_current!r}, motor angle '
                                          f'{motor_angle!r}, motor velocity {motor_velocity!r})')
        if abs(measured_current) > self.current_limit:
            return _REJECTED, self.reject('actuator', receive_time,
                                          f'measured current {measured_current:.3f} A beyond '
                                          f'+-{self.current_limit:.3f}')
        self.measured_current = measured_current
        self.motor_angle = motor_angle
        self.motor_velocity = motor_velocity
        self.actuator_interval = next_interval(self.actuator_interval, receive_time - self.actuator_time)
        self.actuator_time = receive_time
        self.actuator_stamp = stamp
        self.actuator_fault = None
        return _FRESH

    def set_force(self, receive_time: float, grip_force: float, stamp: float = _NAN):
        """Measured grip force of a force sensor (N)."""
        try:
            receive_time, grip_force, stamp = float(receive_time), float(grip_force), float(stamp)
        except (TypeError, ValueError):
            return _REJECTED, self.reject('force', receive_time, 'a value is not a number')
        why = self._check_times('force', receive_time, stamp, self.force_stamp)
        if why is not None:
            if why == 'duplicate':
                return _DUPLICATE
            if stamp == stamp and _isfinite(stamp):
                self.force_stamp = stamp
            return _REJECTED, self.reject('force', receive_time, why)
        if not _isfinite(grip_force):
            return _REJECTED, self.reject('force', receive_time, f'grip force {grip_force!r} not finite')
        if abs(grip_force) > self.force_limit:
            return _REJECTED, self.reject('force', receive_time,
                                          f'grip force {grip_force:.3f} N beyond +-{self.force_limit:.1f}')
        self.measured_force = grip_force
        self.force_interval = next_interval(self.force_interval, receive_time - self.force_time)
        self.force_time = receive_time
        self.force_stamp = stamp
        self.force_fault = None
        return _FRESH
