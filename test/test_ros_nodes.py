"""Closed loop over loopback DDS with the real nodes.

The controller runs in this process (its ``GripController.step`` is wrapped to
record every period); the simulated instrument and the master run as separate
processes (``python -m grip_force_ros.lab.node_process <name>``: the installed
executables' ``main``, their teardown watched), as they do in the demo. Discovery is on
localhost and each test process has its own ROS_DOMAIN_ID (conftest.py).
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from _control_oracle import StepClock
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped

from grip_force_ros import topics
from grip_force_ros.nodes.common import STATE_SUB_QOS
from grip_force_ros.nodes.controller import ControllerNode
from grip_force_ros.lab.harness import RosRunner
from grip_force_ros.lab.processes import NodeProcess
from grip_force_ros.params import load_params_file

pytestmark = pytest.mark.ros

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'paper_needle_driver.yaml'


class Recorder:
    """Wraps ``controller.step``: one row per control period."""

    FIELDS = ('now', 'mode', 'target', 'estimate', 'command', 'limits', 'instrument_time',
              'actuator_time', 'master_time', 'reasons')

    def __init__(self, node: ControllerNode):
        self.rows: list[tuple] = []
        self.measured: list[tuple[float, float]] = []    # (controller clock s, load cell N)
        self.diagnostics: list[DiagnosticStatus] = []     # the controller's, as published
        self._node = node
        inner = node.controller.step

        def step(now, inputs, interlock=None):
            out = inner(now, inputs, interlock)
            self.rows.append((now, out.mode, out.target_force, out.estimated_force,
                              out.current_command, out.limits_hit, inputs.instrument_time,
                              inputs.actuator_time, inputs.master_time, out.reasons))
            return out
        node.controller.step = step

    def on_measured(self, msg: WrenchStamped) -> None:
        self.measured.append((self._node.get_clock().now().nanoseconds * 1e-9,
                              msg.wrench.force.z))

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.diagnostics += [s for s in msg.status if s.name.endswith('controller')]

    def column(self, name: str) -> np.ndarray:
        i = self.FIELDS.index(name)
        kind = object if name in ('mode', 'limits', 'reasons') else float
        return np.array([r[i] for r in self.rows], dtype=kind)


def run_loop(tmp_path, duration: float, controller: dict | None = None, sim: dict | None = None,
             master: dict | None = None, during=None):
    """Run controller (here) + sim + master (processes) for ``duration`` s of grasp.

    ``during(ros, recorder, sim_process)`` runs once the loop is up, instead of sleeping.
    """
    with RosRunner() as ros:
        ctl = ros.add(ControllerNode, **(controller or {}))
        rec = Recorder(ctl)
        probe = ros.plain_node('probe')
        probe.create_subscription(WrenchStamped, topics.MEASURED_FORCE, rec.on_measured,
                                  STATE_SUB_QOS)
        probe.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, rec.on_diagnostics, 50)
        ros.start()
        sim_proc = NodeProcess('sim_instrument', params_file=str(CONFIG), params=sim,
                               log_path=str(tmp_path / 'sim.log'))
        try:
            # the master starts once the plant is up, so the task starts on a live loop
            assert ros.wait_for(lambda: ctl.inputs.instrument_time == ctl.inputs.instrument_time,
                                15.0), 'no instrument state from the sim process'
            master_proc = NodeProcess('master', params_file=str(CONFIG), params=master,
                                      log_path=str(tmp_path / 'master.log'))
            try:
                assert ros.wait_for(lambda: ctl.inputs.master_time == ctl.inputs.master_time,
                                    15.0), 'no master input from the master process'
                if during is not None:
                    during(ros, rec, sim_proc)
                else:
                    time.sleep(duration)
            finally:
                master_proc.stop()
        finally:
            sim_proc.stop()
        assert ros.spin_error is None, ros.spin_error
    return rec


def hold_window(rec: Recorder, target: float, settle: float):
    """Rows of the longest run with the target constant at ``target``, after ``settle`` s.

    The longest run: a watchdog trip on a loaded machine (target 0 while safe) splits a hold.
    """
    now, tgt = rec.column('now'), rec.column('target')
    at = np.concatenate([[False], np.isclose(tgt, target, atol=1e-9), [False]])
    edges = np.flatnonzero(np.diff(at.astype(int)))
    if edges.size == 0:
        return None, None
    starts, ends = edges[::2], edges[1::2]
    longest = np.argmax(ends - starts)
    idx = np.arange(starts[longest], ends[longest])
    start_time = now[idx[0]]
    return start_time, idx[now[idx] >= start_time + settle]


def _hold_samples(rec, target):
    """(controller rows, load-cell forces) of the hold at ``target``, 0.5 s after it starts."""
    start, hold = hold_window(rec, target, settle=0.5)
    assert hold is not None and hold.size > 500, 'the grasp never held its full target force'
    now = rec.column('now')
    meas_t = np.array([m[0] for m in rec.measured])
    meas_f = np.array([m[1] for m in rec.measured])
    in_hold = (meas_t >= now[hold[0]]) & (meas_t <= now[hold[-1]])
    return hold, meas_f[in_hold], meas_t, meas_f


def test_needle_grasp_reaches_target_force_with_load_cell_feedback(tmp_path):
    params = load_params_file(CONFIG)
    rec = run_loop(tmp_path, 5.5, controller={'force_sensor_enabled': True},
                   master={'trajectory': 'needle_grasp'})
    target = params.grip_force_max
    hold, force, meas_t, meas_f = _hold_samples(rec, target)
    # within 2.5 % of the target on average, every sample within 10 % (sensor noise 0.02 N)
    assert abs(force.mean() - target) < 0.025 * target, (force.mean(), target)
    assert np.all(np.abs(force - target) < 0.10 * target), (force.min(), force.max())
    # time to reach the target: from the master closing past contact to within 5 %
    now = rec.column('now')
    grip_rows = np.flatnonzero(rec.column('mode') == 'grip')
    t_grip = now[grip_rows[0]]
    reached = meas_t[(meas_t > t_grip) & (np.abs(meas_f - target) < 0.05 * target)]
    assert reached.size and reached[0] - t_grip < 1.5, 'target force not reached within 1.5 s'
    # the loop steps once per actuator state: its median period is the sim's median state
    # interval (1 ms on a quiet machine; a loaded one delays the sim's timer and both grow
    # alike: 1.25 ms at load 9); a controller stepping on its timer besides, or skipping
    # states, would differ. The period itself is reported, not judged (machine-dependent).
    running = rec.column('mode') != 'safe'
    periods = np.diff(now[running])
    states = np.diff(np.unique(rec.column('actuator_time')[running]))
    print(f'median control period {np.median(periods) * 1e3:.3f} ms, median actuator state '
          f'interval {np.median(states) * 1e3:.3f} ms (load average {os.getloadavg()[0]:.1f})')
    assert np.median(periods) == pytest.approx(np.median(states), rel=0.2)


#: Sensorless hold on a plant that matches its YAML: the load cell's mean may differ from the
#: target by the model's residual. Expected within ~2 % (docs/control.md: +1.0 % for the same
#: grasp on the same sim without ROS; three runs here: -1.6 %, -0.1 %, +0.2 %); bound 3 %:
#: after a move the stick band's state can be 1-3 % off, because
#: the sim's drum tension lags gear*K*I/r0 (drum inertia, cable compliance). The load cell's
#: own noise (0.02 N std) averages to ~1e-3 N over the hold's > 500 samples.
SENSORLESS_HOLD_TOLERANCE = 0.03


def test_needle_grasp_sensorless_tracks_its_estimate(tmp_path):
    """Without a sensor the loop closes on the model estimate: the estimate must hold the
    target, and with the plant as its YAML says the load cell must too, within the model's
    residual (:data:`SENSORLESS_HOLD_TOLERANCE`)."""
    params = load_params_file(CONFIG)
    rec = run_loop(tmp_path, 5.5, controller={'force_sensor_enabled': False},
                   master={'trajectory': 'needle_grasp'})
    target = params.grip_force_max
    hold, force, _, _ = _hold_samples(rec, target)
    estimate = rec.column('estimate')[hold]
    assert abs(estimate.mean() - target) < 0.01 * target, (estimate.mean(), target)
    assert np.all(np.abs(estimate - target) < 0.10 * target)
    print(f'sensorless hold: estimate {estimate.mean():.3f} N, load cell {force.mean():.3f} N, '
          f'target {target:.3f} N')
    assert np.isfinite(force).all() and force.size > 100
    assert abs(force.mean() - target) < SENSORLESS_HOLD_TOLERANCE * target, (force.mean(), target)


def _summary(rec):
    from collections import Counter
    return (Counter(rec.column('mode')), Counter(str(r) for r in rec.column('reasons')).most_common(4),
            Counter(str(x) for x in rec.column('limits')).most_common(4),
            float(np.max(rec.column('target'), initial=0)), float(np.max(rec.column('command'), initial=0)))


def test_current_and_slew_limits_hold(tmp_path):
    # a current limit well below what 4 N needs (~0.29 A): the limit must hold, and say so
    max_current, slew = 0.15, 20.0
    limits_at = Recorder.FIELDS.index('limits')

    def until_the_limit_has_acted(ros, rec, sim_proc):
        # wait for the event itself (not a fixed time: start-up is slow on a loaded machine),
        # then long enough for /diagnostics (10 Hz) to report it
        assert ros.wait_for(lambda: rec.rows and 'current_limit' in rec.rows[-1][limits_at],
                            20.0), ('the current limit never acted', _summary(rec))
        time.sleep(0.5)

    rec = run_loop(tmp_path, 0.0,
                   controller={'force_sensor_enabled': True, 'max_current': max_current,
                               'max_current_slew': slew},
                   master={'trajectory': 'needle_grasp', 'time_scale': 0.6},
                   during=until_the_limit_has_acted)
    command = rec.column('command')
    assert np.all(np.abs(command) <= max_current + 1e-12)
    # the slew limit acts on the time measured between steps (test/_control_oracle.py)
    params = load_params_file(CONFIG)
    clock = StepClock()
    allowed = np.array([slew * clock.dt(float(t), params) for t in rec.column('now')])
    assert np.all(np.abs(np.diff(command)) <= allowed[1:] * (1 + 1e-9) + 1e-15)
    limits = rec.column('limits')
    assert any('current_limit' in hit for hit in limits), 'the current limit never acted'
    assert np.max(command) == pytest.approx(max_current)
    # and /diagnostics says so: WARN, with the limit named
    hit = [s for s in rec.diagnostics
           if 'current_limit' in {kv.key: kv.value for kv in s.values}['limits_hit']]
    assert hit and all(s.level == DiagnosticStatus.WARN for s in hit if s.message.startswith('grip'))


def test_stale_input_trips_watchdog_and_control_resumes_without_a_jump(tmp_path):
    params = load_params_file(CONFIG)
    timeout, period = params.watchdog_timeout, 1.0 / params.control_rate
    marks = {}

    def freeze_the_plant(ros, rec, sim_proc):
        # wait for a steady grip, freeze the sim process (no more joint states), thaw it
        assert ros.wait_for(lambda: rec.rows and rec.rows[-1][1] == 'grip'
                            and rec.rows[-1][2] == params.grip_force_max, 10.0)
        time.sleep(0.5)
        marks['freeze'] = len(rec.rows)
        sim_proc.pause()
        time.sleep(0.3)
        marks['thaw'] = len(rec.rows)
        sim_proc.resume()
        time.sleep(1.0)

    master = {'trajectory': 'needle_grasp', 'time_scale': 3.0}
    rec = run_loop(tmp_path, 0.0, controller={'force_sensor_enabled': True}, master=master,
                   during=freeze_the_plant)
    rows = rec.rows
    now = rec.column('now')
    mode = rec.column('mode')
    inst = rec.column('instrument_time')
    freeze, thaw = marks['freeze'], marks['thaw']
    # the first period whose instrument input is older than the timeout is already safe,
    # so the output is in the safe state within two control periods of the input going stale
    stale = np.flatnonzero((now - inst > timeout) & (np.arange(len(rows)) >= freeze))
    assert stale.size, 'the frozen plant never made the input stale'
    first_stale = stale[0]
    assert mode[first_stale] == 'safe'
    safe_since = np.flatnonzero(mode[freeze:] == 'safe')[0] + freeze
    # counted in control periods (wall-clock latency depends on the machine's load: printed)
    assert safe_since <= first_stale
    print(f'watchdog: safe {1e3 * (now[safe_since] - inst[safe_since] - timeout):.2f} ms after '
          f'the input became stale (period {1e3 * period:.1f} ms)')
    # while safe the command ramps to 0 A at the slew limit, never away from 0, in each
    # stretch of safe rows: a stall of this process between the freeze mark and the pause
    # lets control resume in between (safe rows 0 -> 0.085 A -> 0; a stall inside the safe
    # state cannot do that: the controller's safe ramp only goes toward 0 A)
    command = rec.column('command')
    safe_rows = np.arange(safe_since, thaw)
    safe_rows = safe_rows[mode[safe_rows] == 'safe']
    for stretch in np.split(safe_rows, np.flatnonzero(np.diff(safe_rows) > 1) + 1):
        assert np.all(np.diff(np.abs(command[stretch])) <= 1e-12), command[stretch]
    # the watchdog says what went stale, in the output and on /diagnostics (ERROR)
    assert any('stale instrument input' in r for r in rec.column('reasons')[first_stale])
    tripped = [s for s in rec.diagnostics
               if {kv.key: kv.value for kv in s.values}['watchdog'] == 'tripped'
               and 'stale instrument input' in s.message]
    assert tripped and all(s.level == DiagnosticStatus.ERROR for s in tripped)
    # control resumes after the thaw: grip again, and no current jump at the switch
    resumed = np.flatnonzero(mode[thaw:] == 'grip')
    assert resumed.size, 'control did not resume after the inputs came back'
    k = resumed[0] + thaw
    # the controller steps on the measured time between states, so a step after a late state
    # may move the current by the slew limit times that longer step (e.g. a 1.39 ms step,
    # 0.139 A at 100 A/s)
    allowed = params.max_current_slew * np.maximum(np.diff(now), period) * (1 + 1e-9)
    assert abs(command[k] - command[k - 1]) <= allowed[k - 1]
    jumps = np.abs(np.diff(command[k - 5:k + 200]))
    assert np.all(jumps <= allowed[k - 5:k - 5 + jumps.size])
