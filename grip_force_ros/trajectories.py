"""Master gripper trajectories: scripted tasks and replays. No rclpy here.

A trajectory maps time since its start (s) to the master gripper opening angle
(rad, 0 = closed, positive = open) and names the phase of the task at that time.
The ``master`` node publishes one; the demo, the tests and the offline
comparisons evaluate the same objects without ROS.

>>> traj = needle_grasp()
>>> round(traj.angle(0.0), 3), traj.phase(0.0)
(0.8, 'approach')
>>> traj.phase(traj.duration - 0.01)
'release'

Kinds (the ``trajectory`` parameter of the master node):

``needle_grasp``
    approach open, close on the needle, hold, pull test (gripper held closed
    while the needle is pulled), release.
``sine_sweep``
    a chirp between open and closed, frequency rising linearly.
``steps``
    a staircase of openings, each held for a while.
``csv``
    replay of a CSV with columns ``t`` (s) and ``master_angle`` (rad).
``rosbag``
    replay of ``position[0]`` of ``master/gripper/measured_js`` from a rosbag2
    (MCAP or sqlite3, read with ``rosbags``).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from grip_force_ros.params.schema import ParameterError, ParamSpec

KINDS = ('needle_grasp', 'sine_sweep', 'steps', 'csv', 'rosbag')

#: Parameters of the master node (not instrument parameters: they live here,
#: next to the trajectories they configure, in the schema's ParamSpec form).
MASTER_SPECS = [
    ParamSpec('trajectory', 'string', 'needle_grasp', '',
              'Which master trajectory to publish.', choices=KINDS, group='master'),
    ParamSpec('trajectory_file', 'string', '', '',
              'CSV (t, master_angle) or rosbag2 directory/file to replay for '
              'trajectory=csv/rosbag.',
              group='master'),
    ParamSpec('master_rate', 'double', 250.0, 'Hz',
              'Rate of master/gripper/measured_js.', min=1.0, max=2000.0, group='master'),
    ParamSpec('master_open_angle', 'double', 0.8, 'rad',
              'Gripper opening of the scripted trajectories when open.', min=0.0, max=1.6,
              group='master'),
    ParamSpec('master_closed_angle', 'double', 0.0, 'rad',
              'Gripper opening of the scripted trajectories when squeezed closed.', min=-0.5,
              max=1.6, group='master'),
    ParamSpec('time_scale', 'double', 1.0, '',
              'Duration multiplier of the scripted trajectories (2 = twice as slow).',
              min=0.05, max=100.0, group='master'),
    ParamSpec('repeat', 'bool', False, '',
              'Start the trajectory again when it ends (otherwise hold the last angle).',
              group='master'),
    ParamSpec('exit_when_done', 'bool', False, '',
              'Exit the node (code 0) shortly after a non-repeating trajectory ends.',
              group='master'),
    ParamSpec('start_when_subscribed', 'bool', True, '',
              'Hold the trajectory at its start until a subscriber (the controller) is matched, '
              'so DDS discovery on a loaded machine cannot swallow the start of the task.',
              group='master'),
]


@dataclass(frozen=True)
class Segment:
    """One phase: move from ``start`` to ``end`` (rad) in ``duration`` (s), smoothly."""

    phase: str
    duration: float
    start: float
    end: float


class Trajectory:
    """Master opening angle over time, from breakpoints.

    Parameters
    ----------
    times : sequence of float
        Breakpoint times (s), strictly rising, first 0.
    angles : sequence of float
        Gripper opening at each breakpoint (rad).
    phases : sequence of str
        Name of the phase that *starts* at each breakpoint (last one unused).
    smooth : bool
        Cosine blend between breakpoints (zero velocity at each) instead of
        linear interpolation. Scripted tasks are smooth; replays are linear.
    """

    def __init__(self, times: Sequence[float], angles: Sequence[float],
                 phases: Sequence[str] | None = None, smooth: bool = False):
        self.times = np.asarray(times, dtype=float)
        self.angles = np.asarray(angles, dtype=float)
        if self.times.ndim != 1 or self.times.shape != self.angles.shape or self.times.size < 1:
            raise ParameterError('trajectory: times and angles must be 1-D of the same length >= 1')
        if not (np.all(np.isfinite(self.times)) and np.all(np.isfinite(self.angles))):
            raise ParameterError('trajectory: times and angles must be finite')
        if np.any(np.diff(self.times) <= 0):
            raise ParameterError('trajectory: times must be strictly rising')
        self.times = self.times - self.times[0]
        self.phases = tuple(phases) if phases is not None else ('replay',) * self.times.size
        self.smooth = smooth
        self._t_list = self.times.tolist()
        self._a_list = self.angles.tolist()

    @property
    def duration(self) -> float:
        """Time of the last breakpoint (s)."""
        return float(self.times[-1])

    def angle(self, t):
        """Gripper opening (rad) at ``t`` (s; scalar or array). Held before 0 and after the end."""
        if np.ndim(t) == 0:
            return self._angle_scalar(float(t))
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        if self.times.size == 1:
            return np.full_like(t, self.angles[0])
        i = np.clip(np.searchsorted(self.times, t, side='right') - 1, 0, self.times.size - 2)
        t0, t1 = self.times[i], self.times[i + 1]
        s = (t - t0) / (t1 - t0)
        if self.smooth:
            s = 0.5 - 0.5 * np.cos(np.pi * s)
        return self.angles[i] + s * (self.angles[i + 1] - self.angles[i])

    def _angle_scalar(self, t: float) -> float:
        """Fast path for the publishing timer."""
        times, angles = self._t_list, self._a_list
        if t <= 0.0 or len(times) == 1:
            return angles[0]
        if t >= times[-1]:
            return angles[-1]
        i = int(np.searchsorted(self.times, t, side='right')) - 1
        s = (t - times[i]) / (times[i + 1] - times[i])
        if self.smooth:
            s = 0.5 - 0.5 * math.cos(math.pi * s)
        return angles[i] + s * (angles[i + 1] - angles[i])

    def phase(self, t: float) -> str:
        """Name of the task phase at ``t`` (s); 'done' after the end."""
        if t >= self.duration:
            return 'done'
        i = int(np.searchsorted(self.times, max(t, 0.0), side='right')) - 1
        return self.phases[i]

    def phase_times(self) -> dict[str, tuple[float, float]]:
        """Phase name -> (start, end) time (s) of its first occurrence."""
        out: dict[str, tuple[float, float]] = {}
        for i, name in enumerate(self.phases[:-1]):
            if name not in out:
                out[name] = (float(self.times[i]), float(self.times[i + 1]))
        return out


def from_segments(segments: Sequence[Segment]) -> Trajectory:
    """Build a smooth trajectory from consecutive segments (each ends where the next starts)."""
    times, angles, phases = [0.0], [segments[0].start], []
    for seg in segments:
        if seg.duration <= 0:
            raise ParameterError(
                f'trajectory: phase {seg.phase!r} has duration {seg.duration} s <= 0')
        if seg.start != angles[-1]:  # a jump: add a very short blend
            times.append(times[-1] + 1e-3)
            angles.append(seg.start)
            phases.append(seg.phase)
        times.append(times[-1] + seg.duration)
        angles.append(seg.end)
        phases.append(seg.phase)
    phases.append('done')
    return Trajectory(times, angles, phases, smooth=True)


def needle_grasp(open_angle: float = 0.8, closed_angle: float = 0.0, time_scale: float = 1.0,
                 approach: float = 0.5, close: float = 0.8, hold: float = 1.5, pull: float = 1.5,
                 release: float = 0.7) -> Trajectory:
    """Build the needle grasp task.

    Parameters
    ----------
    open_angle, closed_angle : float
        Gripper opening when open and when squeezed (rad).
    time_scale : float
        Multiplies every duration.
    approach, close, hold, pull, release : float
        Phase durations (s): held open; closing from open to closed; held
        closed (the force settles: the steady hold force is measured here);
        held closed while the needle is pulled (pull-out test); opening.
    """
    k = time_scale
    return from_segments([
        Segment('approach', approach * k, open_angle, open_angle),
        Segment('close', close * k, open_angle, closed_angle),
        Segment('hold', hold * k, closed_angle, closed_angle),
        Segment('pull', pull * k, closed_angle, closed_angle),
        Segment('release', release * k, closed_angle, open_angle),
    ])


def sine_sweep(open_angle: float = 0.8, closed_angle: float = 0.0, time_scale: float = 1.0,
               f_start: float = 0.2, f_end: float = 3.0, duration: float = 10.0,
               rate: float = 1000.0) -> Trajectory:
    """Build a linear chirp between ``open_angle`` and ``closed_angle`` (rad).

    Frequency rises from ``f_start`` to ``f_end`` (Hz) over ``duration`` (s,
    times ``time_scale``); sampled at ``rate`` (Hz) and interpolated linearly.
    """
    T = duration * time_scale
    t = np.arange(0.0, T + 0.5 / rate, 1.0 / rate)
    f0, f1 = f_start / time_scale, f_end / time_scale
    phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / T * t ** 2)
    mid, amp = 0.5 * (open_angle + closed_angle), 0.5 * (open_angle - closed_angle)
    angle = mid + amp * np.cos(phase)  # starts open
    return Trajectory(t, angle, ['sweep'] * t.size)


def steps(open_angle: float = 0.8, closed_angle: float = 0.0, time_scale: float = 1.0,
          levels: Sequence[float] = (1.0, 0.5, 0.25, 0.0, 0.25, 0.0, 1.0),
          step_duration: float = 1.0) -> Trajectory:
    """Build a staircase; ``levels`` are fractions of the opening (1 = open, 0 = closed)."""
    angles = [closed_angle + lv * (open_angle - closed_angle) for lv in levels]
    hold = step_duration * time_scale
    times, values, phases = [], [], []
    t = 0.0
    for i, a in enumerate(angles):
        if i:  # a 2 ms ramp makes each step a clean, finite-slope edge
            t += 2e-3
        times += [t, t + hold - 2e-3]
        values += [a, a]
        phases += [f'step{i}', f'step{i}']
        t += hold - 2e-3
    phases[-1] = 'done'
    return Trajectory(times, values, phases)


def read_csv(path: str | Path) -> Trajectory:
    """Replay of a CSV with header columns ``t`` (s) and ``master_angle`` (rad)."""
    path = Path(path)
    try:
        with path.open(newline='') as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ParameterError(f'{path}: cannot read master trajectory: {exc}') from exc
    if not rows or 't' not in rows[0] or 'master_angle' not in rows[0]:
        raise ParameterError(f'{path}: expected CSV columns t, master_angle')
    try:
        t = [float(r['t']) for r in rows]
        a = [float(r['master_angle']) for r in rows]
    except (TypeError, ValueError) as exc:
        raise ParameterError(f'{path}: non-numeric value in t or master_angle: {exc}') from exc
    try:
        return Trajectory(t, a)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from None


def read_rosbag(path: str | Path, topic: str | None = None) -> Trajectory:
    """Replay of ``position[0]`` of the master topic of a rosbag2 (MCAP or sqlite3)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from grip_force_ros.topics import MASTER_JS
    want = topic or MASTER_JS
    path = Path(path)
    t, a = [], []
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            conns = [c for c in reader.connections if c.topic.lstrip('/') == want.lstrip('/')]
            if not conns:
                raise ParameterError(f'{path}: no topic {want!r} in the bag')
            for conn, stamp, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                if len(msg.position) >= 1 and math.isfinite(msg.position[0]):
                    t.append(stamp * 1e-9)
                    a.append(float(msg.position[0]))
    except ParameterError:
        raise
    except Exception as exc:  # rosbags raises its own errors for unreadable bags
        raise ParameterError(f'{path}: cannot read rosbag2: {exc}') from exc
    if not t:
        raise ParameterError(f'{path}: no usable master samples on {want!r}')
    t_arr, a_arr = np.asarray(t), np.asarray(a)
    keep = np.concatenate([[True], np.diff(t_arr) > 0])  # drop duplicate stamps
    return Trajectory(t_arr[keep], a_arr[keep])


def make_trajectory(kind: str = 'needle_grasp', trajectory_file: str = '', *,
                    master_open_angle: float = 0.8, master_closed_angle: float = 0.0,
                    time_scale: float = 1.0, **_ignored) -> Trajectory:
    """Build a trajectory from the master node's parameters (see :data:`MASTER_SPECS`)."""
    scripted = dict(open_angle=master_open_angle, closed_angle=master_closed_angle,
                    time_scale=time_scale)
    if kind == 'needle_grasp':
        return needle_grasp(**scripted)
    if kind == 'sine_sweep':
        return sine_sweep(**scripted)
    if kind == 'steps':
        return steps(**scripted)
    if kind in ('csv', 'rosbag'):
        if not trajectory_file:
            raise ParameterError(f"parameter 'trajectory_file': required for trajectory={kind!r}")
        return read_csv(trajectory_file) if kind == 'csv' else read_rosbag(trajectory_file)
    raise ParameterError(f"parameter 'trajectory': {kind!r} is not one of {list(KINDS)}")
