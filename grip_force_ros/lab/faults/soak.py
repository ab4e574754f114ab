"""Soak: the closed loop at 1 kHz for minutes, watching memory, timing drift and missed periods.

``master`` (repeating needle grasp), ``sim_instrument`` and ``controller`` run as separate
processes, as in the demo. A monitor node in this process records every current command,
the header stamp of every target force (the controller's clock at each control step; the
command itself carries the stamp of the actuator state it answers) and the controller's
/diagnostics; ``psutil`` samples the resident memory (RSS) and CPU of each process.

Reported (:func:`run_soak`):

* memory: RSS of each process after the warm-up and at the end (MB), and the slope of a
  straight-line fit over all samples after the warm-up (MB/min);
* latency drift: controller period statistics (mean, std, p99, max, ms) of the first and
  the last full minute, from the step stamps;
* missed periods: command intervals longer than 1.5 control periods (per minute and in
  total), the controller's own ``late_periods`` counter, commands that never arrived
  (stamp gaps beyond one period that the controller did not report as late are counted
  as lost messages);
* safe-state reports: /diagnostics messages in mode ``safe`` after the warm-up (watchdog
  trips caused by stalls under load).

A benchmark (prints figures), not a test: ``grip-force soak --minutes 10``.

The monitor spins an EventsExecutor (``GRIP_FORCE_SOAK_MONITOR_EXECUTOR=single`` for the
SingleThreadedExecutor: its RSS grew ~16 MB/min at 1 kHz in the first 10-minute run, the
monitor's own growth, not the nodes').
"""
from __future__ import annotations

import array
import math
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from grip_force_ros.control import Mode

#: Time given to discovery and the first grasp before measuring (s).
WARMUP = 15.0
#: RSS sampling interval (s).
RSS_INTERVAL = 5.0


def _period_stats(intervals: np.ndarray, period: float) -> dict:
    """Statistics of controller periods (s) in ms, and the count longer than 1.5 periods."""
    if intervals.size == 0:
        return {'periods': 0}
    ms = intervals * 1e3
    return {
        'periods': int(intervals.size),
        'mean_ms': round(float(ms.mean()), 4),
        'std_ms': round(float(ms.std()), 4),
        'p50_ms': round(float(np.percentile(ms, 50)), 4),
        'p99_ms': round(float(np.percentile(ms, 99)), 4),
        'max_ms': round(float(ms.max()), 3),
        'missed': int(np.count_nonzero(intervals > 1.5 * period)),
    }


class _Recorder:
    """Step stamps, commands and diagnostics, binned per minute (callbacks of the monitor node)."""

    def __init__(self, period: float, start: float):
        self.period = period
        self.start = start            # monotonic time when measuring starts
        self.lock = threading.Lock()
        self.stamps = array.array('d')  # s, step stamps (target force) of the current minute
        self.minutes: list[dict] = []  # closed minutes
        self.last_stamp: float | None = None
        self.minute_index = 0
        self.safe_reports: list[str] = []
        self.diag: dict[str, str] = {}
        self.diag_first: dict[str, str] | None = None
        self.commands = 0
        self.non_finite = 0
        self.max_abs_command = 0.0

    def on_command(self, msg) -> None:
        if time.monotonic() < self.start:
            return
        value = msg.effort[0] if len(msg.effort) else math.nan
        self.commands += 1
        if not math.isfinite(value):
            self.non_finite += 1
        else:
            self.max_abs_command = max(self.max_abs_command, abs(value))

    def on_step(self, msg) -> None:
        """Record a target force: one per control step, stamped with the controller's clock at it."""
        now = time.monotonic()
        if now < self.start:
            return
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        minute = int((now - self.start) // 60.0)
        with self.lock:
            if minute != self.minute_index:
                self._close_minute()
                self.minute_index = minute
            self.stamps.append(stamp)

    def _close_minute(self) -> None:
        stamps = np.frombuffer(self.stamps, dtype=float) if len(self.stamps) else np.zeros(0)
        if self.last_stamp is not None and stamps.size:
            stamps = np.concatenate(([self.last_stamp], stamps))
        intervals = np.diff(stamps) if stamps.size > 1 else np.zeros(0)
        stats = _period_stats(intervals, self.period)
        stats['minute'] = self.minute_index + 1
        self.minutes.append(stats)
        if len(self.stamps):
            self.last_stamp = self.stamps[-1]
        self.stamps = array.array('d')

    def on_diagnostics(self, msg) -> None:
        if time.monotonic() < self.start:
            return
        for status in msg.status:
            if not status.name.endswith('controller'):
                continue
            values = {kv.key: kv.value for kv in status.values}
            if self.diag_first is None:
                self.diag_first = values
            self.diag = values
            if values.get('mode') == Mode.SAFE:
                self.safe_reports.append(status.message)

    def finish(self) -> None:
        with self.lock:
            self._close_minute()


def run_soak(minutes: float = 10.0, config: str | os.PathLike | None = None,
             progress=None) -> dict:
    """Run the closed loop for ``minutes`` (after a warm-up) and return the figures.

    Parameters
    ----------
    minutes : float
        Measured duration (min), after :data:`WARMUP` s.
    config : path or str, optional
        Instrument YAML (path or shipped name) for the three processes; default
        :data:`~grip_force_ros.params.files.DEFAULT_INSTRUMENT`.
    progress : callable, optional
        ``progress(text)`` once a minute.
    """
    import psutil
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    from grip_force_ros import topics
    from grip_force_ros.nodes.common import RECORD_QOS
    from grip_force_ros.lab.harness import RosRunner
    from grip_force_ros.lab.processes import NodeProcess
    from grip_force_ros.params import load_params_file
    from grip_force_ros.params.files import instrument_path

    config = instrument_path(config)
    params = load_params_file(config)
    period = 1.0 / params.control_rate
    logdir = Path(tempfile.mkdtemp(prefix='grip_force_soak_'))
    qos = RECORD_QOS
    t_start = time.monotonic()
    rec = _Recorder(period, t_start + WARMUP)
    rss: dict[str, list[tuple[float, float]]] = {}
    cpu: dict[str, float] = {}
    with RosRunner(executor_kind=os.environ.get('GRIP_FORCE_SOAK_MONITOR_EXECUTOR', 'events')) as ros:
        node = ros.plain_node('soak_monitor')
        node.create_subscription(JointState, topics.SERVO_CURRENT, rec.on_command, qos)
        node.create_subscription(WrenchStamped, topics.TARGET_FORCE, rec.on_step, qos)
        node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, rec.on_diagnostics, 10)
        ros.start()
        procs = {
            'sim_instrument': NodeProcess('sim_instrument', params_file=str(config),
                                          log_path=str(logdir / 'sim_instrument.log')),
            'controller': NodeProcess('controller', params_file=str(config),
                                      log_path=str(logdir / 'controller.log')),
            'master': NodeProcess('master', params_file=str(config), params={'repeat': True},
                                  log_path=str(logdir / 'master.log')),
        }
        handles = {name: psutil.Process(p.pid) for name, p in procs.items()}
        handles['monitor (this process)'] = psutil.Process(os.getpid())
        try:
            end = t_start + WARMUP + minutes * 60.0
            next_report = t_start + WARMUP + 60.0
            started_cpu = False
            while time.monotonic() < end:
                now = time.monotonic()
                for name, proc in procs.items():
                    if not proc.alive():
                        raise RuntimeError(f'{name} exited with {proc.popen.returncode} '
                                           f'(log: {logdir / (name + ".log")})')
                if now >= t_start + WARMUP:
                    if not started_cpu:
                        for h in handles.values():
                            h.cpu_percent(None)
                        started_cpu = True
                    for name, h in handles.items():
                        rss.setdefault(name, []).append((now - t_start - WARMUP,
                                                         h.memory_info().rss / 2**20))
                if progress and now >= next_report:
                    progress(f'{(now - t_start - WARMUP) / 60:.0f} min: {rec.commands} commands, '
                             f"late periods {rec.diag.get('late_periods', '?')}, "
                             f"controller RSS {rss['controller'][-1][1]:.1f} MB")
                    next_report += 60.0
                time.sleep(max(0.0, min(RSS_INTERVAL, end - time.monotonic())))
            cpu = {name: round(h.cpu_percent(None), 1) for name, h in handles.items()}
            for name, h in handles.items():
                rss.setdefault(name, []).append((time.monotonic() - t_start - WARMUP,
                                                 h.memory_info().rss / 2**20))
        finally:
            for proc in procs.values():
                proc.stop()
        rec.finish()

    memory = {}
    for name, samples in rss.items():
        t = np.array([s[0] for s in samples]) / 60.0
        mb = np.array([s[1] for s in samples])
        slope = float(np.polyfit(t, mb, 1)[0]) if len(samples) > 2 else math.nan
        memory[name] = {'rss_start_mb': round(float(mb[0]), 2), 'rss_end_mb': round(float(mb[-1]), 2),
                        'growth_mb': round(float(mb[-1] - mb[0]), 2),
                        'slope_mb_per_min': round(slope, 4), 'samples': len(samples)}
    full = [m for m in rec.minutes if m.get('periods', 0) > 0.5 * 60.0 / period]
    first, last = (full[0], full[-1]) if full else ({}, {})
    diag, diag0 = rec.diag, rec.diag_first or {}

    def _delta(key):
        try:
            return int(diag[key]) - int(diag0.get(key, 0))
        except (KeyError, ValueError):
            return None

    expected = minutes * 60.0 / period
    report = {
        'config': str(config),
        'minutes': minutes,
        'control_rate_hz': params.control_rate,
        'memory': memory,
        'cpu_percent_of_one_core': cpu,
        'period_first_minute': first,
        'period_last_minute': last,
        'period_drift_ms': {k: round(last[k] - first[k], 4) for k in ('mean_ms', 'std_ms', 'p99_ms')
                            if k in first and k in last},
        'per_minute': rec.minutes,
        'commands_received': rec.commands,
        'commands_expected': int(expected),
        'missed_periods': int(sum(m.get('missed', 0) for m in rec.minutes)),
        'controller_late_periods': _delta('late_periods'),
        'controller_periods': _delta('periods'),
        'controller_tick_mean_us': diag.get('tick_mean_us'),
        'controller_tick_max_us': diag.get('tick_max_us'),
        'safe_state_reports': len(rec.safe_reports),
        'safe_state_reasons': sorted(set(rec.safe_reports))[:5],
        'non_finite_commands': rec.non_finite,
        'max_abs_command_a': round(rec.max_abs_command, 4),
        'max_current_a': params.max_current,
        'load_average_1min': round(os.getloadavg()[0], 2),
        'cpu_count': os.cpu_count(),
        'logs': str(logdir),
    }
    return report
