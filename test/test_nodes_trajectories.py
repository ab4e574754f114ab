"""Master trajectories (ROS-free): shapes, phases, replays from CSV and rosbag2."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from grip_force_ros.params import ParameterError
from grip_force_ros.trajectories import (KINDS, MASTER_SPECS, Trajectory, make_trajectory,
                                         needle_grasp, read_csv, read_rosbag, sine_sweep, steps)


def test_needle_grasp_phases_in_order_with_their_angles():
    traj = needle_grasp(open_angle=0.7, closed_angle=0.05)
    spans = traj.phase_times()
    assert list(spans) == ['approach', 'close', 'hold', 'pull', 'release']
    assert all(a[1] == pytest.approx(b[0], abs=2e-3)
               for a, b in zip(spans.values(), list(spans.values())[1:]))
    mid = {name: traj.angle(0.5 * (t0 + t1)) for name, (t0, t1) in spans.items()}
    assert mid['approach'] == pytest.approx(0.7)
    assert mid['hold'] == pytest.approx(0.05) and mid['pull'] == pytest.approx(0.05)
    assert 0.05 < mid['close'] < 0.7 and 0.05 < mid['release'] < 0.7
    assert traj.angle(traj.duration + 10) == pytest.approx(0.7)
    assert traj.phase(traj.duration + 0.1) == 'done'


def test_scripted_trajectories_are_smooth_and_bounded():
    for traj in (needle_grasp(), sine_sweep(), steps()):
        t = np.linspace(0, traj.duration, 20001)
        a = traj.angle(t)
        assert a.min() >= -1e-12 and a.max() <= 0.8 + 1e-12
    # the grasp closes with zero speed at both ends (cosine blend): a finite, small peak speed
    traj = needle_grasp()
    t = np.linspace(0, traj.duration, 50001)
    speed = np.abs(np.gradient(traj.angle(t), t))
    for phase in ('close', 'release'):
        t0, t1 = traj.phase_times()[phase]
        inside = (t > t0) & (t < t1)
        assert speed[inside].max() == pytest.approx(np.pi / 2 * 0.8 / (t1 - t0), rel=0.01)
        assert speed[np.argmin(np.abs(t - t0))] < 0.05 * speed[inside].max()


@settings(max_examples=200, deadline=None)
@given(t=st.floats(min_value=-1.0, max_value=12.0, allow_nan=False),
       kind=st.sampled_from(['needle_grasp', 'sine_sweep', 'steps']))
def test_scalar_fast_path_equals_the_vectorised_one(t, kind):
    traj = make_trajectory(kind)
    assert traj.angle(t) == pytest.approx(float(traj.angle(np.array([t]))[0]), abs=1e-12)


def test_time_scale_stretches_the_task():
    assert needle_grasp(time_scale=2.0).duration == pytest.approx(2 * needle_grasp().duration)


def test_sine_sweep_frequency_rises():
    traj = sine_sweep(duration=10.0)
    t = np.linspace(0, traj.duration, 100001)
    a = traj.angle(t) - 0.4
    crossings = t[1:][np.diff(np.sign(a)) != 0]
    gaps = np.diff(crossings)
    assert gaps[:5].mean() > 3 * gaps[-5:].mean()


def test_csv_replay(tmp_path):
    path = tmp_path / 'm.csv'
    path.write_text('t,master_angle\n10.0,0.5\n10.5,0.1\n11.0,0.3\n')
    traj = read_csv(path)
    assert traj.duration == pytest.approx(1.0)           # times start at 0
    assert traj.angle(0.25) == pytest.approx(0.3)          # linear between samples
    assert make_trajectory('csv', str(path)).angle(1.0) == pytest.approx(0.3)


@pytest.mark.parametrize('text,needle', [
    ('time,angle\n0,1\n', 'expected CSV columns'),
    ('t,master_angle\n0,0.1\n0,0.2\n', 'strictly rising'),
    ('t,master_angle\n0,abc\n', 'non-numeric'),
    ('t,master_angle\n0,nan\n1,0.2\n', 'finite'),
])
def test_bad_csv_is_refused_with_the_reason(tmp_path, text, needle):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(ParameterError) as err:
        read_csv(path)
    assert needle in str(err.value) and 'bad.csv' in str(err.value)


def test_missing_file_is_a_parameter_error(tmp_path):
    with pytest.raises(ParameterError, match='trajectory_file'):
        make_trajectory('csv', '')
    with pytest.raises(ParameterError, match='cannot read'):
        read_csv(tmp_path / 'nope.csv')


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_rosbag_replay(tmp_path, storage):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    JointState = store.types['sensor_msgs/msg/JointState']
    Header = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    bag = tmp_path / 'bag'
    rng = np.random.default_rng(3)
    angles = rng.uniform(0.0, 0.8, 50)
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    with Writer(bag, version=9, storage_plugin=plugin) as writer:
        conn = writer.add_connection('/master/gripper/measured_js', JointState.__msgtype__,
                                     typestore=store)
        for i, a in enumerate(angles):
            stamp = 1_000_000_000 + i * 10_000_000
            msg = JointState(header=Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9),
                                           frame_id=''),
                             name=['gripper'], position=np.array([a]),
                             velocity=np.array([], dtype=float), effort=np.array([], dtype=float))
            writer.write(conn, stamp, store.serialize_cdr(msg, JointState.__msgtype__))
    traj = read_rosbag(bag)
    assert traj.duration == pytest.approx(0.49)
    assert traj.angle(np.arange(50) * 0.01) == pytest.approx(angles)
    with pytest.raises(ParameterError, match='no topic'):
        read_rosbag(bag, topic='other/topic')


def test_every_kind_has_a_builder_and_the_specs_list_them():
    assert set(KINDS) == set(next(s for s in MASTER_SPECS if s.name == 'trajectory').choices)
    for kind in ('needle_grasp', 'sine_sweep', 'steps'):
        assert isinstance(make_trajectory(kind), Trajectory)
    for spec in MASTER_SPECS:
        assert spec.check(spec.default) == spec.default or spec.type == 'double'
