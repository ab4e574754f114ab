"""What the controller runs on the instrument to identify it: the grasp staircase, the tare. No ROS.

:class:`CurrentStaircase`
    The short load-cell grasp of ``~/calibrate`` (and of the demo's instrument
    comparison): the motor current climbs in slow ramps through
    :data:`CALIBRATION_SHARES` of :func:`calibration_current`, holding each level
    :data:`CALIBRATION_HOLD` s, then ramps back to 0 A. Slow ramps up keep the pulley
    friction in its loading direction, the direction the model describes
    (:func:`~grip_force_ros.identify.calibration.steady_plateaus` keeps the loading
    plateaus only).
:class:`GraspRecording`
    The samples of that grasp, written as a log CSV (docs/design.md contract) that
    ``grip-force calibrate`` fits (:func:`~grip_force_ros.identify.fit_instrument`).
:class:`SensorZero`
    The tare: the mean load-cell force and the mean difference between measured and
    commanded current over a short window with the jaw open and no grip force, which
    are the two sensors' offsets.

The ROS side (the controller node's ``~/calibrate`` and ``~/tare`` services) feeds
them one sample per control step and applies the current limits; see
docs/ros_interface.md, "Services".
"""
from __future__ import annotations

import bisect
import math
from pathlib import Path
from typing import Sequence

#: Calibration staircase: shares of the top current (:func:`calibration_current`).
CALIBRATION_SHARES = (0.25, 0.5, 0.75, 1.0)
#: Time each level is held (s): six 0.1 s plateau windows after the settling.
CALIBRATION_HOLD = 0.6
#: Ramp from the start to the first level (s): the jaw closes from open onto the load cell.
CALIBRATION_FIRST_RAMP = 0.5
#: Ramp between levels, and from the top level back to 0 A (s).
CALIBRATION_RAMP = 0.3


def calibration_current(params, obj: str = 'needle', model=None) -> float:
    """Return the current (A) of the top calibration level.

    That is ``grip_force_max`` on ``obj`` per the model of ``params`` (``model``: that
    model if already built), at most ``max_current``.
    """
    if model is None:
        from grip_force_ros.model import GripForceModel
        model = GripForceModel(params)
    current = float(model.inverse(params.grip_force_max, 0.0, 0.0, obj))
    return min(current, params.max_current)


class CurrentStaircase:
    """The calibration grasp's current command over time: a piecewise-linear staircase.

    Parameters
    ----------
    top : float
        Current of the top level (A), > 0.
    start : float
        Current at ``t = 0`` (A): the command in force when the staircase starts.
    shares : sequence of float
        Levels as shares of ``top``, rising.
    hold, first_ramp, ramp : float
        Hold time of each level, ramp to the first level, ramp between levels and down
        to 0 A (s).

    Raises
    ------
    ValueError
        A non-positive or non-finite top current or time, or levels not rising in (0, 1].
    """

    def __init__(self, top: float, start: float = 0.0, shares: Sequence[float] = CALIBRATION_SHARES,
                 hold: float = CALIBRATION_HOLD, first_ramp: float = CALIBRATION_FIRST_RAMP,
                 ramp: float = CALIBRATION_RAMP):
        if not (math.isfinite(top) and top > 0.0):
            raise ValueError(f'calibration top current must be > 0 A, got {top!r}')
        if not all(math.isfinite(x) and x > 0.0 for x in (hold, first_ramp, ramp)):
            raise ValueError('calibration hold and ramp times must be > 0 s')
        shares = tuple(float(s) for s in shares)
        if not shares or any(not 0.0 < s <= 1.0 for s in shares) or list(shares) != sorted(set(shares)):
            raise ValueError(f'calibration levels must rise within (0, 1], got {shares}')
        times, currents = [0.0], [float(start)]
        t = 0.0
        for k, share in enumerate(shares):
            t += first_ramp if k == 0 else ramp
            times.append(t)
            currents.append(share * top)
            t += hold
            times.append(t)
            currents.append(share * top)
        self.hold_end = t                   # s, end of the top level's hold
        times.append(t + ramp)
        currents.append(0.0)
        self.times = tuple(times)           # s, corners of the staircase
        self.currents = tuple(currents)     # A, current at each corner
        self.duration = times[-1]           # s
        self.levels = tuple(s * top for s in shares)   # A

    def current(self, t: float) -> float:
        """Return the current command (A) at ``t`` s after the start (0 A after the end)."""
        times, currents = self.times, self.currents
        if t <= 0.0:
            return currents[0]
        if t >= self.duration:
            return 0.0
        k = bisect.bisect_right(times, t)   # times[k - 1] <= t < times[k]
        t0, t1 = times[k - 1], times[k]
        return currents[k - 1] + (currents[k] - currents[k - 1]) * (t - t0) / (t1 - t0)


class GraspRecording:
    """The calibration grasp written as it runs: a log CSV (docs/design.md contract), SI units.

    One formatted line per sample (a few microseconds), so that nothing is left to write
    when the grasp ends; :func:`~grip_force_ros.logs.read_log` and ``grip-force calibrate
    --log`` read the file.

    Parameters
    ----------
    path : path
        The CSV to write (its directory must exist).
    """

    COLUMNS = ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force')

    def __init__(self, path):
        self.path = Path(path)
        self._file = open(self.path, 'w', encoding='utf-8')
        self._file.write(','.join(self.COLUMNS) + '\n')
        self.rows = 0
        self._last_t = -math.inf

    def add(self, t: float, current: float, motor_angle: float, wrist_angle: float,
            jaw_angle: float, grip_force: float) -> None:
        """Write one sample: time (s), measured current (A), angles (rad), load cell (N).

        A sample not later than the previous one is skipped (log time rises strictly).
        """
        if t > self._last_t:
            self._last_t = t
            self._file.write(f'{t:.10g},{current:.10g},{motor_angle:.10g},{wrist_angle:.10g},'
                             f'{jaw_angle:.10g},{grip_force:.10g}\n')
            self.rows += 1

    def close(self) -> None:
        """Close the file (again: nothing)."""
        self._file.close()


class SensorZero:
    """The tare: mean load-cell force and mean current error over a window (SI).

    With the jaw open and no grip force the load cell carries no force and the
    current loop follows its command, so what the sensors read beyond that is their
    offset: the load cell's mean reading (N), and the mean of measured minus commanded
    current (A).

    Parameters
    ----------
    duration : float
        Length of the window (s), > 0.
    """

    def __init__(self, duration: float):
        if not (math.isfinite(duration) and duration > 0.0):
            raise ValueError(f'tare duration must be > 0 s, got {duration!r}')
        self.duration = duration
        self.start = math.nan      # s, time of the first sample
        self.samples = 0
        self.force_samples = 0
        self._current_error = 0.0  # A, sum
        self._force = 0.0          # N, sum

    def add(self, t: float, measured_current: float, commanded_current: float,
            force: float | None) -> bool:
        """Add one sample (s, A, A, N or None without a load-cell sample); True once complete."""
        if self.samples == 0:
            self.start = t
        self.samples += 1
        self._current_error += measured_current - commanded_current
        if force is not None:
            self.force_samples += 1
            self._force += force
        return self.done(t)

    def done(self, t: float) -> bool:
        """Return whether the window is complete at ``t`` (s)."""
        return self.samples > 1 and t - self.start >= self.duration

    @property
    def current_offset(self) -> float:
        """Mean measured minus commanded current (A)."""
        return self._current_error / self.samples if self.samples else math.nan

    @property
    def force_offset(self) -> float:
        """Mean load-cell force (N); NaN without load-cell samples."""
        return self._force / self.force_samples if self.force_samples else math.nan
