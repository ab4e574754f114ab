"""The loop's messages as serialized bytes: JointState and WrenchStamped without Python objects.

rclpy turns every message a subscription takes into Python message objects, and every one
a node publishes back into C structures: about 30 us for a ``sensor_msgs/JointState`` taken
and 13 us for one published on the reference machine (BENCHMARKS.md, "The nodes' own
cost"), most of a 1 kHz node's own CPU. The loop nodes take their 1 kHz inputs with
``raw=True`` and read the few numbers they need straight from the CDR bytes (about 5 us),
and publish their 1 kHz outputs as bytes filled into a template serialized once. What goes
over DDS is the same CDR that rclpy would have written, so every other subscriber (``ros2
topic echo``, a bag recorder, the dVRK) sees ordinary messages.

The layout (XCDR1 little endian, as Fast DDS writes it): a 4-byte encapsulation header,
then the fields in order, each aligned to its size counted from the end of that header;
strings are a uint32 length (with the NUL) and the bytes; sequences a uint32 count and the
elements. Bytes that do not parse raise :class:`~grip_force_ros.nodes.common.InputRejected`,
so a malformed message is refused as a typed one would be.
"""
from __future__ import annotations

import struct
from typing import Sequence

from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from grip_force_ros.nodes.common import InputRejected

_U32 = struct.Struct('<I').unpack_from
_STAMP = struct.Struct('<iI')
_WRENCH = struct.Struct('<6d')
_HEADER = 4          # bytes of the CDR encapsulation header; alignment counts from its end
FIELDS = ('position', 'velocity', 'effort')


def _align(offset: int, size: int) -> int:
    """Return ``offset`` (bytes from the buffer's start) moved up to a multiple of ``size``."""
    return offset + (-(offset - _HEADER) & (size - 1))


class JointStateData:
    """The values of one serialized ``sensor_msgs/JointState``, read without rclpy.

    Attributes with the message's names, so :func:`~grip_force_ros.nodes.common.read_joints`
    takes it as it takes a message: ``name`` (list of str), ``position``, ``velocity``,
    ``effort`` (tuples of float: rad or m, rad/s or m/s, N*m, N or the profile's unit).

    Parameters
    ----------
    data : bytes
        The CDR bytes a ``raw=True`` subscription delivers.

    Raises
    ------
    InputRejected
        The bytes do not hold a JointState (truncated, bad lengths, bad text).
    """

    __slots__ = ('sec', 'nanosec', 'frame_id', 'name', 'position', 'velocity', 'effort',
                 'offsets', 'end')

    def __init__(self, data: bytes):
        try:
            self.sec, self.nanosec = _STAMP.unpack_from(data, _HEADER)
            (size,) = _U32(data, 12)
            self.frame_id = data[16:16 + size - 1].decode() if size else ''
            offset = _align(16 + size, 4)
            (count,) = _U32(data, offset)
            offset += 4
            names = []
            for _ in range(count):
                (size,) = _U32(data, offset)
                offset += 4
                names.append(data[offset:offset + size - 1].decode())
                offset = _align(offset + size, 4)
            self.name = names
            offsets = []
            arrays = []
            for _ in FIELDS:
                (count,) = _U32(data, offset)
                offset += 4
                if count:
                    offset = _align(offset, 8)
                    arrays.append(struct.unpack_from(f'<{count}d', data, offset))
                else:
                    arrays.append(())
                offsets.append(offset)
                offset += 8 * count
        except (struct.error, UnicodeDecodeError, MemoryError, OverflowError) as exc:
            raise InputRejected(f'not a serialized JointState ({exc})') from None
        self.position, self.velocity, self.effort = arrays
        self.offsets = offsets      # bytes from the start: each field's first value
        self.end = offset           # bytes from the start: the end of the last field

    @property
    def stamp(self) -> float:
        """Return the header time in seconds (0.0 when unset)."""
        return self.sec + self.nanosec * 1e-9


class JointStateWriter:
    """Serialized ``sensor_msgs/JointState`` of fixed joints and fields, filled per message.

    Parameters
    ----------
    names : sequence of str
        Joint names, in order.
    fields : sequence of str
        Which of 'position', 'velocity', 'effort' the message carries (one value per joint
        each); the others are empty.
    frame_id : str
        Header frame id.

    Examples
    --------
    >>> w = JointStateWriter(['jaw_drum'], ('effort',))
    >>> data = w.write(1, 500, (0.25,))       # stamp 1.0000005 s, effort 0.25
    """

    def __init__(self, names: Sequence[str], fields: Sequence[str], frame_id: str = ''):
        unknown = [f for f in fields if f not in FIELDS]
        if unknown:
            raise ValueError(f'unknown JointState field(s) {unknown}; any of {FIELDS}')
        self.names = tuple(names)
        self.fields = tuple(f for f in FIELDS if f in fields)   # the message's order
        n = len(self.names)
        msg = JointState(name=list(self.names))
        msg.header.frame_id = frame_id
        for field in self.fields:
            setattr(msg, field, [0.0] * n)
        data = serialize_message(msg)
        parsed = JointStateData(data)
        # rclpy's buffer may run past the message (room reserved for empty sequences); a
        # strict reader (rosbags) takes the message's own length, padded to 4 bytes
        self._buffer = bytearray(data[:_align(parsed.end, 4)])
        starts = [parsed.offsets[FIELDS.index(f)] for f in self.fields]
        # one pack of the stamp, one of each field's doubles
        self._values = [(struct.Struct(f'<{n}d'), start) for start in starts]
        self._width = n

    def write(self, sec: int, nanosec: int, *values: Sequence[float]) -> bytes:
        """Return the message's bytes with the stamp (s, ns) and one sequence per field."""
        buffer = self._buffer
        _STAMP.pack_into(buffer, _HEADER, sec, nanosec)
        for (packer, start), field_values in zip(self._values, values):
            packer.pack_into(buffer, start, *field_values)
        return bytes(buffer)


def read_wrench(data: bytes) -> tuple[float, float, float, float]:
    """Return (stamp s, force x, y, z in N) of a serialized ``geometry_msgs/WrenchStamped``.

    Raises
    ------
    InputRejected
        The bytes do not hold a WrenchStamped.
    """
    try:
        sec, nanosec = _STAMP.unpack_from(data, _HEADER)
        (size,) = _U32(data, 12)
        fx, fy, fz = _WRENCH.unpack_from(data, _align(16 + size, 8))[:3]
    except struct.error as exc:
        raise InputRejected(f'not a serialized WrenchStamped ({exc})') from None
    return sec + nanosec * 1e-9, fx, fy, fz


class WrenchWriter:
    """Serialized ``geometry_msgs/WrenchStamped`` (force and torque), filled per message.

    Parameters
    ----------
    frame_id : str
        Header frame id.
    """

    def __init__(self, frame_id: str = ''):
        msg = WrenchStamped()
        msg.header.frame_id = frame_id
        self._buffer = bytearray(serialize_message(msg))
        self._start = _align(16 + len(frame_id.encode()) + 1, 8)

    def write(self, sec: int, nanosec: int, force: Sequence[float],
              torque: Sequence[float] = (0.0, 0.0, 0.0)) -> bytes:
        """Return the bytes with the stamp (s, ns), force (N) and torque (N*m)."""
        buffer = self._buffer
        _STAMP.pack_into(buffer, _HEADER, sec, nanosec)
        _WRENCH.pack_into(buffer, self._start, *force, *torque)
        return bytes(buffer)
