"""rosbag2 logs (MCAP or sqlite3) of the product's topics, read and written with ``rosbags``.

Topics (names from :mod:`grip_force_ros.topics`, standard message types):

| topic | type | columns |
|---|---|---|
| ``instrument/actuator/measured_js`` | sensor_msgs/JointState ``jaw_drum`` | position -> ``motor_angle`` (rad), velocity -> ``motor_velocity`` (rad/s), effort -> ``current`` (A) |
| ``instrument/measured_js`` | sensor_msgs/JointState ``wrist_pitch``, ``jaw`` (and ``jaw_drum``, in the sim's combined state) | positions -> ``wrist_angle``, ``jaw_angle`` (rad); velocities -> ``wrist_velocity``, ``jaw_velocity`` (rad/s); ``jaw_drum`` as on the actuator topic |
| ``grip/measured_force`` | geometry_msgs/WrenchStamped | force.z -> ``grip_force`` (N); torque.z -> ``jaw_torque`` (N*m) |
| ``/diagnostics`` | diagnostic_msgs/DiagnosticArray | a status value with key ``object`` -> ``object`` |

Reading aligns every topic on the time stamps (``header.stamp``; the bag's
receive time when a stamp is zero) of the actuator topic (of the joint state when it
carries the drum and the actuator topic is empty), by linear interpolation
(``object``: the last value published). Messages of one topic usually share one
byte layout; those are decoded together with numpy instead of one by one.
"""  # noqa: E501 - Markdown table rows are kept whole
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Mapping

import numpy as np

from grip_force_ros import topics
from grip_force_ros.logs.columns import OBJECT_COLUMN, LogError, normalise_log

_JS = 'sensor_msgs/msg/JointState'
_WRENCH = 'geometry_msgs/msg/WrenchStamped'
_DIAG = 'diagnostic_msgs/msg/DiagnosticArray'
_OBJECT_STATUS = 'grip_force_ros: object'


def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def is_bag(path) -> bool:
    """Tell whether ``path`` is a rosbag2 directory or an ``.mcap``/``.db3`` storage file."""
    path = Path(path)
    if path.is_dir():
        return True
    return path.suffix in ('.mcap', '.db3')


# --- one byte layout per topic: offsets of the numeric fields found with sentinels ---------

_SENTINEL0 = 1.2345678901234567e-300


def _layout(ts, msgtype: str, make, fields: list[str]):
    """Serialise a message whose numeric fields hold sentinels; return (template, offsets).

    ``make(values)`` builds the message from a dict field -> value (float fields,
    plus 'sec'/'nanosec' stamp fields). Offsets are byte positions in the CDR data.
    """
    sentinels = {f: _SENTINEL0 * (i + 2) for i, f in enumerate(fields)}
    sec, nsec = 0x5A5A1234, 0x3C3C5678
    data = bytes(ts.serialize_cdr(make(sentinels, sec, nsec), msgtype))
    offsets = {}
    for f, v in sentinels.items():
        pos = data.find(np.float64(v).tobytes())
        if pos < 0 or data.find(np.float64(v).tobytes(), pos + 1) >= 0:  # pragma: no cover
            raise LogError(f'cannot locate field {f} in the {msgtype} layout')
        offsets[f] = pos
    offsets['sec'] = data.find(np.int32(sec).tobytes())
    offsets['nanosec'] = data.find(np.uint32(nsec).tobytes())
    return np.frombuffer(data, dtype=np.uint8).copy(), offsets


def _js_maker(ts, names: list[str], frame_id: str = ''):
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    JointState = ts.types[_JS]
    k = len(names)

    def make(v, sec, nsec):
        arr = lambda kind: np.array([v[f'{kind}{i}'] for i in range(k)], dtype=np.float64)  # noqa: E731
        return JointState(header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id),
                          name=list(names), position=arr('p'), velocity=arr('v'), effort=arr('e'))
    fields = [f'{kind}{i}' for kind in 'pve' for i in range(k)]
    return make, fields


def _wrench_maker(ts, frame_id: str = topics.JAW_FRAME):
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    Vector3 = ts.types['geometry_msgs/msg/Vector3']
    Wrench = ts.types['geometry_msgs/msg/Wrench']
    WrenchStamped = ts.types[_WRENCH]

    def make(v, sec, nsec):
        return WrenchStamped(header=Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame_id),
                             wrench=Wrench(force=Vector3(x=v['fx'], y=v['fy'], z=v['fz']),
                                           torque=Vector3(x=v['tx'], y=v['ty'], z=v['tz'])))
    return make, ['fx', 'fy', 'fz', 'tx', 'ty', 'tz']


def _encode(template: np.ndarray, offsets: dict, t_ns: np.ndarray, columns: dict) -> np.ndarray:
    """Rows of CDR bytes (n x len(template)) with stamps and fields filled in, vectorised."""
    n = t_ns.size
    rows = np.tile(template, (n, 1))
    sec = (t_ns // 1_000_000_000).astype('<i4')
    nsec = (t_ns % 1_000_000_000).astype('<u4')
    rows[:, offsets['sec']:offsets['sec'] + 4] = sec.view(np.uint8).reshape(n, 4)
    rows[:, offsets['nanosec']:offsets['nanosec'] + 4] = nsec.view(np.uint8).reshape(n, 4)
    for f, values in columns.items():
        o = offsets[f]
        rows[:, o:o + 8] = np.ascontiguousarray(values, dtype='<f8').view(np.uint8).reshape(n, 8)
    return rows


def _decode(rows: np.ndarray, offsets: dict, fields: list[str]) -> tuple[np.ndarray, dict]:
    """Stamps (ns) and fields from rows of equally laid-out CDR messages."""
    def take(o, dtype, size):
        return np.ascontiguousarray(rows[:, o:o + size]).view(dtype).ravel()
    stamp = (take(offsets['sec'], '<i4', 4).astype(np.int64) * 1_000_000_000
             + take(offsets['nanosec'], '<u4', 4).astype(np.int64))
    return stamp, {f: take(offsets[f], '<f8', 8).astype(np.float64) for f in fields}


# --- writing ----------------------------------------------------------------------------------

def write_bag(path, log: Mapping[str, np.ndarray], *, storage: str = 'mcap',
              overwrite: bool = False, chunk_rows: int = 100_000) -> Path:
    """Write a log as a rosbag2 of the product's topics (readable by ``ros2 bag``).

    Parameters
    ----------
    path : str or Path
        Bag directory to create.
    log : mapping of str to array
        Contract columns (see :mod:`grip_force_ros.logs`); ``motor_velocity``,
        ``wrist_velocity`` and ``jaw_velocity`` (rad/s) are written when present,
        else estimated from the angles. ``t`` (s) becomes ``header.stamp`` and the
        bag time (shifted to start at >= 0).
    storage : {'mcap', 'sqlite3'}
        rosbag2 storage plugin.
    overwrite : bool
        Replace an existing bag directory.
    chunk_rows : int
        Rows serialised per chunk (bounds the memory of a long log).

    Returns
    -------
    Path
        The bag directory.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    path = Path(path)
    log = normalise_log(log, where=str(path))
    plugins = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
    if storage not in plugins:
        raise LogError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
    if path.exists():
        if not overwrite:
            raise LogError(f'{path}: exists (pass overwrite=True to replace it)')
        shutil.rmtree(path)
    ts = _typestore()
    t = log['t']
    shift = -min(0.0, float(t[0]))
    t_ns = np.round((t + shift) * 1e9).astype(np.int64)
    n = t.size

    def velocity(name, angle):
        if name in log:
            return log[name]
        return np.gradient(log[angle], t)

    act_make, act_fields = _js_maker(ts, [topics.DRUM_JOINT])
    act_tpl, act_off = _layout(ts, _JS, act_make, act_fields)
    ins_make, ins_fields = _js_maker(ts, [topics.WRIST_JOINT, topics.JAW_JOINT])
    ins_tpl, ins_off = _layout(ts, _JS, ins_make, ins_fields)
    wr_make, wr_fields = _wrench_maker(ts)
    wr_tpl, wr_off = _layout(ts, _WRENCH, wr_make, wr_fields)
    nan = np.full(n, np.nan)
    zeros = np.zeros(n)
    act_cols = {'p0': log['motor_angle'], 'v0': velocity('motor_velocity', 'motor_angle'),
                'e0': log['current']}
    ins_cols = {'p0': log['wrist_angle'], 'p1': log['jaw_angle'],
                'v0': velocity('wrist_velocity', 'wrist_angle'),
                'v1': velocity('jaw_velocity', 'jaw_angle'), 'e0': zeros, 'e1': zeros}
    wr_cols = {'fx': zeros, 'fy': zeros, 'fz': log.get('grip_force', nan),
               'tx': zeros, 'ty': zeros, 'tz': log.get('jaw_torque', zeros)}

    with Writer(path, version=9, storage_plugin=plugins[storage]) as writer:
        # Fully qualified names, as `ros2 bag record` writes them.
        act = writer.add_connection('/' + topics.ACTUATOR_JS, _JS, typestore=ts)
        ins = writer.add_connection('/' + topics.INSTRUMENT_JS, _JS, typestore=ts)
        wr = writer.add_connection('/' + topics.MEASURED_FORCE, _WRENCH, typestore=ts)
        diag = writer.add_connection(topics.DIAGNOSTICS, _DIAG, typestore=ts)
        objects = log.get(OBJECT_COLUMN)
        if objects is not None:
            _write_objects(writer, diag, ts, t_ns, objects)
        for start in range(0, n, chunk_rows):
            sl = slice(start, start + chunk_rows)
            blocks = [(conn, _encode(tpl, off, t_ns[sl], {k: v[sl] for k, v in cols.items()}))
                      for conn, tpl, off, cols in ((act, act_tpl, act_off, act_cols),
                                                   (ins, ins_tpl, ins_off, ins_cols),
                                                   (wr, wr_tpl, wr_off, wr_cols))]
            for i, stamp in enumerate(t_ns[sl].tolist()):
                for conn, rows in blocks:
                    writer.write(conn, stamp, rows[i].tobytes())
    return path


def _write_objects(writer, conn, ts, t_ns, objects):
    Time = ts.types['builtin_interfaces/msg/Time']
    Header = ts.types['std_msgs/msg/Header']
    Array = ts.types[_DIAG]
    Status = ts.types['diagnostic_msgs/msg/DiagnosticStatus']
    KeyValue = ts.types['diagnostic_msgs/msg/KeyValue']
    changes = np.flatnonzero(np.r_[True, objects[1:] != objects[:-1]])
    for i in changes.tolist():
        stamp = int(t_ns[i])
        msg = Array(header=Header(stamp=Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000),
                                  frame_id=''),
                    status=[Status(level=0, name=_OBJECT_STATUS, message='object in the jaw',
                                   hardware_id='', values=[KeyValue(key='object', value=str(objects[i]))])])
        writer.write(conn, stamp, bytes(ts.serialize_cdr(msg, _DIAG)))


# --- reading ----------------------------------------------------------------------------------

def _bag_dir(path: Path) -> Path:
    if path.is_dir():
        return path
    if path.suffix in ('.mcap', '.db3') and (path.parent / 'metadata.yaml').exists():
        return path.parent
    raise LogError(f'{path}: not a rosbag2 (expected a directory with metadata.yaml)')


#: Raw messages held per topic before they are decoded into arrays (bounds the memory of a read).
FLUSH_MESSAGES = 50_000


class _TopicBuffer:
    """Raw messages of one topic, decoded into arrays as they come.

    Grouped by byte length and decoded every FLUSH_MESSAGES messages (vectorised per
    group), so raw bytes never pile up.
    """

    def __init__(self, decode):
        self.decode = decode            # (groups) -> dict of arrays
        self.groups: dict[int, tuple[list[int], list[bytes]]] = {}
        self.pending = 0
        self.parts: list[dict] = []
        self.count = 0

    def add(self, bag_ns: int, raw: bytes):
        times, datas = self.groups.setdefault(len(raw), ([], []))
        times.append(bag_ns)
        datas.append(raw)
        self.pending += 1
        self.count += 1
        if self.pending >= FLUSH_MESSAGES:
            self.flush()

    def flush(self):
        if self.pending:
            self.parts.append(self.decode(self.groups))
            self.groups = {}
            self.pending = 0

    def finish(self) -> dict:
        self.flush()
        keys = set(self.parts[0])
        if any(set(p) != keys for p in self.parts):
            raise LogError('joint names change between messages of one topic')
        return _sorted_unique({k: np.concatenate([p[k] for p in self.parts]) for k in keys})


def read_bag(path, *, progress=None, measured: bool = True) -> dict[str, np.ndarray]:
    """Read a rosbag2 (MCAP or sqlite3) of the product's topics into contract columns.

    ``measured=False``: the force topic is optional (a bag of inputs only).

    Returns
    -------
    dict of str to numpy.ndarray
        ``t`` (s, from the actuator stamps), ``current``, ``motor_angle``,
        ``motor_velocity``, ``wrist_angle``, ``jaw_angle``, ``wrist_velocity``,
        ``jaw_velocity``, ``grip_force`` and/or ``jaw_torque``, ``object`` when
        published on ``/diagnostics``.

    Raises
    ------
    LogError
        Unreadable bag or a missing topic.
    """
    from rosbags.rosbag2 import Reader

    path = Path(path)
    ts = _typestore()
    wanted = {topics.ACTUATOR_JS: _JS, topics.INSTRUMENT_JS: _JS, topics.MEASURED_FORCE: _WRENCH,
              topics.DIAGNOSTICS: _DIAG}
    decoders = {topics.ACTUATOR_JS: lambda g: _decode_js(ts, g, path),
                topics.INSTRUMENT_JS: lambda g: _decode_js(ts, g, path),
                topics.MEASURED_FORCE: lambda g: _decode_wrench(ts, g, path)}
    buffers = {name: _TopicBuffer(decoders[name]) for name in decoders}
    objects: list[tuple[int, str]] = []
    try:
        with Reader(_bag_dir(path)) as reader:
            conns = [c for c in reader.connections
                     if c.topic.lstrip('/') in {w.lstrip('/') for w in wanted}]
            by_id = {c.id: next(w for w in wanted if w.lstrip('/') == c.topic.lstrip('/'))
                     for c in conns}
            count = 0
            for conn, bag_ns, raw in reader.messages(connections=conns):
                topic = by_id[conn.id]
                if topic == topics.DIAGNOSTICS:
                    msg = ts.deserialize_cdr(raw, conn.msgtype)
                    for st in msg.status:
                        for kv in st.values:
                            if kv.key == 'object':
                                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                                objects.append((stamp or bag_ns, kv.value))
                    continue
                buffers[topic].add(bag_ns, raw)
                count += 1
                if progress is not None and count % 500_000 == 0:
                    progress(count)
    except LogError:
        raise
    except Exception as exc:  # rosbags raises its own types; keep one domain error
        raise LogError(f'{path}: cannot read bag: {exc}') from exc

    # the drum in its own topic (split) or in the joint state (the sim's combined state)
    combined = not buffers[topics.ACTUATOR_JS].count
    needed = ((topics.INSTRUMENT_JS,) + (() if combined else (topics.ACTUATOR_JS,))
              + ((topics.MEASURED_FORCE,) if measured else ()))
    for topic in needed:
        if not buffers[topic].count:
            raise LogError(f'{path}: no messages on {topic}')
    try:
        act = buffers.pop(topics.ACTUATOR_JS)
        ins = buffers.pop(topics.INSTRUMENT_JS).finish()
        act = ins if combined else act.finish()
        if f'effort/{topics.DRUM_JOINT}' not in act:
            raise LogError(f'no {topics.DRUM_JOINT} on {topics.ACTUATOR_JS} nor on '
                           f'{topics.INSTRUMENT_JS}')
        force = buffers.pop(topics.MEASURED_FORCE)
        wr = force.finish() if force.count else None
    except LogError as exc:
        raise LogError(f'{path}: {exc}') from None

    t_ns = act['stamp']
    lo = max(ins['stamp'][0], wr['stamp'][0] if wr is not None else ins['stamp'][0])
    hi = min(ins['stamp'][-1], wr['stamp'][-1] if wr is not None else ins['stamp'][-1])
    keep = (t_ns >= lo) & (t_ns <= hi)
    if keep.sum() < 2:
        raise LogError(f'{path}: topics do not overlap in time')
    t_ns = t_ns[keep]
    t = t_ns * 1e-9

    def on_time(src, column):
        return np.interp(t_ns, src['stamp'], src[column])

    drum = topics.DRUM_JOINT
    log = {'t': t,
           'current': act[f'effort/{drum}'][keep],
           'motor_angle': act[f'position/{drum}'][keep],
           'motor_velocity': act[f'velocity/{drum}'][keep],
           'wrist_angle': on_time(ins, f'position/{topics.WRIST_JOINT}'),
           'jaw_angle': on_time(ins, f'position/{topics.JAW_JOINT}'),
           'wrist_velocity': on_time(ins, f'velocity/{topics.WRIST_JOINT}'),
           'jaw_velocity': on_time(ins, f'velocity/{topics.JAW_JOINT}')}
    if wr is not None and np.any(np.isfinite(wr['fz'])):
        log['grip_force'] = on_time(wr, 'fz')
    if wr is not None and np.any(wr['tz'] != 0):
        log['jaw_torque'] = on_time(wr, 'tz')
    if objects:
        objects.sort()
        o_ns = np.array([s for s, _ in objects], dtype=np.int64)
        names = np.array([v for _, v in objects])
        idx = np.clip(np.searchsorted(o_ns, t_ns, side='right') - 1, 0, None)
        log[OBJECT_COLUMN] = names[idx]
    return normalise_log(log, where=str(path), measured=measured)


def _stamps(stamp_ns: np.ndarray, bag_ns: np.ndarray) -> np.ndarray:
    return np.where(stamp_ns != 0, stamp_ns, bag_ns)


def _sorted_unique(out: dict) -> dict:
    order = np.argsort(out['stamp'], kind='stable')
    out = {k: v[order] for k, v in out.items()}
    first = np.r_[True, np.diff(out['stamp']) > 0]
    return {k: v[first] for k, v in out.items()}


def _decode_js(ts, groups: dict, path: Path) -> dict:
    parts: dict[str, list[np.ndarray]] = {}
    for size, (bag_times, datas) in groups.items():
        first = ts.deserialize_cdr(datas[0], _JS)
        names = list(first.name)
        make, fields = _js_maker(ts, names, first.header.frame_id)
        tpl, off = _layout(ts, _JS, make, fields)
        if len(tpl) == size and len(first.position) == len(first.velocity) == len(first.effort) == len(names):
            rows = np.frombuffer(b''.join(datas), dtype=np.uint8).reshape(len(datas), size)
            stamp, vals = _decode(rows, off, fields)
            cols = {}
            for i, name in enumerate(names):
                cols[f'position/{name}'] = vals[f'p{i}']
                cols[f'velocity/{name}'] = vals[f'v{i}']
                cols[f'effort/{name}'] = vals[f'e{i}']
        else:  # irregular messages (empty velocity or effort arrays): one by one
            stamp = []
            cols = {}
            for raw in datas:
                m = ts.deserialize_cdr(raw, _JS)
                stamp.append(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
                for i, name in enumerate(m.name):
                    for kind in ('position', 'velocity', 'effort'):
                        seq = getattr(m, kind)
                        cols.setdefault(f'{kind}/{name}', []).append(seq[i] if i < len(seq) else np.nan)
            stamp = np.array(stamp, dtype=np.int64)
            cols = {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}
        parts.setdefault('stamp', []).append(_stamps(stamp, np.asarray(bag_times, dtype=np.int64)))
        for k, v in cols.items():
            parts.setdefault(k, []).append(v)
    lengths = {sum(len(x) for x in v) for v in parts.values()}
    if len(lengths) != 1:
        raise LogError(f'{path}: joint names change between JointState messages')
    return {k: np.concatenate(v) for k, v in parts.items()}


def _decode_wrench(ts, groups: dict, path: Path) -> dict:
    parts: dict[str, list[np.ndarray]] = {}
    for size, (bag_times, datas) in groups.items():
        first = ts.deserialize_cdr(datas[0], _WRENCH)
        make, fields = _wrench_maker(ts, first.header.frame_id)
        tpl, off = _layout(ts, _WRENCH, make, fields)
        if len(tpl) != size:  # pragma: no cover - WrenchStamped has one layout per frame_id
            raise LogError(f'{path}: unexpected WrenchStamped layout')
        rows = np.frombuffer(b''.join(datas), dtype=np.uint8).reshape(len(datas), size)
        stamp, vals = _decode(rows, off, fields)
        parts.setdefault('stamp', []).append(_stamps(stamp, np.asarray(bag_times, dtype=np.int64)))
        for k in ('fz', 'tz'):
            parts.setdefault(k, []).append(vals[k])
    return {k: np.concatenate(v) for k, v in parts.items()}
