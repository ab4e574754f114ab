"""Logs: CSV and rosbag2 (MCAP, sqlite3) round trips in the docs/design.md contract."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from grip_force_ros import topics
from grip_force_ros.logs import (LogError, iter_log, measured_column, read_log, write_bag,
                                 write_csv)


def _log(n=3000, seed=0, measured='grip_force'):
    rng = np.random.default_rng(seed)
    t = 0.5 + np.arange(n) * 1e-3
    return {'t': t, 'current': rng.normal(0.2, 0.1, n), 'motor_angle': np.sin(t),
            'wrist_angle': 0.3 * np.cos(2 * t), 'jaw_angle': 0.2 + 0.1 * np.sin(3 * t),
            measured: rng.normal(2.0, 1.0, n),
            'object': np.where(t < t[n // 2], 'free', 'needle')}


def test_csv_round_trip_keeps_values_and_objects(tmp_path):
    log = _log()
    path = write_csv(tmp_path / 'run.csv', log)
    back = read_log(path, chunk_rows=700)      # several chunks
    assert set(back) == set(log)
    for k in log:
        if k == 'object':
            assert (back[k] == log[k]).all()
        else:
            np.testing.assert_allclose(back[k], log[k], rtol=1e-9, atol=1e-12)


def test_iter_log_streams_in_bounded_chunks(tmp_path):
    log = _log(n=2500)
    path = write_csv(tmp_path / 'run.csv', log)
    chunks = list(iter_log(path, chunk_rows=1000))
    assert [len(c['t']) for c in chunks] == [1000, 1000, 500]
    np.testing.assert_allclose(np.concatenate([c['current'] for c in chunks]), log['current'], rtol=1e-9)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_bag_round_trip(tmp_path, storage):
    log = _log()
    bag = write_bag(tmp_path / f'run_{storage}', log, storage=storage)
    back = read_log(bag)
    for k in ('t', 'current', 'motor_angle', 'wrist_angle', 'jaw_angle', 'grip_force'):
        np.testing.assert_allclose(back[k], log[k], rtol=1e-12, atol=1e-9)
    assert (back['object'] == log['object']).all()
    # velocities estimated from the angles were written as JointState velocity
    np.testing.assert_allclose(back['motor_velocity'], np.cos(log['t']), atol=1e-3)


def test_bag_with_jaw_torque_reads_as_jaw_torque(tmp_path):
    log = _log(measured='jaw_torque')
    back = read_log(write_bag(tmp_path / 'torque', log))
    assert measured_column(back) == 'jaw_torque'
    assert 'grip_force' not in back
    np.testing.assert_allclose(back['jaw_torque'], log['jaw_torque'])


def test_bag_messages_are_standard_ros_messages(tmp_path):
    """The raw CDR of each topic deserialises with the ROS message classes themselves."""
    rclpy_ser = pytest.importorskip('rclpy.serialization')
    from geometry_msgs.msg import WrenchStamped
    from rosbags.rosbag2 import Reader
    from sensor_msgs.msg import JointState

    log = _log(n=50)
    bag = write_bag(tmp_path / 'std', log, storage='sqlite3')
    seen = {}
    with Reader(bag) as reader:
        for conn, _, raw in reader.messages():
            topic = conn.topic.lstrip('/')   # the bag has fully qualified names
            if topic in seen:
                continue
            cls = {'sensor_msgs/msg/JointState': JointState,
                   'geometry_msgs/msg/WrenchStamped': WrenchStamped}.get(conn.msgtype)
            if cls is not None:
                seen[topic] = rclpy_ser.deserialize_message(bytes(raw), cls)
    act = seen[topics.ACTUATOR_JS]
    assert list(act.name) == [topics.DRUM_JOINT]
    assert act.effort[0] == pytest.approx(log['current'][0])
    ins = seen[topics.INSTRUMENT_JS]
    assert list(ins.name) == [topics.WRIST_JOINT, topics.JAW_JOINT]
    assert ins.position[1] == pytest.approx(log['jaw_angle'][0])
    assert seen[topics.MEASURED_FORCE].wrench.force.z == pytest.approx(log['grip_force'][0])
    assert seen[topics.MEASURED_FORCE].header.stamp.sec == 0
    assert seen[topics.MEASURED_FORCE].header.stamp.nanosec == 500_000_000


def test_bag_topics_at_different_rates_are_aligned_on_the_actuator_time(tmp_path):
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    T, H = ts.types['builtin_interfaces/msg/Time'], ts.types['std_msgs/msg/Header']
    JS = ts.types['sensor_msgs/msg/JointState']
    W, V, WS = (ts.types['geometry_msgs/msg/Wrench'], ts.types['geometry_msgs/msg/Vector3'],
                ts.types['geometry_msgs/msg/WrenchStamped'])

    def hdr(ns):
        return H(stamp=T(sec=ns // 10**9, nanosec=ns % 10**9), frame_id='')
    path = tmp_path / 'rates'
    with Writer(path, version=9) as w:
        a = w.add_connection(topics.ACTUATOR_JS, JS.__msgtype__, typestore=ts)
        i = w.add_connection(topics.INSTRUMENT_JS, JS.__msgtype__, typestore=ts)
        f = w.add_connection(topics.MEASURED_FORCE, WS.__msgtype__, typestore=ts)
        for k in range(101):                      # actuator 1 kHz, others 500 Hz, all ramps
            ns = 10**9 + k * 10**6
            w.write(a, ns, ts.serialize_cdr(JS(header=hdr(ns), name=['jaw_drum'],
                                               position=np.array([k * 1.0]),
                                               velocity=np.array([0.0]), effort=np.array([0.1])),
                                            JS.__msgtype__))
            if k % 2 == 0:
                w.write(i, ns, ts.serialize_cdr(JS(header=hdr(ns), name=['wrist_pitch', 'jaw'],
                                                   position=np.array([0.0, k * 0.01]), velocity=np.array([]),
                                                   effort=np.array([])), JS.__msgtype__))
                w.write(f, ns, ts.serialize_cdr(WS(header=hdr(ns), wrench=W(force=V(x=0.0, y=0.0, z=k * 0.1),
                                                                            torque=V(x=0.0, y=0.0, z=0.0))),
                                                WS.__msgtype__))
    back = read_log(path)
    assert len(back['t']) == 101
    np.testing.assert_allclose(back['jaw_angle'], np.arange(101) * 0.01, atol=1e-12)
    np.testing.assert_allclose(back['grip_force'], np.arange(101) * 0.1, atol=1e-12)


def test_contract_errors_name_the_problem(tmp_path):
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,current,motor_angle,wrist_angle,jaw_angle\n0,0,0,0,0\n1,0,0,0,0\n')
    with pytest.raises(LogError, match='grip_force or jaw_torque|measured column'):
        read_log(bad)
    back = tmp_path / 'back.csv'
    back.write_text('t,current,motor_angle,wrist_angle,jaw_angle,grip_force\n0,0,0,0,0,0\n0,0,0,0,0,0\n')
    with pytest.raises(LogError, match='rise'):
        read_log(back)
    with pytest.raises(LogError, match='unknown object'):
        write_csv(tmp_path / 'o.csv', {**_log(n=10), 'object': ['banana'] * 10})
    with pytest.raises(LogError, match='cannot open'):
        read_log(tmp_path / 'missing.csv')


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=2, max_size=40))
def test_csv_round_trip_property(tmp_path_factory, values):
    n = len(values)
    log = {'t': np.arange(n) * 0.01, 'current': np.array(values), 'motor_angle': np.zeros(n),
           'wrist_angle': np.zeros(n), 'jaw_angle': np.zeros(n), 'jaw_torque': -np.array(values)}
    path = write_csv(tmp_path_factory.mktemp('p') / 'p.csv', log)
    back = read_log(path, chunk_rows=7)
    np.testing.assert_allclose(back['current'], log['current'], rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(back['jaw_torque'], log['jaw_torque'], rtol=1e-9, atol=1e-300)


def test_bag_is_decoded_in_bounded_batches(tmp_path, monkeypatch):
    """Raw messages are turned into arrays every FLUSH_MESSAGES; the result does not change."""
    from grip_force_ros.logs import bag as bag_module
    log = _log(n=2500)
    path = write_bag(tmp_path / 'batches', log)
    whole = read_log(path)
    monkeypatch.setattr(bag_module, 'FLUSH_MESSAGES', 300)
    batched = read_log(path)
    for k in whole:
        if k == 'object':
            assert (batched[k] == whole[k]).all()
        else:
            np.testing.assert_array_equal(batched[k], whole[k])
