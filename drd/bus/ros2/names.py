"""rmw_zenoh's names on the wire (ROS 2 Jazzy): data keys, liveliness tokens, the QoS string, type names.

Pure string work, no zenoh: each function is the Python reading of one piece of rmw_zenoh_cpp (the
zenoh 1.x code released with Jazzy), named in its docstring, so a mismatch can be checked line by line:

- ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp``: ``TopicInfo`` (data key), ``Entity`` (token layout),
  ``mangle_name``, ``qos_to_keyexpr`` / ``keyexpr_to_qos``;
- ``rmw_zenoh_cpp/src/detail/qos.cpp``: the defaults the QoS string leaves out;
- ``rmw_zenoh_cpp/src/detail/type_support_common.cpp``: ``_create_type_name`` (``pkg::msg::dds_::Name_``);
- ``rmw_zenoh_cpp/src/detail/graph_cache.cpp``: ``_demangle_if_ros_type`` (what ``ros2 topic list`` shows).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from enum import IntEnum, StrEnum
from typing import Self

import xxhash

ADMIN_SPACE = "@ros2_lv"
#: rcl's enclave when none is configured (mangled to ``%`` in tokens).
DEFAULT_ENCLAVE = "/"
#: rmw's infinite duration (RMW_DURATION_INFINITE): rmw_zenoh's default deadline, lifespan and lease.
INFINITE = (9223372036, 854775807)

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TYPE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)/(msg|srv|action)/([A-Za-z][A-Za-z0-9_]*)")


class EntityKind(StrEnum):
    """The entity chunk of a liveliness token (``entity_to_str`` in liveliness_utils.cpp)."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(IntEnum):
    """rmw_qos_reliability_policy_e."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    BEST_AVAILABLE = 4


class Durability(IntEnum):
    """rmw_qos_durability_policy_e."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    BEST_AVAILABLE = 4


class History(IntEnum):
    """rmw_qos_history_policy_e."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class Liveliness(IntEnum):
    """rmw_qos_liveliness_policy_e."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3
    BEST_AVAILABLE = 5


@dataclass(frozen=True, slots=True)
class QoS:
    """A QoS profile as rmw_zenoh puts it in a token. The default is rclcpp's ``QoS(10)``.

    The liveliness token carries it (zenoh delivers whatever the two sides say); reliability and history also
    set how a publisher puts, and ``TRANSIENT_LOCAL`` makes publishers and subscriptions zenoh-ext advanced ones
    with a cache and a history query of ``depth`` samples (``drd.bus.ros2.node``), as rmw_zenoh does.
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10
    deadline: tuple[int, int] = INFINITE
    lifespan: tuple[int, int] = INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    lease: tuple[int, int] = INFINITE

    @classmethod
    def sensor_data(cls) -> Self:
        """rclcpp's ``SensorDataQoS``: best effort, keep last 5 (what robots use for scans and images)."""
        return cls(reliability=Reliability.BEST_EFFORT, depth=5)

    def keyexpr(self) -> str:
        """The token's QoS chunk: ``qos_to_keyexpr``, each part empty when it equals rmw_zenoh's default.

        e.g. ``::,10:,:,:,,`` for the default (rmw_zenoh's own default depth is 42, so 10 is written).
        """
        d = _RMW_ZENOH_DEFAULT

        def part(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        return ":".join((
            part(self.reliability, d.reliability),
            part(self.durability, d.durability),
            f"{part(self.history, d.history)},{part(self.depth, d.depth)}",
            f"{part(self.deadline[0], d.deadline[0])},{part(self.deadline[1], d.deadline[1])}",
            f"{part(self.lifespan[0], d.lifespan[0])},{part(self.lifespan[1], d.lifespan[1])}",
            f"{part(self.liveliness, d.liveliness)},{part(self.lease[0], d.lease[0])},"
            f"{part(self.lease[1], d.lease[1])}",
        ))

    @classmethod
    def parse(cls, text: str) -> QoS:
        """The inverse of :meth:`keyexpr` (``keyexpr_to_qos``): empty parts take rmw_zenoh's defaults."""
        parts = text.split(":")
        if len(parts) != 6:
            raise ValueError(f"QoS chunk {text!r}: expected 6 ':'-separated parts")
        history, deadline, lifespan, live = (p.split(",") for p in parts[2:])
        if (len(history), len(deadline), len(lifespan), len(live)) != (2, 2, 2, 3):
            raise ValueError(f"QoS chunk {text!r}: wrong number of ','-separated components")
        d = _RMW_ZENOH_DEFAULT

        def num(s: str, default: int) -> int:
            return default if s == "" else int(s)

        return QoS(
            reliability=Reliability(num(parts[0], d.reliability)),
            durability=Durability(num(parts[1], d.durability)),
            history=History(num(history[0], d.history)),
            depth=num(history[1], d.depth),
            deadline=(num(deadline[0], d.deadline[0]), num(deadline[1], d.deadline[1])),
            lifespan=(num(lifespan[0], d.lifespan[0]), num(lifespan[1], d.lifespan[1])),
            liveliness=Liveliness(num(live[0], d.liveliness)),
            lease=(num(live[1], d.lease[0]), num(live[2], d.lease[1])),
        )


#: qos.cpp's ``QoS::QoS()``: what the token's QoS chunk leaves out.
_RMW_ZENOH_DEFAULT = replace(QoS(), depth=42)


def mangle(name: str) -> str:
    """``mangle_name``: ``/`` cannot appear inside a key chunk, so rmw_zenoh writes ``%``."""
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    """``demangle_name``."""
    return chunk.replace("%", "/")


def dds_type_name(type_name: str) -> str:
    """``geometry_msgs/msg/Twist`` → ``geometry_msgs::msg::dds_::Twist_`` (``_create_type_name``)."""
    m = _TYPE.fullmatch(type_name)
    if m is None:
        raise ValueError(f"ROS 2 type name {type_name!r}: expected 'package/msg/Name'")
    return f"{m[1]}::{m[2]}::dds_::{m[3]}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of :func:`dds_type_name` (``_demangle_if_ros_type``); other names are returned as given."""
    namespace, sep, rest = dds_name.partition("dds_::")
    if not sep or not rest.endswith("_"):
        return dds_name
    return namespace.replace("::", "/") + rest[:-1]


def node_namespace(namespace: str) -> str:
    """rcl's form of a namespace: absolute, no trailing ``/``; ``""`` is ``/``."""
    ns = "/" + namespace.strip("/")
    if ns != "/" and not all(_NAME.fullmatch(part) for part in ns[1:].split("/")):
        raise ValueError(f"ROS 2 namespace {namespace!r}: parts are letters, digits and '_'")
    return ns


def resolve_topic(topic: str, namespace: str = "/", node: str = "") -> str:
    """A topic's fully qualified name, as rcl expands it: ``cmd_vel`` in ``/ranger1`` is ``/ranger1/cmd_vel``."""
    if topic.startswith("~"):
        if not node:
            raise ValueError(f"topic {topic!r}: '~' needs a node name")
        topic = f"{node}/{topic[1:].lstrip('/')}"
    full = topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"
    parts = full.split("/")[1:]
    if not topic or not all(_NAME.fullmatch(p) for p in parts):
        raise ValueError(f"ROS 2 topic {topic!r}: parts are letters, digits and '_', not empty")
    return "/" + "/".join(parts)


def check_node_name(name: str) -> str:
    """Refuse a node name ROS 2 would refuse (and that would break the token's chunks)."""
    if not _NAME.fullmatch(name):
        raise ValueError(f"ROS 2 node name {name!r}: letters, digits and '_', not starting with a digit")
    return name


def topic_key(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """The data key expression (``TopicInfo``): ``<domain>/<topic without slashes at its ends>/<dds type>/<hash>``.

    e.g. ``0/ranger1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45…``.
    """
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(type_name)}/{type_hash}"


@dataclass(frozen=True, slots=True)
class NodeInfo:
    """What every token of a node's entities starts with (``NodeInfo`` plus the session's zid and node id)."""

    domain_id: int
    zid: str
    node_id: int
    namespace: str
    name: str
    enclave: str = DEFAULT_ENCLAVE


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A publisher's or subscription's topic: fully qualified name, ROS type name, RIHS01 hash, QoS."""

    name: str
    type_name: str
    type_hash: str
    qos: QoS = QoS()


def liveliness_token(kind: EntityKind, node: NodeInfo, entity_id: int, topic: TopicInfo | None = None) -> str:
    """An entity's liveliness key (``Entity::Entity``), the form ``ros2 node list`` / ``topic list`` read:

    ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>``, and for a
    publisher or subscription ``/<topic>/<dds type>/<type hash>/<qos>``; names mangled (``/`` → ``%``).
    A node's token repeats its node id as the entity id.
    """
    if (kind is EntityKind.NODE) != (topic is None):
        raise ValueError(f"a {kind.name} token {'takes no' if topic else 'needs a'} topic")
    parts = [ADMIN_SPACE, str(node.domain_id), node.zid, str(node.node_id), str(entity_id), kind.value,
             mangle(node.enclave), mangle(node.namespace), mangle(node.name)]
    if topic is not None:
        parts += [mangle(topic.name), dds_type_name(topic.type_name), topic.type_hash, topic.qos.keyexpr()]
    return "/".join(parts)


def entity_gid(token: str) -> bytes:
    """An entity's 16-byte GID as rmw_zenoh derives it (``Entity::Entity``): XXH3-128 (seed 0) of its liveliness
    key, the low 64 bits then the high 64 bits, each in the machine's (little endian) order. rmw_zenoh's graph
    computes the GID of every entity it sees from its token, so the GID in drd's attachments is the one
    ``ros2 topic info -v`` shows for drd's publisher.
    """
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")


@dataclass(frozen=True, slots=True)
class GraphEntity:
    """One liveliness token of the ROS graph, parsed (``Entity::make(keyexpr)``)."""

    kind: EntityKind
    domain_id: int
    zid: str
    node_id: str
    entity_id: str
    enclave: str
    namespace: str
    node_name: str
    topic: TopicInfo | None = None

    @property
    def node(self) -> str:
        """The node's fully qualified name, as ``ros2 node list`` prints it."""
        return f"{self.namespace.rstrip('/')}/{self.node_name}"


def parse_token(key: str) -> GraphEntity | None:
    """A liveliness key read back, or None for one that is not a well-formed rmw_zenoh token."""
    parts = key.split("/")
    if len(parts) not in (9, 13) or parts[0] != ADMIN_SPACE or any(not p for p in parts):
        return None
    try:
        kind = EntityKind(parts[5])
        topic = None
        if len(parts) == 13:
            topic = TopicInfo(demangle(parts[9]), ros_type_name(parts[10]), parts[11], QoS.parse(parts[12]))
        if (kind is EntityKind.NODE) != (topic is None):
            return None
        return GraphEntity(kind, int(parts[1]), parts[2], parts[3], parts[4], demangle(parts[6]),
                           demangle(parts[7]), demangle(parts[8]), topic)
    except ValueError:
        return None
