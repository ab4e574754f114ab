"""The live text view of ``grip-force monitor``: force and state topics, refreshed in place.

:func:`render` and :func:`plain_line` are pure functions of a :class:`Snapshot`;
:func:`monitor` subscribes (through :class:`~grip_force_ros.lab.demo.recorder.RecorderNode`
without a bag) and redraws. On a terminal the block is redrawn in place with ANSI
cursor moves; when stdout is not a TTY one plain line is printed per refresh.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from typing import Any, TextIO

from grip_force_ros import topics
from grip_force_ros.lab.demo.messages import FIELDS, TOPIC_TYPES, diagnostic_summary, values_of

_LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


@dataclass
class Snapshot:
    """What the monitor knows at one refresh."""

    elapsed: float = 0.0                                    # s since the monitor started
    values: dict[str, float] = field(default_factory=dict)  # field name -> SI value
    ages: dict[str, float] = field(default_factory=dict)    # topic -> s since its last message
    rates: dict[str, float] = field(default_factory=dict)   # topic -> Hz over the last refresh
    diagnostics: list[dict[str, Any]] = field(default_factory=list)


def controller_mode(diagnostics: list[dict[str, Any]]) -> str:
    """Return the controller's state/mode from /diagnostics ('?' if none seen)."""
    for status in diagnostics:
        if 'controller' in status['name'].lower():
            values = status['values']
            for key in ('mode', 'state'):
                if key in values:
                    return values[key]
            return status['message'] or _LEVELS.get(status['level'], '?')
    return '?'


def _v(snapshot: Snapshot, key: str, fmt: str = '7.3f') -> str:
    v = snapshot.values.get(key)
    return format(v, fmt) if isinstance(v, float) and math.isfinite(v) else '    -  '


def _rate(snapshot: Snapshot, topic: str) -> str:
    age = snapshot.ages.get(topic)
    if age is None:
        return '(no data)'
    if age > 1.0:
        return f'(silent {age:.1f} s)'
    return f'({snapshot.rates.get(topic, 0.0):5.0f} Hz)'


def render(snapshot: Snapshot, header: str = '') -> list[str]:
    """Render the block of lines the terminal view shows."""
    s = snapshot
    lines = [f'grip-force monitor  {header}  t = {s.elapsed:6.1f} s',
             f'  master angle     {_v(s, "master_angle")} rad        {_rate(s, topics.MASTER_JS)}',
             f'  target force     {_v(s, "target_force")} N          '
             f'{_rate(s, topics.TARGET_FORCE)}',
             f'  estimated force  {_v(s, "estimated_force")} N          '
             f'{_rate(s, topics.ESTIMATED_FORCE)}   pull-out {_v(s, "pull_out_force")} N',
             f'  estimate band    {_v(s, "estimate_band_low")} .. '
             f'{_v(s, "estimate_band_high").strip()} N  {_rate(s, topics.ESTIMATE_BAND)}',
             f'  measured force   {_v(s, "measured_force")} N          '
             f'{_rate(s, topics.MEASURED_FORCE)}',
             f'  current command  {_v(s, "current_command")} A          '
             f'{_rate(s, topics.SERVO_CURRENT)}   measured {_v(s, "current")} A',
             f'  jaw / wrist      {_v(s, "jaw_angle")} / {_v(s, "wrist_angle").strip()} rad  '
             f'{_rate(s, topics.INSTRUMENT_JS)}',
             f'  mode             {controller_mode(s.diagnostics)}']
    if not s.diagnostics:
        lines.append('  diagnostics      (none yet)')
    for status in s.diagnostics:
        extra = ', '.join(f'{k}={v}' for k, v in list(status['values'].items())[:4])
        lines.append(f"  [{_LEVELS.get(status['level'], '?'):5s}] {status['name']}: "
                     f"{status['message']}" + (f' ({extra})' if extra else ''))
    return lines


def plain_line(snapshot: Snapshot) -> str:
    """One line per refresh for logs and pipes."""
    s = snapshot
    worst = max((d['level'] for d in s.diagnostics), default=None)
    return (f't={s.elapsed:.2f} master={_v(s, "master_angle", ".3f")} '
            f'target={_v(s, "target_force", ".3f")} estimated={_v(s, "estimated_force", ".3f")} '
            f'measured={_v(s, "measured_force", ".3f")} '
            f'current_cmd={_v(s, "current_command", ".3f")} '
            f'current={_v(s, "current", ".3f")} mode={controller_mode(s.diagnostics)} '
            f'diag={_LEVELS.get(worst, "-") if worst is not None else "-"}')


class _Collector:
    """Snapshots from a bag-less RecorderNode."""

    def __init__(self, node):
        self.node = node
        self.started = time.monotonic()
        self._last_counts = {t: 0 for t in TOPIC_TYPES}
        self._last_time = time.monotonic()
        self._diagnostics: dict[str, dict] = {}

    def snapshot(self) -> Snapshot:
        now_wall, now = time.time(), time.monotonic()
        snap = Snapshot(elapsed=now - self.started)
        dt = max(now - self._last_time, 1e-6)
        for topic in TOPIC_TYPES:
            count = self.node.count(topic)
            snap.rates[topic] = (count - self._last_counts[topic]) / dt
            self._last_counts[topic] = count
            item = self.node.latest(topic)
            if item is None:
                continue
            received, msg = item
            snap.ages[topic] = now_wall - received
            if topic == topics.DIAGNOSTICS:
                for status in diagnostic_summary(msg):   # keep the newest per status name
                    self._diagnostics[status['name']] = status
            elif topic in FIELDS:
                snap.values.update(values_of(topic, msg))
        self._last_time = now
        snap.diagnostics = list(self._diagnostics.values())
        return snap


def monitor(duration: float | None = None, period: float = 0.2, stream: TextIO | None = None,
            domain_id: int | None = None, tty: bool | None = None) -> int:
    """Show the live view until ``duration`` (s) or Ctrl-C; returns the number of refreshes.

    Parameters
    ----------
    duration : float, optional
        Stop after this long (s); default: run until interrupted.
    period : float
        Refresh period (s).
    stream : text stream
        Where to draw (default stdout).
    domain_id : int, optional
        ROS domain to watch (default: ROS_DOMAIN_ID of the environment).
    tty : bool, optional
        Force the in-place view (True) or plain lines (False); default: ask the stream.
    """
    import sys

    import rclpy
    from rclpy.context import Context

    from grip_force_ros.lab.demo.recorder import RecorderNode, SpinThread, interrupt_behind

    stream = stream or sys.stdout
    tty = stream.isatty() if tty is None else tty
    if domain_id is None:
        domain_id = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = RecorderNode(None, context=context, node_name=f'grip_force_monitor_{os.getpid()}')
    spinner = SpinThread(node).start()
    collector = _Collector(node)
    header = f'domain {domain_id}'
    drawn = 0
    refreshes = 0
    try:
        while True:
            time.sleep(period)
            snap = collector.snapshot()
            if tty:
                lines = render(snap, header)
                if drawn:
                    stream.write(f'\033[{drawn}F')   # back to the first line of the block
                stream.write(''.join(f'\033[2K{line}\n' for line in lines))
                drawn = len(lines)
            else:
                stream.write(plain_line(snap) + '\n')
            stream.flush()
            refreshes += 1
            if duration is not None and snap.elapsed >= duration:
                break
    except KeyboardInterrupt:
        pass
    except Exception as exc:
        if not interrupt_behind(exc):     # a Ctrl-C inside ``latest``'s deserialization
            raise
    finally:
        spinner.stop()
        node.destroy_node()
        rclpy.shutdown(context=context)
    return refreshes
