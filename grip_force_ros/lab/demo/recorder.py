"""A rosbag2 (MCAP) recorder and a live cache of the latest values, in one rclpy node.

This is the only module of ``grip_force_ros.lab.demo`` besides the monitor that
imports rclpy. Messages are received serialized (``raw=True``) and written
as they are, with the publisher's type name and offered QoS, so that
``ros2 bag info`` / ``ros2 bag play`` elsewhere read the bag as if
``ros2 bag record`` had made it.
"""
from __future__ import annotations

import importlib
import threading
import time
from pathlib import Path
from typing import Any, Mapping

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                QosReliability, QosTime)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from grip_force_ros.lab.demo.messages import TOPIC_TYPES, absolute, stamp_seconds
from grip_force_ros.nodes.common import RECORD_QOS, STATE_PUB_QOS, make_executor, matching_qos
from grip_force_ros.lab.harness import SPIN_SLICE

_INFINITE = QosTime(2147483647, 4294967295)  # what rosbag2 writes for an infinite duration


def message_class(type_name: str):
    """Return the rclpy message class of 'pkg/msg/Name'."""
    pkg, _, name = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


def _qos_time(duration) -> QosTime:
    ns = int(duration.nanoseconds)
    if ns <= 0 or ns >= 2**63 - 1:
        return _INFINITE if ns else QosTime(0, 0)
    return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)


def _enum(enum_cls, policy) -> Any:
    try:
        return enum_cls[policy.name]
    except (KeyError, AttributeError):
        return enum_cls.UNKNOWN


def to_bag_qos(profile: QoSProfile) -> Qos:
    """Convert an rclpy QoS profile to the rosbags metadata record."""
    return Qos(history=_enum(QosHistory, profile.history), depth=int(profile.depth),
               reliability=_enum(QosReliability, profile.reliability),
               durability=_enum(QosDurability, profile.durability),
               deadline=_qos_time(profile.deadline), lifespan=_qos_time(profile.lifespan),
               liveliness=_enum(QosLiveliness, profile.liveliness),
               liveliness_lease_duration=_qos_time(profile.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


class RecorderNode(Node):
    """Subscribe to ``topics`` as their publishers appear; write every message to a bag.

    Parameters
    ----------
    bag_path : path or None
        Directory of the new rosbag2 (must not exist). None: record nothing,
        only keep the latest message of each topic (the monitor uses that).
    topic_types : mapping
        Topic -> type name ('sensor_msgs/msg/JointState').
    node_name : str
        Name of the recorder's node.
    context : rclpy.context.Context, optional
        The context of the node (default rclpy's).
    namespace : str
        ROS namespace of the recorded nodes ('' : the root): one arm of several
        (``PSM1``). Every topic, /diagnostics included (the demo remaps it into the arm's
        namespace), is recorded under it (``/PSM1/instrument/measured_js``), and the
        methods below take the topics' names in the root (``instrument/measured_js``).
        The recorder's own node goes in that namespace too.
    """

    def __init__(self, bag_path: str | Path | None, topic_types: Mapping[str, str] = TOPIC_TYPES,
                 node_name: str = 'grip_force_recorder', context=None, namespace: str = ''):
        self.prefix = '/' + namespace.strip('/') if namespace.strip('/') else ''
        super().__init__(node_name, context=context, namespace=self.prefix or None)
        self.topic_types = {self.full_name(t): ty for t, ty in topic_types.items()}
        self._lock = threading.Lock()
        self._latest: dict[str, tuple[float, bytes]] = {}
        self.counts: dict[str, int] = {t: 0 for t in self.topic_types}
        self._subs: dict[str, Any] = {}
        self._connections: dict[str, Any] = {}
        self._typestore = get_typestore(Stores.ROS2_JAZZY)
        self._writer: Writer | None = None
        if bag_path is not None:
            self._writer = Writer(Path(bag_path), version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.set_custom_data('recorded_by', 'grip_force_ros demo recorder')
            self._writer.open()
        self._discovery_timer = self.create_timer(0.05, self._discover)
        self._discover()

    def full_name(self, topic: str) -> str:
        """Return the recorded name of ``topic``: absolute, under the namespace if any."""
        return self.prefix + absolute(topic)

    # -- subscriptions -----------------------------------------------------
    def subscribe_all(self, qos: QoSProfile | None = None) -> None:
        """Subscribe to every topic now, before its publisher exists.

        Nothing a node publishes after discovery is then lost to the
        recorder's own polling. ``qos`` must match the publishers (default:
        RELIABLE, VOLATILE, as the package's nodes publish). The offered QoS
        written into the bag is still the publisher's, read at the first message.
        """
        qos = qos or RECORD_QOS
        for topic, type_name in self.topic_types.items():
            if topic not in self._subs:
                self._subscribe(topic, type_name, qos)
        self._discovery_timer.cancel()

    def _discover(self) -> None:
        for topic, type_name in self.topic_types.items():
            if topic in self._subs:
                continue
            infos = [i for i in self.get_publishers_info_by_topic(topic)
                     if i.topic_type == type_name]
            if not infos:
                continue
            self._subscribe(topic, type_name, matching_qos([i.qos_profile for i in infos]))
        if len(self._subs) == len(self.topic_types):
            self._discovery_timer.cancel()

    def _offered_qos(self, topic: str, type_name: str) -> list[Qos]:
        infos = [i for i in self.get_publishers_info_by_topic(topic) if i.topic_type == type_name]
        return [to_bag_qos(i.qos_profile) for i in infos] or [to_bag_qos(STATE_PUB_QOS)]

    def _subscribe(self, topic: str, type_name: str, qos: QoSProfile) -> None:
        def callback(data: bytes, topic=topic) -> None:
            now_ns = time.time_ns()
            with self._lock:
                self._latest[topic] = (now_ns * 1e-9, data)
                self.counts[topic] += 1
                if self._writer is not None:
                    conn = self._connections.get(topic)
                    if conn is None:   # first message: the publishers are known now
                        conn = self._connections[topic] = self._writer.add_connection(
                            topic, type_name, typestore=self._typestore,
                            serialization_format='cdr',
                            offered_qos_profiles=self._offered_qos(topic, type_name))
                    self._writer.write(conn, now_ns, data)

        self._subs[topic] = self.create_subscription(message_class(type_name), topic, callback,
                                                     qos, raw=True)

    # -- live values ---------------------------------------------------------
    def latest(self, topic: str) -> tuple[float, Any] | None:
        """(receive time [s], deserialized message) of the newest message on ``topic``."""
        topic = self.full_name(topic)
        with self._lock:
            item = self._latest.get(topic)
        if item is None:
            return None
        return item[0], deserialize_message(item[1], message_class(self.topic_types[topic]))

    def latest_stamp(self, topic: str) -> float | None:
        """Header stamp (s) of the newest message on ``topic``; None before the first one."""
        item = self.latest(topic)
        return None if item is None else stamp_seconds(item[1])

    def count(self, topic: str) -> int:
        with self._lock:
            return self.counts[self.full_name(topic)]

    def matched_publishers(self, topic: str) -> int:
        """Return how many publishers the subscription on ``topic`` has matched (0: none yet).

        A publisher may see this subscription before the subscription sees it: what it sends
        in between reaches the subscription only while the publisher still keeps it (its
        history depth).
        """
        subscription = self._subs.get(self.full_name(topic))
        return 0 if subscription is None else subscription.get_publisher_count()

    # -- end -----------------------------------------------------------------
    def close(self) -> Path | None:
        """Close the bag (topics never seen get a connection with no messages)."""
        with self._lock:
            if self._writer is None:
                return None
            for topic, type_name in self.topic_types.items():
                if topic not in self._connections:
                    self._connections[topic] = self._writer.add_connection(
                        topic, type_name, typestore=self._typestore,
                        offered_qos_profiles=self._offered_qos(topic, type_name))
            self._writer.close()
            path, self._writer = self._writer.path, None
        return path


def interrupt_behind(exc: BaseException) -> bool:
    """Whether a Ctrl-C (KeyboardInterrupt) is behind ``exc``, in its chain of causes.

    A KeyboardInterrupt raised while a pybind11 extension converts its return value comes out
    as a ``TypeError`` ("Unable to convert function return value to a Python type!") caused by
    it, as in :meth:`RecorderNode.latest` (rclpy's ``deserialize_message``) called from a
    main thread: a demo interrupted there exited 1 with that traceback instead of 130. The
    demo and the monitor read it as the Ctrl-C it is.
    """
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


class SpinThread:
    """Spin one node on a background thread until :meth:`stop`.

    With the EventsExecutor (:func:`~grip_force_ros.nodes.common.make_executor`): it costs
    this process about 45 us of CPU per message taken, rclpy's SingleThreadedExecutor about
    130 us (it builds a wait set in Python for every wake-up;
    ``test_recorder_works_off_a_backlog_while_the_streams_go_on`` prints the figure). A
    demo records ~6200 messages/s: 0.8 of a core with the latter, beside two SCHED_FIFO
    1 kHz nodes on a 2-core machine. The recorder then never worked off the backlog of its
    start: it stayed 0.97 s (its 1000-message history) behind for a whole demo on a quiet
    machine, 0.5 ms with the EventsExecutor.
    """

    def __init__(self, node: Node):
        self.node = node
        self.executor = make_executor(context=node.context)
        self.executor.add_node(node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f'spin-{node.get_name()}',
                                        daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set() and rclpy.ok(context=self.node.context):
            # short slices: the EventsExecutor holds the GIL while it waits
            self.executor.spin_once(timeout_sec=SPIN_SLICE)

    def start(self) -> 'SpinThread':
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop spinning and end the executor; the caller then destroys the node.

        The executor ends here, with the node still alive (see
        :func:`~grip_force_ros.nodes.lifetime.close_node`).
        """
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=5.0)
