"""The demo's figure and figures follow the samples' header stamps (no ROS graph).

In a run where a process stalls, a time base that follows the receive times moves the
master's whole trace: the recorder's queue of the 250 Hz master holds 4 s of it (1000
messages), so a master stream that falls behind once stays late (e.g. 2.5 s off the jaw
and force traces) for the rest of the run.
These tests write a synthetic bag (rosbags, as the recorder writes one) whose receive times
are delayed by stalls while the header stamps are right, and check the arrays handed to
the plot, the analysis' figures and the safe-state entries against the stamps.
"""
from __future__ import annotations

import numpy as np
import pytest

from grip_force_ros import topics
from grip_force_ros.lab.demo import analysis
from grip_force_ros.lab.demo.series import (CLOCK_STAMP, CLOCK_UNSTAMPED, read_bag_series,
                                            resample, sample_clock)

T0 = 1_700_000_000.0        # s, the system clock at the master's start of its task
LATENCY = 0.0005            # s, an undisturbed delivery
MASTER_LAG = 2.5            # s, how late the master stream reaches the recorder after its stall
MASTER_STALL_AT = 0.3       # s into the task, the stall after which the master stream lags
RECORDER_STALL = (1.2, 3.2)  # s into the task: instrument states stamped here arrive at its end
SIM_SILENT = (0.05, 0.35)   # s into the task: the sim publishes no actuator state (approach)
SAFE_AT = 0.2               # s into the task, a safe-state entry (approach)
ERROR = 0.05                # N, load cell - target where there is a target


def _spec(tmp_path=None):
    """The run the synthetic bag stands for: a sim that sends its state split (two topics)."""
    from grip_force_ros.lab.demo.run import RunSpec
    from grip_force_ros.params.files import instrument_path
    config = instrument_path('paper_needle_driver')
    if tmp_path is not None:
        split = tmp_path / 'split_state.yaml'
        split.write_text(config.read_text().replace(
            'ros__parameters:', 'ros__parameters:\n    state_message: split', 1))
        config = split
    return RunSpec(config=config, duration=4.0)


def _target(tau, trajectory):
    """Target grip force (N) at task time ``tau`` (s): 4 N from the hold to the release."""
    phases = trajectory.phase_times()
    return np.where((tau >= phases['hold'][0]) & (tau < phases['release'][0]), 4.0, 0.0)


def write_stalled_bag(path, trajectory):
    """Write a demo bag with stalls: delayed receive times, right stamps.

    * master (250 Hz): from 0.5 s before its task; after ``MASTER_STALL_AT`` every message
      reaches the recorder ``MASTER_LAG`` late (a backlog never worked off);
    * instrument joint states (1 kHz): those stamped in ``RECORDER_STALL`` all arrive at
      its end (a recorder that stalled 2 s);
    * actuator states (1 kHz): none stamped in ``SIM_SILENT`` (the sim itself stalled);
    * target, load cell, estimate, command (1 kHz) on time;
    * /diagnostics (10 Hz) of the controller, with a safe-state entry at ``SAFE_AT``, all
      received ``MASTER_LAG`` late.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    ty = store.types
    js_type, wrench_type = 'sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped'
    diag_type = 'diagnostic_msgs/msg/DiagnosticArray'

    def header(stamp):
        sec = int(stamp)
        return ty['std_msgs/msg/Header'](
            stamp=ty['builtin_interfaces/msg/Time'](sec=sec, nanosec=int(round((stamp - sec) * 1e9))),
            frame_id='')

    def joints(stamp, names, position, velocity=None, effort=None):
        n = len(names)
        return ty[js_type](header=header(stamp), name=list(names),
                           position=np.asarray(position, float),
                           velocity=np.asarray(velocity if velocity is not None else [0.0] * n, float),
                           effort=np.asarray(effort if effort is not None else [0.0] * n, float))

    def wrench(stamp, z, x=0.0):
        vec = ty['geometry_msgs/msg/Vector3']
        return ty[wrench_type](header=header(stamp), wrench=ty['geometry_msgs/msg/Wrench'](
            force=vec(x=x, y=0.0, z=z), torque=vec(x=0.0, y=0.0, z=0.0)))

    messages = []      # (receive time [s], topic, type, message)
    for tau in np.arange(-0.5, trajectory.duration + 0.3, 0.004):
        angle = float(trajectory.angle(max(tau, 0.0)))
        late = MASTER_LAG if tau > MASTER_STALL_AT else 0.0
        messages.append((T0 + tau + LATENCY + late, topics.MASTER_JS, js_type,
                         joints(T0 + tau, [topics.MASTER_JOINT], [angle])))
    for tau in np.arange(-0.5, trajectory.duration + 0.3, 0.001):
        stamp = T0 + tau
        angle = 0.5 * float(trajectory.angle(max(tau, 0.0)))
        target = float(_target(tau, trajectory))
        measured = target + ERROR if target > 0 else 0.0
        received = stamp + LATENCY
        if RECORDER_STALL[0] <= tau < RECORDER_STALL[1]:
            received = T0 + RECORDER_STALL[1] + LATENCY
        messages.append((received, topics.INSTRUMENT_JS, js_type,
                         joints(stamp, [topics.WRIST_JOINT, topics.JAW_JOINT], [0.0, angle])))
        if not SIM_SILENT[0] <= tau < SIM_SILENT[1]:
            messages.append((stamp + LATENCY, topics.ACTUATOR_JS, js_type,
                             joints(stamp, [topics.DRUM_JOINT], [0.0], [0.0], [0.1 * measured])))
        messages.append((stamp + LATENCY, topics.SERVO_CURRENT, js_type,
                         joints(stamp, [topics.DRUM_JOINT], [0.0], [0.0], [0.1 * target])))
        messages.append((stamp + LATENCY, topics.TARGET_FORCE, wrench_type, wrench(stamp, target)))
        messages.append((stamp + LATENCY, topics.MEASURED_FORCE, wrench_type,
                         wrench(stamp, measured)))
        messages.append((stamp + LATENCY, topics.ESTIMATED_FORCE, wrench_type,
                         wrench(stamp, target, 1.5)))
    status, pair = ty['diagnostic_msgs/msg/DiagnosticStatus'], ty['diagnostic_msgs/msg/KeyValue']
    for tau in np.arange(-0.5, trajectory.duration, 0.1):
        mode = 'safe' if abs(tau - SAFE_AT) < 0.05 else 'free'
        values = [pair(key='mode', value=mode)]
        if mode == 'safe':
            values.append(pair(key='reasons', value='stale actuator input: 31.0 ms old'))
        msg = ty[diag_type](header=header(T0 + tau), status=[status(
            level=0, name='grip_force_ros: controller', message=mode, hardware_id='',
            values=values)])
        messages.append((T0 + tau + LATENCY + MASTER_LAG, topics.DIAGNOSTICS, diag_type, msg))
    messages.sort(key=lambda m: m[0])    # the bag holds them in the order they arrived
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    connections = {}
    for received, topic, msgtype, msg in messages:
        conn = connections.get(topic)
        if conn is None:
            conn = connections[topic] = writer.add_connection('/' + topic.lstrip('/'), msgtype,
                                                              typestore=store)
        writer.write(conn, int(round(received * 1e9)), store.serialize_cdr(msg, msgtype))
    writer.close()
    return path


@pytest.fixture(scope='module')
def stalled_bag(tmp_path_factory):
    return write_stalled_bag(tmp_path_factory.mktemp('time_base') / 'bag', _spec().trajectory())


def test_every_topic_of_a_stalled_recording_is_on_its_header_stamps(stalled_bag):
    clocks = {}
    series, diagnostics = read_bag_series(stalled_bag, clocks=clocks)
    assert set(clocks.values()) == {CLOCK_STAMP}, clocks
    master = series[topics.MASTER_JS]
    # the samples sit at their stamps, not 2.5 s later where the recorder got them
    assert master['t'][0] == pytest.approx(T0 - 0.5, abs=1e-6)
    assert np.max(np.abs(np.diff(master['t']) - 0.004)) < 1e-5
    jaw = series[topics.INSTRUMENT_JS]['t']
    assert np.max(np.diff(jaw)) < 0.0011          # the recorder's stall moved no sample
    assert np.max(np.diff(series[topics.ACTUATOR_JS]['t'])) == pytest.approx(0.3, abs=0.002)
    times = [t for t, _ in diagnostics]
    assert times == sorted(times) and times[0] == pytest.approx(T0 - 0.5, abs=1e-6)


def test_the_figure_data_and_the_figures_line_up_on_the_stamps(stalled_bag, monkeypatch, tmp_path):
    from grip_force_ros.lab.demo import plot as plot_module
    from grip_force_ros.lab.demo.run import RunResult, analyse_run

    drawn = {}
    original = plot_module.summary_plot

    def capture(data, windows, metrics, path, title='', clocks=None):
        drawn.update(data=data, clocks=clocks)
        return original(data, windows, metrics, path, title=title, clocks=clocks)

    monkeypatch.setattr(plot_module, 'summary_plot', capture)
    spec = _spec(tmp_path)
    trajectory = spec.trajectory()
    out = stalled_bag.parent
    result = analyse_run(RunResult(spec, out, stalled_bag, 0, {}, {}, trajectory), plot=True)
    assert result.plot.exists() and result.plot.stat().st_size > 30_000
    assert set(result.clocks.values()) == {CLOCK_STAMP}
    assert set(result.as_dict()['clocks'].values()) == {CLOCK_STAMP}
    data = drawn['data']
    t = data['t']
    task = (t >= 0.0) & (t <= trajectory.duration)
    # one clock, one origin: the master at the task time, the jaw and the force with it
    expected = trajectory.angle(np.clip(t[task], 0.0, None))
    assert np.nanmax(np.abs(data['master_angle'][task] - expected)) < 0.01
    assert np.nanmax(np.abs(data['jaw_angle'][task] - 0.5 * expected)) < 0.01
    target = _target(t[task], trajectory)
    phases = trajectory.phase_times()
    steps = ((np.abs(t[task] - phases['hold'][0]) > 0.01)      # away from the target's steps
             & (np.abs(t[task] - phases['release'][0]) > 0.01))
    assert np.nanmax(np.abs(data['target_force'][task][steps] - target[steps])) < 1e-9
    # the sim's own stall shows as a gap in its traces, not as a line drawn across it
    gap = (t > SIM_SILENT[0] + 0.01) & (t < SIM_SILENT[1] - 0.01)
    assert np.all(np.isnan(data['current'][gap]))
    assert np.all(np.isfinite(data['current'][(t > 0.5) & (t < 3.9)]))
    assert np.all(np.isfinite(result.data['current'][gap]))   # the analysis interpolates
    # the figures are those of the stamps: the hold error, the phases, the safe state
    m = result.metrics
    assert m['hold_error_mean'] == pytest.approx(ERROR, abs=1e-6)
    assert m['target_force'] == pytest.approx(4.0, abs=1e-6)
    assert m['settling_time'] == pytest.approx(0.0)
    assert [e['t'] for e in result.safe_events] == [pytest.approx(SAFE_AT, abs=0.002)]
    assert result.problems == []


def test_a_topic_without_stamps_or_on_another_clock_is_on_its_receive_times_and_says_so():
    received = 1_700_000_000.0 + np.arange(5) * 0.001
    t, clock = sample_clock(np.zeros(5), received)
    assert clock == CLOCK_UNSTAMPED and np.array_equal(t, received)
    t, clock = sample_clock(np.arange(5) * 0.001 + 12.0, received)   # a simulated clock
    assert np.array_equal(t, received) and 'another clock' in clock and 'before' in clock
    t, clock = sample_clock(received + 5.0, received)                  # a clock ahead
    assert np.array_equal(t, received) and 'after being received' in clock
    late = received + 2.5                  # received 2.5 s late all along, from the start on
    t, clock = sample_clock(received, late, start=received[0])
    assert clock == CLOCK_STAMP and np.array_equal(t, received)


def test_resample_shows_a_silence_as_a_gap_only_when_asked():
    t = np.concatenate([np.arange(0.0, 1.0, 0.001), np.arange(1.5, 2.0, 0.001)])
    series = {'a': {'t': t, 'x': t.copy()}}
    shown = resample(series, rate=100.0, t0=0.0, max_gap=0.1)
    across = resample(series, rate=100.0, t0=0.0)
    silent = (shown['t'] > 0.9995) & (shown['t'] < 1.5)      # after the last sample (0.999 s)
    assert np.all(np.isnan(shown['x'][silent])) and np.all(np.isfinite(across['x'][silent]))
    assert np.allclose(shown['x'][~silent], shown['t'][~silent])
    # a slow topic's own sample interval is not a gap (five of its intervals)
    slow = {'a': {'t': np.arange(0.0, 2.0, 0.05), 'x': np.arange(0.0, 2.0, 0.05)}}
    assert np.all(np.isfinite(resample(slow, rate=100.0, t0=0.0, max_gap=0.1)['x']))


def test_the_safe_state_entries_follow_the_stamps_of_the_diagnostics(stalled_bag):
    series, diagnostics = read_bag_series(stalled_bag)
    events = analysis.safe_state_entries(diagnostics, (0.0, 4.0), offset=T0)
    assert [e['t'] for e in events] == [pytest.approx(SAFE_AT, abs=1e-3)]
