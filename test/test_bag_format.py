"""The project's rosbag2 files are what rosbag2 (Jazzy) itself writes and reads.

Both writers, ``grip_force_ros.logs.write_bag`` (logs, the blind check) and the demo's
``RecorderNode`` (grip_force_ros/lab/demo/recorder.py), write with the ``rosbags`` library:
storage ``mcap``, serialization ``cdr``, rosbag2 metadata **version 9**, the version of
rosbag2 0.26 (ROS 2 Jazzy), which ``ros2 bag info`` on a Jazzy machine reads.

What rosbag2 requires of ``metadata.yaml`` for a version, from its decoder (ros2/rosbag2,
``rosbag2_storage/include/rosbag2_storage/yaml.hpp``, ``convert<BagMetadata>::decode``
and ``convert<TopicMetadata>::decode``, and ``rosbag2_storage/src/rosbag2_storage/qos.cpp``,
``convert<Rosbag2QoS>::decode``):

- always: ``version`` (int), ``storage_identifier``, ``duration.nanoseconds``,
  ``starting_time.nanoseconds_since_epoch``, ``message_count``,
  ``topics_with_message_count`` (a sequence of ``{topic_metadata: {name, type,
  serialization_format, ...}, message_count}``), ``relative_file_paths`` (sequence);
- version >= 3: ``compression_format``, ``compression_mode``;
- version >= 4: ``topic_metadata.offered_qos_profiles``: for 4-8 a YAML *string*; from 9
  on a YAML *sequence* of QoS maps whose ``reliability``/``durability``/``liveliness``
  are policy *names* (``rmw_qos_*_policy_from_str``; ``history`` may be a name or an int),
  with ``depth``, ``deadline``/``lifespan``/``liveliness_lease_duration`` as
  ``{sec, nsec}`` and ``avoid_ros_namespace_conventions`` (bool);
- version >= 5: ``files`` (``{path, starting_time, duration, message_count}``);
- version >= 6: ``custom_data`` (a string map; null reads as empty);
- version >= 7: ``topic_metadata.type_description_hash``;
- version >= 8: ``ros_distro``.

The MCAP file: rosbag2's MCAP plugin (ros2/rosbag2 ``rosbag2_storage_mcap/src/
mcap_storage.cpp``) writes the profile ``ros2``, one schema per type named by the type
(``sensor_msgs/msg/JointState``) with encoding ``ros2msg`` (the .msg text with its
dependencies), one channel per topic with message encoding = the serialization format
(``cdr``) and ``offered_qos_profiles`` in its metadata, and a metadata record ``rosbag2``
whose ``serialized_metadata`` it reads back with the decoder above (``read_metadata``).
The MCAP records are read here with a small parser of the MCAP format, independent of
``rosbags``; the bag is also opened with ``rosbags``' reader.
"""
from __future__ import annotations

import io
import os
import struct
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from grip_force_ros import topics
from grip_force_ros.logs import write_bag

#: The metadata version rosbag2 0.26 (Jazzy) writes: the version these bags claim.
JAZZY_METADATA_VERSION = 9

QOS_NAMES = {   # rmw_qos_*_policy_to_str names, plus the 'unknown' rosbag2 writes itself
    'history': {'system_default', 'keep_last', 'keep_all', 'unknown'},
    'reliability': {'system_default', 'reliable', 'best_effort', 'best_available', 'unknown'},
    'durability': {'system_default', 'transient_local', 'volatile', 'best_available', 'unknown'},
    'liveliness': {'system_default', 'automatic', 'manual_by_topic', 'best_available', 'unknown'},
}


# --- rosbag2's metadata schema, per version -----------------------------------------------------

def _time(node, key, where, problems):
    if not isinstance(node, dict) or not isinstance(node.get(key), int):
        problems.append(f'{where}: needs {{{key}: int}}, got {node!r}')


def _qos_problems(profile, version, where):
    problems = []
    if not isinstance(profile, dict):
        return [f'{where}: a QoS profile must be a map, got {profile!r}']
    for policy, names in QOS_NAMES.items():
        value = profile.get(policy)
        if version >= 9:
            ok = value in names or (policy == 'history' and isinstance(value, int))
        else:
            ok = isinstance(value, int)
        if not ok:
            problems.append(f'{where}.{policy}: {value!r} is not valid for version {version}')
    if not isinstance(profile.get('depth'), int):
        problems.append(f'{where}.depth: needs an int')
    for key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
        d = profile.get(key)
        if not (isinstance(d, dict) and isinstance(d.get('sec'), int) and isinstance(d.get('nsec'), int)):
            problems.append(f'{where}.{key}: needs {{sec: int, nsec: int}}, got {d!r}')
    if not isinstance(profile.get('avoid_ros_namespace_conventions'), bool):
        problems.append(f'{where}.avoid_ros_namespace_conventions: needs a bool')
    return problems


def offered_qos(value, version, where='offered_qos_profiles'):
    """The offered QoS profiles of a topic as rosbag2 decodes them: (profiles, problems)."""
    if version >= 9:
        if not isinstance(value, list):
            return [], [f'{where}: version {version} needs a YAML sequence, got {value!r}']
        profiles = value
    else:
        if not isinstance(value, str):
            return [], [f'{where}: version {version} needs a YAML string, got {value!r}']
        profiles = yaml.safe_load(value) if value else []
    problems = []
    for i, p in enumerate(profiles):
        problems += _qos_problems(p, version, f'{where}[{i}]')
    return profiles, problems


def metadata_problems(doc) -> list[str]:
    """What rosbag2's decoder would refuse (or read wrongly) in a metadata.yaml document."""
    if not isinstance(doc, dict) or not isinstance(doc.get('rosbag2_bagfile_information'), dict):
        return ['no rosbag2_bagfile_information map']
    info = doc['rosbag2_bagfile_information']
    problems: list[str] = []
    version = info.get('version')
    if not isinstance(version, int):
        return [f'version: needs an int, got {version!r}']

    def need(key, kind, node=info, where=''):
        if key not in node:
            problems.append(f'{where}{key}: missing (required from the version that introduced it; '
                            f'this is version {version})')
            return None
        if not isinstance(node[key], kind):
            problems.append(f'{where}{key}: needs {kind}, got {node[key]!r}')
        return node[key]

    need('storage_identifier', str)
    _time(info.get('duration'), 'nanoseconds', 'duration', problems)
    _time(info.get('starting_time'), 'nanoseconds_since_epoch', 'starting_time', problems)
    need('message_count', int)
    paths = need('relative_file_paths', list) or []
    if not all(isinstance(p, str) for p in paths):
        problems.append('relative_file_paths: needs strings')
    if version >= 3:
        need('compression_format', str)
        need('compression_mode', str)
    if version >= 5:
        for i, f in enumerate(need('files', list) or []):
            where = f'files[{i}].'
            need('path', str, f, where)
            need('message_count', int, f, where)
            _time(f.get('starting_time'), 'nanoseconds_since_epoch', where + 'starting_time', problems)
            _time(f.get('duration'), 'nanoseconds', where + 'duration', problems)
    if version >= 6:
        custom = info.get('custom_data', 'missing')
        if not (custom is None or (isinstance(custom, dict)
                                   and all(isinstance(v, str) for v in custom.values()))):
            problems.append(f'custom_data: needs a string map (or null), got {custom!r}')
    if version >= 8:
        need('ros_distro', str)
    total = 0
    for i, entry in enumerate(need('topics_with_message_count', list) or []):
        where = f'topics_with_message_count[{i}].'
        total += need('message_count', int, entry, where) or 0
        meta = need('topic_metadata', dict, entry, where) or {}
        for key in ('name', 'type', 'serialization_format'):
            need(key, str, meta, where + 'topic_metadata.')
        if version >= 4:
            if 'offered_qos_profiles' not in meta:
                problems.append(f'{where}topic_metadata.offered_qos_profiles: missing')
            else:
                problems += offered_qos(meta['offered_qos_profiles'], version,
                                        f'{where}topic_metadata.offered_qos_profiles')[1]
        if version >= 7:
            need('type_description_hash', str, meta, where + 'topic_metadata.')
    if isinstance(info.get('message_count'), int) and info['message_count'] != total:
        problems.append(f'message_count {info["message_count"]} != sum over topics {total}')
    return problems


def test_the_schema_check_refuses_what_rosbag2_would_refuse():
    good = {'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': 'mcap', 'duration': {'nanoseconds': 5},
        'starting_time': {'nanoseconds_since_epoch': 1}, 'message_count': 2,
        'relative_file_paths': ['b.mcap'], 'compression_format': '', 'compression_mode': '',
        'files': [{'path': 'b.mcap', 'starting_time': {'nanoseconds_since_epoch': 1},
                   'duration': {'nanoseconds': 5}, 'message_count': 2}],
        'custom_data': None, 'ros_distro': 'jazzy',
        'topics_with_message_count': [{'message_count': 2, 'topic_metadata': {
            'name': '/a', 'type': 'std_msgs/msg/String', 'serialization_format': 'cdr',
            'type_description_hash': 'RIHS01_00',
            'offered_qos_profiles': [{
                'history': 'keep_last', 'depth': 10, 'reliability': 'reliable',
                'durability': 'volatile', 'deadline': {'sec': 0, 'nsec': 0},
                'lifespan': {'sec': 0, 'nsec': 0}, 'liveliness': 'automatic',
                'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
                'avoid_ros_namespace_conventions': False}]}}]}}
    assert metadata_problems(good) == []
    info = good['rosbag2_bagfile_information']
    topic = info['topics_with_message_count'][0]['topic_metadata']

    def broken(change):
        doc = yaml.safe_load(yaml.safe_dump(good))
        change(doc['rosbag2_bagfile_information'])
        return metadata_problems(doc)

    assert any('ros_distro' in p for p in broken(lambda i: i.pop('ros_distro')))
    assert any('files' in p for p in broken(lambda i: i.pop('files')))
    assert any('sum over topics' in p for p in broken(lambda i: i.update(message_count=3)))
    # a version-8 QoS string (integer policies) under a version-9 claim
    v8 = yaml.safe_dump([{**topic['offered_qos_profiles'][0], 'reliability': 1}])
    assert any('YAML sequence' in p for p in broken(
        lambda i: i['topics_with_message_count'][0]['topic_metadata'].update(offered_qos_profiles=v8)))
    assert any('reliability' in p for p in broken(
        lambda i: i['topics_with_message_count'][0]['topic_metadata']['offered_qos_profiles'][0]
        .update(reliability=1)))
    assert any('type_description_hash' in p for p in broken(
        lambda i: i['topics_with_message_count'][0]['topic_metadata'].pop('type_description_hash')))


# --- a small reader of the MCAP format (https://mcap.dev/spec), independent of rosbags ------------

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_METADATA = 0x01, 0x03, 0x04, 0x05, 0x06, 0x0C


def _string(b: io.BytesIO) -> str:
    (n,) = struct.unpack('<I', b.read(4))
    return b.read(n).decode()


def _map(b: io.BytesIO) -> dict[str, str]:
    (n,) = struct.unpack('<I', b.read(4))
    end = b.tell() + n
    out = {}
    while b.tell() < end:
        key = _string(b)
        out[key] = _string(b)
    return out


def _records(data: bytes):
    b = io.BytesIO(data)
    while True:
        head = b.read(9)
        if len(head) < 9:
            return
        op, length = struct.unpack('<BQ', head)
        yield op, b.read(length)


def read_mcap(path: Path) -> dict:
    """Header, schemas, channels, message counts per channel and metadata records."""
    data = path.read_bytes()
    assert data[:8] == MAGIC and data[-8:] == MAGIC, 'not an MCAP file'
    out = {'profile': None, 'schemas': {}, 'channels': {}, 'counts': {}, 'metadata': {}}

    def walk(records):
        for op, body in records:
            b = io.BytesIO(body)
            if op == OP_HEADER:
                out['profile'] = _string(b)
            elif op == OP_SCHEMA:
                (sid,) = struct.unpack('<H', b.read(2))
                name, encoding = _string(b), _string(b)
                (n,) = struct.unpack('<I', b.read(4))
                out['schemas'][sid] = {'name': name, 'encoding': encoding, 'data': b.read(n).decode()}
            elif op == OP_CHANNEL:
                cid, sid = struct.unpack('<HH', b.read(4))
                topic, encoding = _string(b), _string(b)
                out['channels'][cid] = {'schema_id': sid, 'topic': topic,
                                        'message_encoding': encoding, 'metadata': _map(b)}
            elif op == OP_MESSAGE:
                (cid,) = struct.unpack('<H', b.read(2))
                out['counts'][cid] = out['counts'].get(cid, 0) + 1
            elif op == OP_CHUNK:
                b.read(8 + 8 + 8 + 4)        # start, end, uncompressed size, crc
                compression = _string(b)
                assert compression == '', f'chunk compression {compression!r} (rosbag2 default: none)'
                (n,) = struct.unpack('<Q', b.read(8))
                walk(_records(b.read(n)))
            elif op == OP_METADATA:
                name = _string(b)
                out['metadata'][name] = _map(b)

    walk(_records(data[8:-8]))
    return out


# --- the bags ----------------------------------------------------------------------------------

def _log(n=200):
    t = np.arange(n) * 1e-3
    return {'t': t, 'current': 0.1 + 0.5 * t, 'motor_angle': 0.2 * t, 'wrist_angle': 0.0 * t,
            'jaw_angle': 0.6 - 0.3 * t, 'grip_force': 2.0 * t,
            'object': np.where(t < 0.1, 'free', 'needle')}


@pytest.fixture(scope='module')
def logs_bag(tmp_path_factory):
    return write_bag(tmp_path_factory.mktemp('logs') / 'grasp', _log())


@pytest.fixture(scope='module')
def demo_bag(tmp_path_factory):
    """A bag of the demo's recorder, fed by publishers with the nodes' QoS."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context
    from sensor_msgs.msg import JointState

    from grip_force_ros.lab.demo.recorder import RecorderNode, SpinThread
    from grip_force_ros.lab.processes import wait_until

    path = tmp_path_factory.mktemp('demo') / 'bag'
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    try:
        recorder = RecorderNode(path, context=ctx)
        recorder.subscribe_all()
        spin = SpinThread(recorder).start()
        node = rclpy.create_node('bag_format_publishers', context=ctx)
        master = node.create_publisher(JointState, topics.MASTER_JS, 10)
        force = node.create_publisher(WrenchStamped, topics.ESTIMATED_FORCE, 10)
        deadline = time.monotonic() + 20
        while (recorder.count(topics.MASTER_JS) == 0 or recorder.count(topics.ESTIMATED_FORCE) == 0) \
                and time.monotonic() < deadline:
            master.publish(JointState(name=[topics.MASTER_JOINT], position=[0.8]))
            force.publish(WrenchStamped())
            time.sleep(0.02)
        for k in range(50):
            js = JointState(name=[topics.MASTER_JOINT], position=[0.8 - 0.01 * k])
            js.header.stamp = node.get_clock().now().to_msg()
            master.publish(js)
            w = WrenchStamped()
            w.header.stamp = js.header.stamp
            w.header.frame_id = topics.JAW_FRAME
            w.wrench.force.z = 0.02 * k
            force.publish(w)
            time.sleep(0.002)
            if k % 8 == 7:   # at most 8 in flight: the publishers keep 10 (a starved recorder)
                wait_until(lambda: recorder.count(topics.ESTIMATED_FORCE) > k, 20.0)
        wait_until(lambda: recorder.count(topics.ESTIMATED_FORCE) >= 50, 20.0)
        spin.stop()
        recorder.close()
        node.destroy_node()
        recorder.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    return path


BAGS = ['logs_bag', 'demo_bag']


def _metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())


@pytest.mark.parametrize('which', BAGS)
def test_metadata_yaml_is_rosbag2_jazzy_version_9(which, request):
    bag = request.getfixturevalue(which)
    doc = _metadata(bag)
    assert metadata_problems(doc) == []
    info = doc['rosbag2_bagfile_information']
    assert info['version'] == JAZZY_METADATA_VERSION
    assert info['storage_identifier'] == 'mcap'
    assert info['compression_mode'] == '' and info['compression_format'] == ''
    assert [f['path'] for f in info['files']] == info['relative_file_paths']
    for rel in info['relative_file_paths']:
        assert (bag / rel).is_file() and rel.endswith('.mcap')
    for entry in info['topics_with_message_count']:
        meta = entry['topic_metadata']
        assert meta['serialization_format'] == 'cdr'
        assert meta['name'].startswith('/'), meta['name']   # fully qualified, as ros2 bag record
        assert meta['type_description_hash'].startswith('RIHS01_')


def test_demo_bag_records_the_offered_qos_and_every_topic(demo_bag):
    from grip_force_ros.lab.demo.messages import TOPIC_TYPES, absolute
    info = _metadata(demo_bag)['rosbag2_bagfile_information']
    by_name = {e['topic_metadata']['name']: e for e in info['topics_with_message_count']}
    assert set(by_name) == {absolute(t) for t in TOPIC_TYPES}
    for topic, type_name in TOPIC_TYPES.items():
        assert by_name[absolute(topic)]['topic_metadata']['type'] == type_name
    master = by_name['/' + topics.MASTER_JS]
    assert master['message_count'] >= 50
    profiles, problems = offered_qos(master['topic_metadata']['offered_qos_profiles'], 9)
    assert problems == [] and profiles
    # Discovery carries no history or depth: `ros2 bag record` writes 'unknown' and 0 too.
    assert (profiles[0]['history'], profiles[0]['depth'], profiles[0]['reliability'],
            profiles[0]['durability']) == ('unknown', 0, 'reliable', 'volatile')
    assert info['custom_data'] == {'recorded_by': 'grip_force_ros demo recorder'}


@pytest.mark.parametrize('which', BAGS)
def test_mcap_records_are_what_rosbag2_writes(which, request):
    bag = request.getfixturevalue(which)
    info = _metadata(bag)['rosbag2_bagfile_information']
    mcap = read_mcap(bag / info['relative_file_paths'][0])
    assert mcap['profile'] == 'ros2'
    types = {e['topic_metadata']['name']: e['topic_metadata']['type']
             for e in info['topics_with_message_count']}
    counts = {e['topic_metadata']['name']: e['message_count'] for e in info['topics_with_message_count']}
    channels = {c['topic']: (cid, c) for cid, c in mcap['channels'].items()}
    assert set(channels) == set(types)
    for topic, (cid, channel) in channels.items():
        assert channel['message_encoding'] == 'cdr'
        schema = mcap['schemas'][channel['schema_id']]
        assert schema['name'] == types[topic]
        assert schema['encoding'] == 'ros2msg'
        profiles, problems = offered_qos(yaml.safe_load(channel['metadata']['offered_qos_profiles']), 9)
        assert problems == []
        assert mcap['counts'].get(cid, 0) == counts[topic]
    # the .msg text with its dependencies, as rosbag2's local message definition source gives it
    joint_state = next(s for s in mcap['schemas'].values() if s['name'] == 'sensor_msgs/msg/JointState')
    assert 'float64[] position' in joint_state['data']
    assert 'MSG: std_msgs/Header' in joint_state['data']
    # rosbag2 reads the bag's metadata from this record, with the same decoder
    serialized = yaml.safe_load(mcap['metadata']['rosbag2']['serialized_metadata'])
    assert metadata_problems({'rosbag2_bagfile_information': serialized}) == []
    assert serialized['version'] == JAZZY_METADATA_VERSION


@pytest.mark.parametrize('which', BAGS)
def test_rosbags_reader_opens_and_deserialises_every_topic(which, request):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    bag = request.getfixturevalue(which)
    info = _metadata(bag)['rosbag2_bagfile_information']
    ts = get_typestore(Stores.ROS2_JAZZY)
    seen = {}
    with Reader(bag) as reader:
        assert reader.message_count == info['message_count']
        for conn in reader.connections:
            assert conn.ext.serialization_format == 'cdr'
        for conn, _, raw in reader.messages():
            if conn.topic not in seen:
                seen[conn.topic] = ts.deserialize_cdr(raw, conn.msgtype)
    expected = {e['topic_metadata']['name'] for e in info['topics_with_message_count']
                if e['message_count']}
    assert set(seen) == expected
    for msg in seen.values():
        assert hasattr(msg, 'header')
