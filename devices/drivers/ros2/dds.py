"""The DDS side of the ``ros2`` cell: one participant per domain, ROS 2 topic names and QoS, latest-sample readers.

ROS 2 (rmw_cyclonedds, rmw_fastrtps) maps topic ``/a/b`` to the DDS topic ``rt/a/b`` and message
``pkg/msg/Name`` to the DDS type ``pkg::msg::dds_::Name_`` (``messages.py``). QoS as the ROS 2 drivers use it:
sensor streams (images, camera info, joint states) are read best effort (a best-effort reader matches both
reliable and best-effort publishers), commands (trajectories, position commands) are sent reliable, volatile,
like a controller's subscription expects.

:class:`DdsConfig` is the network part of a device's cell-file section (``domain_id``, ``interface``,
``peers``); every ``ros2`` device of a process with the same settings shares one :class:`Node` (one DDS
participant), released when the last device closes.

Deleting readers (cyclonedds-python 11): a ``DataReader`` deletes its DDS reader only when Python frees it by
reference count. A reader freed by the cyclic garbage collector (it is in, or hangs off, a reference cycle, as a
reader whose listener calls back into its owner always does) keeps its DDS reader: the collector clears the weak
entity registry first, so ``Entity.__del__`` skips ``dds_delete``, then frees the listener's ctypes thunk, and
the next sample's listener call jumps into freed memory (a segfault; ``benchmarks/crash_ros2_close.py``). So
every reader here is deleted explicitly: :meth:`Subscription.close` marks it closed, deletes the DDS reader
(``dds_delete`` waits for a listener call in progress; the GIL is released meanwhile) and only then drops the
listener; a device closes its subscriptions before it releases the node, and :func:`release` closes the
subscriptions left open on the node (it keeps every one alive until then) before it deletes the participant.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from devices.drivers.common import import_vendor
from devices.protocols import DeviceError
from planner.validate import integer, require


@dataclass(frozen=True)
class DdsConfig:
    """Where the ROS 2 graph is: the DDS domain and, optionally, the network interface and unicast peers."""

    domain_id: int = 0
    """The DDS domain: ``ROS_DOMAIN_ID`` of the lab's ROS 2 nodes (0 to 232)."""
    interface: str = ""
    """The network interface DDS uses (e.g. "eth0", "lo"); empty: cyclonedds' choice (or CYCLONEDDS_URI's)."""
    peers: tuple[str, ...] = ()
    """Unicast discovery peers (addresses); empty: multicast discovery, as ROS 2's default."""

    def __post_init__(self) -> None:
        require(
            integer(self.domain_id) and 0 <= self.domain_id <= 232,
            f"domain_id: an integer in [0, 232] (ROS_DOMAIN_ID), got {self.domain_id!r}",
        )
        require(isinstance(self.interface, str), f"interface: a network interface name, got {self.interface!r}")
        require(
            isinstance(self.peers, list | tuple) and all(isinstance(p, str) and p for p in self.peers),
            f"peers: a list of addresses, got {self.peers!r}",
        )
        object.__setattr__(self, "peers", tuple(self.peers))

    def xml(self) -> str:
        """The cyclonedds configuration of these settings ("" when nothing is set: the defaults)."""
        if not self.interface and not self.peers:
            return ""
        general = f'<Interfaces><NetworkInterface name="{self.interface}"/></Interfaces>' if self.interface else ""
        discovery = ""
        if self.peers:
            general += "<AllowMulticast>false</AllowMulticast>"
            peers = "".join(f'<Peer address="{p}"/>' for p in self.peers)
            discovery = f"<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex><Peers>{peers}</Peers></Discovery>"
        return f"<CycloneDDS><Domain><General>{general}</General>{discovery}</Domain></CycloneDDS>"


def ros_topic(name: str) -> str:
    """The DDS topic of a ROS 2 topic name (``/joint_states`` -> ``rt/joint_states``)."""
    return "rt/" + name.lstrip("/")


def sensor_qos() -> Any:
    """Best effort, volatile, keep the last 5: reads sensor streams from any publisher."""
    core = import_vendor("cyclonedds.core", "ros2", "ROS 2 cell")
    qos = import_vendor("cyclonedds.qos", "ros2", "ROS 2 cell")
    return qos.Qos(core.Policy.Reliability.BestEffort, core.Policy.Durability.Volatile, core.Policy.History.KeepLast(5))


def command_qos() -> Any:
    """Reliable, volatile, keep the last 10: what a ros2_control controller's command subscription expects."""
    core = import_vendor("cyclonedds.core", "ros2", "ROS 2 cell")
    qos = import_vendor("cyclonedds.qos", "ros2", "ROS 2 cell")
    return qos.Qos(
        core.Policy.Reliability.Reliable(max_blocking_time=100_000_000),
        core.Policy.Durability.Volatile,
        core.Policy.History.KeepLast(10),
    )


def await_subscriber(writer: Any, timeout_s: float, refusal: str) -> None:
    """Wait until something subscribes to ``writer``'s topic (a controller's command subscription): a command
    written before discovery matched a reader is lost. DeviceError ``refusal`` after ``timeout_s`` seconds."""
    waited = time.monotonic() + timeout_s
    while not writer.get_matched_subscriptions():
        if time.monotonic() > waited:
            raise DeviceError(refusal)
        time.sleep(0.02)


class Subscription:
    """A ROS 2 topic read in the background: the latest sample, arrival times for the rate, and waiting.

    on_sample (optional) is called in the reader's thread for every sample (keep it short). qos: the reader's
    (default :func:`sensor_qos`). :meth:`close` deletes the reader (the owner's close; else the node's release).
    """

    def __init__(
        self,
        node: Node,
        topic: str,
        message: type,
        on_sample: Callable[[Any], None] | None = None,
        qos: Any = None,
    ) -> None:
        sub = import_vendor("cyclonedds.sub", "ros2", "ROS 2 cell")
        core = import_vendor("cyclonedds.core", "ros2", "ROS 2 cell")
        self.topic = topic
        self.message = message
        self._on_sample = on_sample
        self._cond = threading.Condition()
        self.latest: Any = None
        self.count = 0
        self.arrivals: deque[float] = deque(maxlen=50)
        self.closed = False
        self._node = node
        # the listener holds this subscription weakly: no reference cycle through the reader
        listener = core.Listener(on_data_available=_weak_on_data(self))
        self._reader: Any = sub.DataReader(
            node.participant,
            node.topic(topic, message),
            qos=qos if qos is not None else sensor_qos(),
            listener=listener,
        )
        node.subscriptions.append(self)

    def close(self) -> None:
        """Delete the reader (idempotent): no sample is handed over after this returns. Not from ``on_sample``."""
        if self.closed:
            return
        self.closed = True
        reader, self._reader = self._reader, None
        if reader is not None:
            delete_entity(reader)  # waits for a listener call in progress, then no more calls
        self._on_sample = None
        with _nodes_lock:
            if self in self._node.subscriptions:
                self._node.subscriptions.remove(self)
        with self._cond:
            self._cond.notify_all()

    def _on_data(self, reader: Any) -> None:
        if self.closed or reader is None:  # None: the reader is being deleted
            return
        try:
            samples = reader.take(N=64)
        except Exception:  # the reader is being deleted (the device closed): nothing to take
            return
        on_sample = self._on_sample
        for sample in samples:
            if not isinstance(sample, self.message):  # an invalid sample (a writer's dispose)
                continue
            if on_sample is not None:
                on_sample(sample)
            with self._cond:
                self.latest = sample
                self.count += 1
                self.arrivals.append(time.monotonic())
                self._cond.notify_all()

    def wait(self, predicate: Callable[[Any], bool], timeout: float) -> Any:
        """The first sample (the latest, then each new one) for which ``predicate`` holds, or None after
        ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        with self._cond:
            seen = -1
            while True:
                if self.latest is not None and self.count != seen:
                    seen = self.count
                    if predicate(self.latest):
                        return self.latest
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(min(left, 0.05))

    def age(self) -> float | None:
        """Seconds since the last sample arrived (None: none has)."""
        with self._cond:
            return time.monotonic() - self.arrivals[-1] if self.arrivals else None

    def rate(self) -> float | None:
        """Samples per second over the last arrivals (None: fewer than 2)."""
        with self._cond:
            if len(self.arrivals) < 2 or self.arrivals[-1] <= self.arrivals[0]:
                return None
            return (len(self.arrivals) - 1) / (self.arrivals[-1] - self.arrivals[0])


def _weak_on_data(subscription: Subscription) -> Callable[[Any], None]:
    """A listener callback that reaches ``subscription`` through a weak reference."""
    ref = weakref.ref(subscription)

    def on_data(reader: Any) -> None:
        target = ref()
        if target is not None:
            target._on_data(reader)

    return on_data


def delete_entity(entity: Any) -> None:
    """Delete a cyclonedds entity's DDS entity now (idempotent; its children with it). cyclonedds-python deletes one
    only in ``Entity.__del__`` (which does nothing after the first call), so that is called here explicitly."""
    entity.__del__()


class Node:
    """One DDS participant on a domain, shared by the ``ros2`` devices of a process (see :func:`acquire`).

    ``settled_stamp``: the ROS time (seconds) at which the arm or the turntable last came to rest; a capture
    takes a frame stamped after it.
    """

    def __init__(self, config: DdsConfig) -> None:
        domain = import_vendor("cyclonedds.domain", "ros2", "ROS 2 cell")
        topic = import_vendor("cyclonedds.topic", "ros2", "ROS 2 cell")
        self.config = config
        self._topic_cls = topic.Topic
        self._topics: dict[str, Any] = {}
        self.settled_stamp = 0.0
        self.users = 0
        self.subscriptions: list[Subscription] = []
        """The open subscriptions on this participant (closed at the last release, if their owner has not)."""
        xml = config.xml()
        try:
            self._domain = domain.Domain(config.domain_id, xml) if xml else None
            self.participant = domain.DomainParticipant(config.domain_id)
        except Exception as exc:  # cyclonedds raises DDSException for a bad interface or configuration
            raise DeviceError(f"DDS domain {config.domain_id}: cannot start ({exc})") from None

    def topic(self, name: str, message: type) -> Any:
        """The DDS topic of ROS 2 topic ``name`` carrying ``message`` (created once)."""
        if name not in self._topics:
            self._topics[name] = self._topic_cls(self.participant, ros_topic(name), message)
        return self._topics[name]

    def writer(self, name: str, message: type) -> Any:
        """A reliable writer on ROS 2 topic ``name`` (commands)."""
        pub = import_vendor("cyclonedds.pub", "ros2", "ROS 2 cell")
        return pub.DataWriter(self.participant, self.topic(name, message), qos=command_qos())

    def sensor_writer(self, name: str, message: type) -> Any:
        """A best-effort writer on ROS 2 topic ``name`` (how a sensor driver publishes: the test cell's)."""
        pub = import_vendor("cyclonedds.pub", "ros2", "ROS 2 cell")
        return pub.DataWriter(self.participant, self.topic(name, message), qos=sensor_qos())


_nodes: dict[DdsConfig, Node] = {}
_nodes_lock = threading.Lock()


def acquire(config: DdsConfig) -> Node:
    """The shared :class:`Node` of ``config`` (created on first use). DeviceError when another configuration of
    the same domain is already open in this process (one domain, one network set-up)."""
    with _nodes_lock:
        node = _nodes.get(config)
        if node is None:
            clash = [c for c in _nodes if c.domain_id == config.domain_id]
            if clash:
                raise DeviceError(
                    f"DDS domain {config.domain_id}: already open with interface {clash[0].interface!r} and peers "
                    f"{list(clash[0].peers)}; give every ros2 device of a cell the same domain_id, interface, peers"
                )
            node = _nodes[config] = Node(config)
        node.users += 1
        return node


def release(node: Node) -> None:
    """One user fewer; the participant is deleted with its last user."""
    with _nodes_lock:
        node.users -= 1
        if node.users > 0:
            return
        _nodes.pop(node.config, None)
        left = list(node.subscriptions)
    for subscription in left:  # readers first, while the participant lives (never by the garbage collector)
        subscription.close()
    if node.participant is not None:
        delete_entity(node.participant)  # the writers and topics with it
    node._topics.clear()
    node.participant = None
    node._domain = None
