"""A ROS 2 node over zenoh as rmw_zenoh makes one: its token, publishers and subscriptions.

Followed, in rmw_zenoh_cpp (the zenoh 1.x code of Jazzy):

- ``src/detail/rmw_node_data.cpp``: a node is only a liveliness token;
- ``src/detail/rmw_publisher_data.cpp``: declare the publisher (congestion control DROP, reliability from the
  QoS, BLOCK for a reliable KEEP_ALL), then its token; each sample carries an :class:`Attachment`, sequence
  numbers from 1, the source timestamp from the system clock in ns;
- ``src/detail/rmw_subscription_data.cpp``: subscribe to the exact data key, then declare the token; undeclare
  the token first on close.

TRANSIENT_LOCAL, as rmw_zenoh does it since 0.2.2 (Jazzy): the publisher is a zenoh-ext *AdvancedPublisher* with a
cache of the QoS depth, publisher detection (a liveliness token under the data key's ``@adv/pub`` space) and, when
reliable, sporadic heartbeats every 0.5 s; the subscription is an *AdvancedSubscriber* that queries the history of
every publisher it detects, late joiners included (the last ``depth`` samples each), and recovers a missed last
sample from the heartbeats when reliable. A volatile entity stays a plain zenoh publisher or subscriber: on the wire
the same, and no cache.

Not done (see docs/design.md): services.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any, Self, TypeVar

import zenoh
import zenoh.ext

from drd.bus.base import BusError
from drd.bus.zenoh_bus import ZenohBus

from .attachment import ATTACHMENT_SIZE, Attachment
from .msgtypes import MessageTypes
from .names import (
    DEFAULT_ENCLAVE,
    Durability,
    EntityKind,
    History,
    NodeInfo,
    QoS,
    Reliability,
    TopicInfo,
    check_node_name,
    entity_gid,
    liveliness_token,
    node_namespace,
    resolve_topic,
    topic_key,
)
from .session import Ros2Session, undeclare, zenoh_call

log = logging.getLogger("drd.bus.ros2")

#: Seconds between the sporadic heartbeats of a reliable TRANSIENT_LOCAL publisher (rmw_zenoh's
#: ``SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD``, 500 ms): a subscriber that missed the last sample asks the cache for it.
HEARTBEAT_PERIOD = 0.5


class MessageInfo:
    """How a message arrived: its key, when (``time.time()``), and the publisher's attachment, if it sent a valid
    one. The attachment is decoded when first read: most callbacks never look, and a control cycle gets ~30 messages."""

    __slots__ = ("key", "received", "_raw", "_attachment")

    def __init__(self, key: str, received: float, raw: bytes | None) -> None:
        self.key, self.received, self._raw = key, received, raw
        self._attachment: Attachment | None = None

    @property
    def attachment(self) -> Attachment | None:
        if self._attachment is None and self._raw is not None:
            raw, self._raw = self._raw, None
            try:
                self._attachment = Attachment.decode(raw)
            except ValueError as exc:
                log.debug("ros2 %s: %s", self.key, exc)
        return self._attachment

    def __repr__(self) -> str:
        return f"MessageInfo({self.key!r}, {self.received}, {self.attachment!r})"


MessageCallback = Callable[[Any, MessageInfo], None]

E = TypeVar("E", "Publisher", "Subscription")


class Ros2Node:
    """A ROS 2 node: its token, its publishers and subscriptions. Closing it undeclares them all."""

    def __init__(self, session: Ros2Session | ZenohBus | str, name: str, namespace: str = "",
                 domain_id: int = 0, *, enclave: str = DEFAULT_ENCLAVE) -> None:
        if domain_id < 0:
            raise ValueError(f"a ROS domain id is not negative, not {domain_id}")
        info = (check_node_name(name), node_namespace(namespace))  # refused before any session opens
        self._owns_session = isinstance(session, str)
        if isinstance(session, str):
            session = Ros2Session.connect(session)
        elif isinstance(session, ZenohBus):
            session = Ros2Session(session)
        self.session = session
        self.info = NodeInfo(domain_id, session.zid, session.next_id(), info[1], info[0], enclave)
        self.token = liveliness_token(EntityKind.NODE, self.info, self.info.node_id)
        self._lock = threading.Lock()
        self._entities: list[Publisher | Subscription] = []
        self._closed = False
        try:
            self._token = zenoh_call(f"node {self.name}", session.session.liveliness().declare_token, self.token)
        except BusError:
            if self._owns_session:
                session.close()
            raise

    @property
    def name(self) -> str:
        """The node's fully qualified name (``/ranger1/drd_drive``)."""
        return f"{self.info.namespace.rstrip('/')}/{self.info.name}"

    @property
    def types(self) -> MessageTypes:
        return self.session.types

    def topic(self, topic: str, type_name: str, qos: QoS | None = None) -> TopicInfo:
        """A topic as this node names it: resolved in its namespace, typed and hashed."""
        if self._closed:  # checked again when added: nothing is declared for a node already closed
            raise BusError(f"node {self.name} is closed")
        full = resolve_topic(topic, self.info.namespace, self.info.name)
        return TopicInfo(full, type_name, self.types.type_hash(type_name), qos or QoS())

    def publisher(self, topic: str, type_name: str, qos: QoS | None = None) -> Publisher:
        """Declare a publisher of ``type_name`` (e.g. ``geometry_msgs/msg/Twist``) on ``topic``."""
        return self._add(Publisher(self, self.topic(topic, type_name, qos)))

    def subscribe(self, topic: str, type_name: str, callback: MessageCallback,
                  qos: QoS | None = None) -> Subscription:
        """Declare a subscription; ``callback(message, info)`` runs on a zenoh thread of the subscription (keep it
        short), or, on a session opened with ``one_thread``, on the session's one callback thread, in arrival order
        (then never wait in it for another message of that session)."""
        return self._add(Subscription(self, self.topic(topic, type_name, qos), callback))

    def _add(self, entity: E) -> E:
        with self._lock:
            closed = self._closed
            if not closed:
                self._entities.append(entity)
        if closed:
            entity.close()
            raise BusError(f"node {self.name} is closed")
        return entity

    def close(self) -> None:
        """Undeclare every entity, then the node's token (ROS 2 tools see them go); close an own session."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            entities, self._entities = self._entities, []
        for entity in reversed(entities):
            entity.close()
        undeclare(self._token)
        if self._owns_session:
            self.session.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Ros2Node({self.name!r}, domain {self.info.domain_id}{', closed' if self._closed else ''})"


class _Entity:
    """What a publisher and a subscription share: a data key, a token, a close that undeclares both."""

    kind: EntityKind

    def __init__(self, node: Ros2Node, topic: TopicInfo) -> None:
        self.node = node
        self.topic = topic
        self.key = topic_key(node.info.domain_id, topic.name, topic.type_name, topic.type_hash)
        self.token = liveliness_token(self.kind, node.info, node.session.next_id(), topic)
        self.gid = entity_gid(self.token)
        self._lock = threading.Lock()
        self._closed = False
        self._entity: Any = None
        self._live: Any = None

    def _declare_token(self) -> None:
        try:
            liveliness = self.node.session.session.liveliness()
            self._live = zenoh_call(f"token of {self.topic.name}", liveliness.declare_token, self.token)
        except BusError:
            undeclare(self._entity)
            raise

    def close(self) -> None:
        """Undeclare the token first (the graph forgets the entity), then the zenoh entity, as rmw_zenoh does."""
        with self._lock:  # not while a publish is putting
            if self._closed:
                return
            self._closed = True
        for declared in (self._live, self._entity):
            if declared is not None:
                undeclare(declared)


class Publisher(_Entity):
    """Publishes one topic as rmw_zenoh does: CDR payload, attachment, on the topic's data key."""

    kind = EntityKind.PUBLISHER

    def __init__(self, node: Ros2Node, topic: TopicInfo) -> None:
        super().__init__(node, topic)
        qos = topic.qos
        reliable = qos.reliability is not Reliability.BEST_EFFORT
        block = reliable and qos.history is History.KEEP_ALL
        self._sequence = itertools.count(1)
        congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        reliability = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        session = node.session.session
        if qos.durability is Durability.TRANSIENT_LOCAL:  # late subscribers get the last `depth` samples
            miss = zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=HEARTBEAT_PERIOD) \
                if reliable else None
            self._entity = zenoh_call(f"publisher of {topic.name}", zenoh.ext.declare_advanced_publisher, session,
                                      self.key, congestion_control=congestion, reliability=reliability,
                                      cache=zenoh.ext.CacheConfig(max(1, qos.depth)), sample_miss_detection=miss,
                                      publisher_detection=True)
        else:
            self._entity = zenoh_call(f"publisher of {topic.name}", session.declare_publisher, self.key,
                                      congestion_control=congestion, reliability=reliability)
        self._declare_token()

    def matched(self) -> bool:
        """Whether this session knows a subscription to the topic now (zenoh's matching status: a put before that
        reaches no one). Always true for a TRANSIENT_LOCAL publisher: its cache serves a late subscriber."""
        status = getattr(self._entity, "matching_status", None)
        return True if status is None else bool(status.matching)

    def publish(self, message: object) -> None:
        """Publish a message object of the topic's type, or a mapping of its fields (see ``MessageTypes.make``)."""
        type_name = self.topic.type_name
        if isinstance(message, Mapping):
            message = self.node.types.make(type_name, **message)
        sent = getattr(message, "__msgtype__", None)
        if sent != type_name:
            raise TypeError(f"{self.topic.name} publishes {type_name}, not {sent or type(message).__name__}")
        self.publish_cdr(self.node.types.serialize(message, type_name))

    def publish_cdr(self, payload: bytes) -> None:
        """Publish an already serialized CDR payload (encapsulation header included)."""
        with self._lock:  # sequence numbers in the order of the puts
            if self._closed:
                raise BusError(f"the publisher of {self.topic.name} is closed")
            attachment = Attachment(next(self._sequence), time.time_ns(), self.gid).encode()
            zenoh_call(f"publish on {self.topic.name}", self._entity.put, payload, attachment=attachment)


class Subscription(_Entity):
    """Receives one topic; a payload that does not decode is logged and counted, never raised on zenoh's thread."""

    kind = EntityKind.SUBSCRIPTION

    def __init__(self, node: Ros2Node, topic: TopicInfo, callback: MessageCallback) -> None:
        super().__init__(node, topic)
        self.callback = callback
        self.received = 0
        self.dropped = 0
        session, qos, dispatcher = node.session.session, topic.qos, node.session.dispatcher
        if qos.durability is Durability.TRANSIENT_LOCAL:  # ask every publisher's cache, late joiners' too
            recovery = zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True) \
                if qos.reliability is not Reliability.BEST_EFFORT else None
            history = zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=max(1, qos.depth))
            self._entity = zenoh_call(f"subscription to {topic.name}", zenoh.ext.declare_advanced_subscriber,
                                      session, self.key, self._on_sample, history=history, recovery=recovery,
                                      subscriber_detection=True)
        else:
            self._entity = zenoh_call(f"subscription to {topic.name}", session.declare_subscriber, self.key,
                                      self._on_sample if dispatcher is None else dispatcher.handler(self._on_sample))
        self._declare_token()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        if sample.kind != zenoh.SampleKind.PUT or self._closed:  # one queued before the close: not delivered
            return
        received = time.time()
        raw = sample.attachment  # each read builds a new object: read once
        if raw is None or len(attached := raw.to_bytes()) < ATTACHMENT_SIZE:
            # rmw_zenoh's subscriptions drop a sample without its attachment (a plain zenoh put claiming odometry at
            # x = 50 broke a geofence: ros2 audit 18, #2); one too short to hold it is none either
            self.dropped += 1
            log.warning("ros2 %s: a sample without rmw_zenoh's attachment (sequence number, timestamp, GID) on %s: "
                        "dropped, as rmw_zenoh drops it", self.topic.name, sample.key_expr,
                        extra={"subject": self.topic.name})
            return
        try:
            message = self.node.types.deserialize(sample.payload.to_bytes(), self.topic.type_name)
        except Exception as exc:  # rosbags raises several kinds on bad bytes
            self.dropped += 1
            log.warning("ros2 %s: a payload that is not a %s: %s", self.topic.name, self.topic.type_name, exc)
            return
        self.received += 1
        try:
            self.callback(message, MessageInfo(str(sample.key_expr), received, attached))
        except Exception:
            log.exception("ros2 %s: the callback raised", self.topic.name)
