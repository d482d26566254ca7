"""The rest of rmw_zenoh's wire format (issue #19): the GID as rmw_zenoh computes it, and TRANSIENT_LOCAL topics.

The GID is XXH3-128 of the entity's liveliness key (rmw_zenoh_cpp ``liveliness_utils.cpp``, ``Entity::Entity``):
computed here with the `xxhash` library on the token another session reads from the graph, it must equal the GID in
the attachment of drd's samples. A TRANSIENT_LOCAL publisher keeps its last ``depth`` samples for subscribers that
join later: read back by a raw zenoh-ext AdvancedSubscriber configured as rmw_zenoh configures one, by
zenoh-ros2-sdk's transient-local subscriber (an independent client), and by a drd subscription."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import xxhash
import zenoh
import zenoh.ext

from drd.bus.ros2 import Attachment, EntityKind, MessageInfo, QoS, Ros2Node, Ros2Session, jazzy
from drd.bus.ros2.names import Durability, entity_gid
from tests.ros2_support import eventually, listening_router, ros2_sdk

STRING = "std_msgs/msg/String"
LATCHED = QoS(durability=Durability.TRANSIENT_LOCAL, depth=2)  # a map's or /tf_static's profile, 2 kept


def rmw_zenoh_gid(token: str) -> bytes:
    """``Entity::Entity``: XXH3-128 of the key, ``memcpy`` of its low then its high 64 bits (little endian)."""
    digest = xxhash.xxh3_128_intdigest(token.encode())
    low, high = digest & (2**64 - 1), digest >> 64
    return low.to_bytes(8, "little") + high.to_bytes(8, "little")


@pytest.fixture
def router() -> Iterator[tuple[Ros2Session, int]]:
    with listening_router() as served:
        yield served


def test_xxh3_is_the_reference_algorithm() -> None:
    """xxHash's own test vector (XXH3_128bits of no bytes, seed 0), so the library is the reference XXH3."""
    assert xxhash.xxh3_128_intdigest(b"") == 0x99AA06D3014798D86001C324468D497F
    token = ("@ros2_lv/0/abc/0/1/MP/%/%ranger1/drd/%ranger1%cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_x/"
             "::,10:,:,:,,")
    canonical = xxhash.xxh3_128_digest(token.encode())  # xxHash's canonical form: high 64 bits first, big endian
    assert entity_gid(token) == rmw_zenoh_gid(token) == canonical[8:][::-1] + canonical[:8][::-1]


def test_the_gid_in_drds_attachment_is_xxh3_of_its_token_on_the_graph(router: tuple[Ros2Session, int]) -> None:
    session, port = router
    got: list[MessageInfo] = []
    robot = Ros2Node(session, "fake_robot", namespace="ranger1")
    drd = Ros2Node(f"tcp/127.0.0.1:{port}", "drd", namespace="ranger1")
    try:
        robot.subscribe("cmd_vel", "geometry_msgs/msg/Twist", lambda msg, info: got.append(info))
        cmd = drd.publisher("cmd_vel", "geometry_msgs/msg/Twist")
        # the token as the robot's graph sees it (a liveliness query from the other session), not drd's own string
        tokens: list[str] = []

        def listed() -> bool:
            replies = session.session.liveliness().get("@ros2_lv/0/*/*/*/MP/**", timeout=1.0)
            tokens[:] = [str(r.ok.key_expr) for r in replies if r.ok is not None and "cmd_vel" in str(r.ok.key_expr)]
            return bool(tokens)

        eventually(listed, "drd's publisher on the graph")
        assert tokens == [cmd.token]

        def sent() -> bool:
            cmd.publish({"linear": {"x": 0.1}})
            return bool(got)

        eventually(sent, "a Twist with its attachment")
        attachment = got[0].attachment
        assert attachment is not None and attachment.gid == rmw_zenoh_gid(tokens[0]) == cmd.gid
        sub_token = next(e for e in session.graph(0) if e.kind is EntityKind.SUBSCRIPTION)
        assert sub_token.topic is not None and sub_token.topic.name == "/ranger1/cmd_vel"
    finally:
        drd.close()
        robot.close()


def _publish_three(node: Ros2Node, topic: str, router: Ros2Session) -> Any:
    """Three samples, routed before this returns: a subscriber declared after must get them from the cache, not
    live (puts still on their way to the router would reach a subscriber declared meanwhile)."""
    pub = node.publisher(topic, STRING, LATCHED)
    for text in ("first", "second", "third"):
        pub.publish({"data": text})
    _flush(node, router)
    return pub


def _flush(node: Ros2Node, router: Ros2Session) -> None:
    """A query from the node's session answered by the router: it travels behind the puts (same link, same
    priority, in order), so its reply means the router has routed them."""
    key = f"drd_test/flush/{node.info.node_id}"
    queryable = router.session.declare_queryable(key, lambda query: query.reply(key, b""))
    try:
        eventually(lambda: any(r.ok is not None for r in node.session.session.get(key, timeout=1.0)),
                   "the router to answer behind the puts")
    finally:
        queryable.undeclare()


def test_a_late_advanced_subscriber_gets_the_last_transient_local_samples(router: tuple[Ros2Session, int]) -> None:
    """As rmw_zenoh's SubscriptionData subscribes to a TRANSIENT_LOCAL topic: history with late publisher detection,
    at most `depth` samples, recovery by heartbeat (reliable), and the subscriber's own detection token."""
    session, port = router
    drd = Ros2Node(f"tcp/127.0.0.1:{port}", "drd_map", namespace="ranger1")
    late = zenoh.open(_client(port))
    got: list[tuple[str, Attachment]] = []
    lock = threading.Lock()
    types = jazzy()

    def on_sample(sample: zenoh.Sample) -> None:
        assert sample.attachment is not None
        message = types.deserialize(sample.payload.to_bytes(), STRING)
        with lock:
            got.append((message.data, Attachment.decode(sample.attachment.to_bytes())))

    sub = None
    try:
        pub = _publish_three(drd, "map", session)  # published before anyone listens
        sub = zenoh.ext.declare_advanced_subscriber(
            late, pub.key, on_sample, history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=2),
            recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True), subscriber_detection=True)
        eventually(lambda: len(got) >= 2, "the cached samples")
        with lock:
            assert [text for text, _ in got] == ["second", "third"]  # the last `depth`, in order
            assert [a.sequence_number for _, a in got] == [2, 3] and all(a.gid == pub.gid for _, a in got)
        pub.publish({"data": "fourth"})  # and then the live ones
        eventually(lambda: len(got) >= 3, "a live sample after the history")
        assert got[2][0] == "fourth"
    finally:
        if sub is not None:
            sub.undeclare()
        late.close()
        drd.close()


def test_the_sdk_and_drd_subscriptions_joining_late_get_them_too(router: tuple[Ros2Session, int],
                                                                tmp_path: Path) -> None:
    session, port = router
    drd = Ros2Node(f"tcp/127.0.0.1:{port}", "drd_map", namespace="")
    listener = Ros2Node(session, "late_listener")
    mine: list[str] = []
    try:
        _publish_three(drd, "/map", session)
        listener.subscribe("/map", STRING, lambda msg, info: mine.append(msg.data), LATCHED)
        eventually(lambda: len(mine) >= 2, "drd's transient-local subscription to get the cache")
        assert mine[:2] == ["second", "third"]
        with ros2_sdk(jazzy(), [STRING], tmp_path / "msgs") as sdk:
            from zenoh_ros2_sdk.qos import QosDurability, QosProfile

            theirs: list[str] = []
            qos = QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=2)
            sub = sdk.ROS2Subscriber(topic="/map", msg_type=STRING, callback=lambda m: theirs.append(m.data),
                                     domain_id=0, router_port=port, qos=qos)
            try:
                # the SDK queries the caches with zenoh's default consolidation (the latest sample per key), so it
                # gets the last one only: rmw_zenoh's AdvancedSubscriber gets `depth` (above)
                eventually(lambda: bool(theirs), "the SDK's transient-local subscriber to get the cache")
                assert theirs[0] == "third"
            finally:
                sub.close()
    finally:
        listener.close()
        drd.close()


def _client(port: int) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{port}"]')
    return config
