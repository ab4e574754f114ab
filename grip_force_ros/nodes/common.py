"""What the three nodes share: QoS, message packing and checking, the executor.

QoS (documented in docs/ros_interface.md). Every profile of the package is named
here; nothing else constructs a ``QoSProfile``:

* state and command topics (1 kHz and the master stream): publishers
  RELIABLE, VOLATILE, KEEP_LAST 10 (a recorder that lags a little still gets
  every sample on loopback), :data:`STATE_PUB_QOS`; the controller and the sim
  subscribe with KEEP_LAST 1 (:data:`STATE_SUB_QOS`), because only the newest
  sample of a state matters to a loop.
* force topics (estimated, target, measured): as state topics.
* ``/diagnostics``: RELIABLE, KEEP_LAST 10, as diagnostic_aggregator expects
  (:data:`DIAGNOSTICS_QOS`).
* recorders and monitors (the demo's bag recorder, the fault probe, the soak
  monitor): KEEP_LAST 1000, deep enough to miss nothing (:data:`RECORD_QOS`), or
  :func:`matching_qos` for whatever the publishers offer.
* the benchmark's ping-pong floor: :func:`state_qos` at the depth under test.
"""
from __future__ import annotations

import math
from typing import Iterable, Sequence

from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState


def state_qos(depth: int) -> QoSProfile:
    """RELIABLE, VOLATILE, KEEP_LAST ``depth`` (messages): the package's state/command QoS."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


#: Publishers of state, command and force topics (the master, the sim, the controller, the probe).
STATE_PUB_QOS = state_qos(10)
#: Subscriptions of a loop: only the newest sample matters.
STATE_SUB_QOS = state_qos(1)
#: ``/diagnostics`` publishers.
DIAGNOSTICS_QOS = state_qos(10)
#: Subscriptions that record or check every message (recorder, fault probe, soak monitor).
RECORD_QOS = state_qos(1000)


def matching_qos(offered: Iterable[QoSProfile]) -> QoSProfile:
    """Build a recording QoS (KEEP_LAST 1000) that matches every offered profile.

    RELIABLE only if every publisher offers it (else BEST_EFFORT), TRANSIENT_LOCAL
    only if every publisher offers it (else VOLATILE).
    """
    offered = list(offered)
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    transient = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                                      for q in offered)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORD_QOS.depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient
                      else DurabilityPolicy.VOLATILE)


class InputRejected(ValueError):
    """A received message is malformed; ``str()`` is the reason for /diagnostics."""


def joint_state(stamp, names: Sequence[str], position: Sequence[float] = (),
                velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> JointState:
    """Build a JointState (SI: rad, rad/s; effort in the unit the topic documents)."""
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = list(names)
    msg.position = [float(v) for v in position]
    msg.velocity = [float(v) for v in velocity]
    msg.effort = [float(v) for v in effort]
    return msg


def read_joints(msg: JointState, joints: Sequence[str], fields: Sequence[str],
                others: bool = False) -> dict[str, tuple]:
    """Extract ``fields`` of ``joints`` from a JointState, checking everything.

    Parameters
    ----------
    msg : JointState
        The received message.
    joints : sequence of str
        Joint names that must all be present (other names are an error too: a message for
        another device on the wrong topic must not be used).
    fields : sequence of str
        Any of 'position', 'velocity', 'effort', present and finite for the wanted joints.
    others : bool
        Other joints are normal (a dVRK arm's ``measured_js`` holds all its joints): they
        are not an error and their values are not checked.

    Returns
    -------
    dict
        joint name -> tuple of the requested fields, in the order given.

    Raises
    ------
    InputRejected
        Why the message cannot be used (names, lengths, non-finite values).
    """
    names = list(msg.name)
    if len(set(names)) != len(names):
        raise InputRejected(f'duplicate joint names {names}')
    unknown = [n for n in names if n not in joints]
    if unknown and not others:
        raise InputRejected(f'unknown joint name(s) {unknown}, expected {list(joints)}')
    missing = [n for n in joints if n not in names]
    if missing:
        raise InputRejected(f'missing joint(s) {missing}')
    arrays = {}
    for field in fields:
        values = getattr(msg, field)
        if len(values) != len(names):
            raise InputRejected(f'{field} has {len(values)} values for {len(names)} joints')
        arrays[field] = values
    out = {}
    for i, name in enumerate(names):
        if others and name not in joints:
            continue
        row = []
        for field in fields:
            v = float(arrays[field][i])
            if not math.isfinite(v):
                raise InputRejected(f'{field} of {name!r} is {v}')
            row.append(v)
        out[name] = tuple(row)
    return out


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_nanoseconds(stamp) -> int:
    """builtin_interfaces/Time as integer nanoseconds (exact, for matching stamps)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def make_executor(context=None, kind: str = 'events'):
    """Make an executor: 'events' (rclpy.experimental.EventsExecutor) or 'single'.

    The nodes' own processes (:func:`~grip_force_ros.nodes.lifetime.run_node`) spin the
    EventsExecutor; 'single' is for a caller that spins nodes of its own in a thread.
    """
    if kind == 'single':
        return SingleThreadedExecutor(context=context)
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # pragma: no cover - older rclpy
        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)
