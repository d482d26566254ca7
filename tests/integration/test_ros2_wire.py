"""The rmw_zenoh wire layer (drd.bus.ros2): bytes, keys and tokens as ROS 2 Jazzy's rmw_zenoh writes them, checked
against rmw_zenoh's own documented examples and against zenoh-ros2-sdk, an independent implementation, over real
zenoh sessions on loopback."""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drd.bus import BusError
from drd.bus.ros2 import (
    Attachment,
    EntityKind,
    MessageInfo,
    NodeInfo,
    QoS,
    Ros2Node,
    Ros2Session,
    TopicInfo,
    dds_type_name,
    jazzy,
    liveliness_token,
    parse_token,
    resolve_topic,
    ros_type_name,
    topic_key,
)
from drd.bus.ros2.names import Durability, Reliability, entity_gid
from drd.bus.zenoh_bus import ZenohBus
from tests.ros2_support import eventually, free_port, listening_router, ros2_sdk

TWIST = "geometry_msgs/msg/Twist"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"  # rmw_zenoh docs/design.md
SCAN = "sensor_msgs/msg/LaserScan"
SDK_TYPES = (TWIST, SCAN)
FAST_OPEN = {"scouting/delay": 50}


# --- bytes, keys, tokens (no network) -----------------------------------------------------------


def test_the_type_hash_and_data_key_of_twist_are_rmw_zenohs() -> None:
    types = jazzy()
    assert types.type_hash(TWIST) == TWIST_HASH
    assert types.type_hash("std_msgs/msg/String") == STRING_HASH
    topic = resolve_topic("cmd_vel", "/ranger1")
    assert topic == "/ranger1/cmd_vel"
    assert topic_key(0, topic, TWIST, TWIST_HASH) == f"0/ranger1/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}"
    # docs/design.md's data key examples (demo_nodes_cpp's talker, with and without a namespace)
    assert topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    assert topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH) == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")


def test_names_resolve_as_rcl_resolves_them() -> None:
    assert resolve_topic("/odom", "/ranger1") == "/odom"
    assert resolve_topic("scan", "/") == "/scan"
    assert resolve_topic("~/status", "/ranger1", "drive") == "/ranger1/drive/status"
    assert dds_type_name("nav_msgs/msg/Odometry") == "nav_msgs::msg::dds_::Odometry_"
    assert ros_type_name("nav_msgs::msg::dds_::Odometry_") == "nav_msgs/msg/Odometry"
    for bad in ("", "/", "a//b", "cmd vel", "1scan", "a/*"):
        with pytest.raises(ValueError):
            resolve_topic(bad, "/ranger1")
    with pytest.raises(ValueError):
        dds_type_name("Twist")


def test_liveliness_tokens_are_docs_design_mds_examples() -> None:
    """rmw_zenoh's docs/design.md (Graph Cache): demo_nodes_cpp's listener and talker, token for token."""
    listener = NodeInfo(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener")
    talker = NodeInfo(2, "8b20917502ee955ac4476e0266340d5c", 0, "/", "talker")
    chatter = TopicInfo("/chatter", "std_msgs/msg/String", STRING_HASH, QoS(depth=7))
    assert liveliness_token(EntityKind.NODE, listener, 0) == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener")
    assert liveliness_token(EntityKind.SUBSCRIPTION, listener, 10, TopicInfo(
        "/chatter", "std_msgs/msg/String", STRING_HASH)) == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/::,10:,:,:,,")
    token = liveliness_token(EntityKind.PUBLISHER, talker, 10, chatter)
    assert token == ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
                     f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
    parsed = parse_token(token)
    assert parsed is not None and parsed.topic == chatter and parsed.node == "/talker"
    assert (parsed.kind, parsed.domain_id, parsed.node_id, parsed.entity_id) == (EntityKind.PUBLISHER, 2, "0", "10")
    ranger = NodeInfo(0, "abc", 3, "/ranger1", "drd_drive")
    assert liveliness_token(EntityKind.NODE, ranger, 3) == "@ros2_lv/0/abc/3/3/NN/%/%ranger1/drd_drive"
    node = parse_token("@ros2_lv/0/abc/3/3/NN/%/%ranger1/drd_drive")
    assert node is not None and node.node == "/ranger1/drd_drive" and node.namespace == "/ranger1"
    assert parse_token("@ros2_lv/0/abc/3/4/MP/%/%/n") is None  # a publisher without its topic
    assert len(entity_gid(token)) == 16 and entity_gid(token) != entity_gid(liveliness_token(
        EntityKind.NODE, talker, 0))


def test_the_qos_chunk_leaves_out_rmw_zenohs_defaults() -> None:
    assert QoS().keyexpr() == "::,10:,:,:,,"
    assert QoS.sensor_data().keyexpr() == "2::,5:,:,:,,"
    latched = QoS(durability=Durability.TRANSIENT_LOCAL, depth=1)
    assert latched.keyexpr() == ":1:,1:,:,:,,"
    assert QoS(depth=42).keyexpr() == "::,:,:,:,,"  # rmw_zenoh's own default depth is left out too
    odd = QoS(reliability=Reliability.BEST_EFFORT, deadline=(1, 500), lease=(3, 0))
    assert odd.keyexpr() == "2::,10:1,500:,:,3,0"
    for qos in (QoS(), QoS.sensor_data(), latched, odd):
        assert QoS.parse(qos.keyexpr()) == qos
    with pytest.raises(ValueError):
        QoS.parse("::,10")


def _values(types: Any, type_name: str) -> dict[str, Any]:
    """Each message type filled with values that are not defaults."""
    header = {"stamp": {"sec": 1700000000, "nanosec": 250}, "frame_id": "ranger1/base"}
    return {
        TWIST: {"linear": {"x": 0.4, "y": -0.1}, "angular": {"z": 1.25}},
        "nav_msgs/msg/Odometry": {"header": header, "child_frame_id": "base_link",
                                  "pose": {"pose": {"position": {"x": 2.5, "y": -1.0},
                                                    "orientation": {"z": 0.7071, "w": 0.7071}},
                                           "covariance": [0.01 * i for i in range(36)]},
                                  "twist": {"twist": {"linear": {"x": 0.3}}}},
        SCAN: {"header": header, "angle_min": -1.5, "angle_max": 1.5, "angle_increment": 0.5,
               "range_min": 0.125, "range_max": 12.0, "ranges": [1.0, 2.5, float("inf"), 0.75, 3.0, 4.0, 5.5],
               "intensities": []},
        "sensor_msgs/msg/Image": {"header": header, "height": 2, "width": 3, "encoding": "rgb8", "step": 9,
                                  "data": list(range(18))},
    }[type_name]


def _same(a: Any, b: Any) -> bool:
    """Field by field, numpy arrays by value."""
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(_same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


@pytest.mark.parametrize("type_name", [TWIST, "nav_msgs/msg/Odometry", SCAN, "sensor_msgs/msg/Image"])
def test_cdr_round_trips_through_rosbags(type_name: str) -> None:
    types = jazzy()
    message = types.make(type_name, **_values(types, type_name))
    data = types.serialize(message, type_name)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little endian encapsulation, as rmw_zenoh's payloads start
    back = types.deserialize(data, type_name)
    assert _same(back, message)
    assert types.serialize(back, type_name) == data


def test_the_cdr_of_a_twist_is_six_little_endian_doubles() -> None:
    types = jazzy()
    data = types.serialize(types.make(TWIST, linear={"x": 0.4}, angular={"z": -1.0}), TWIST)
    assert data == b"\x00\x01\x00\x00" + struct.pack("<6d", 0.4, 0, 0, 0, 0, -1.0)


def test_make_fills_in_defaults_and_refuses_what_the_type_lacks() -> None:
    types = jazzy()
    odom = types.make("nav_msgs/msg/Odometry")
    assert odom.pose.pose.orientation.w == 1.0 and odom.pose.covariance.shape == (36,)
    with pytest.raises(ValueError, match="no field"):
        types.make(TWIST, speed=1.0)
    with pytest.raises(ValueError, match="fixed array of 36"):
        types.make("geometry_msgs/msg/PoseWithCovariance", covariance=[0.0])
    with pytest.raises(ValueError, match="unknown ROS 2 message type"):
        types.make("vision_msgs/msg/Detection2DArray")


def test_made_messages_share_no_nested_message_or_array() -> None:
    """`make` works out each type's defaults once: a second message must still get its own header and arrays."""
    types = jazzy()
    first, second = types.make("sensor_msgs/msg/LaserScan"), types.make("sensor_msgs/msg/LaserScan", range_max=8.0)
    first.header.frame_id = "ranger1/laser"
    assert second.header.frame_id == "" and first.ranges is not second.ranges
    assert (first.range_max, second.range_max) == (0.0, 8.0)
    pose = types.make("geometry_msgs/msg/Pose", orientation={"z": 1.0})
    assert (pose.orientation.z, pose.orientation.w) == (1.0, 1.0)  # the .msg default w = 1 still applies


def test_the_attachment_is_rmw_zenohs_33_bytes_and_reads_the_sdks() -> None:
    gid = bytes(range(16))
    data = Attachment(7, 1_700_000_000_123456789, gid).encode()
    assert data == struct.pack("<qqB", 7, 1_700_000_000_123456789, 16) + gid
    assert Attachment.decode(data) == Attachment(7, 1_700_000_000_123456789, gid)
    sdk = pytest.importorskip("zenoh_ros2_sdk.attachment")
    theirs = sdk.Attachment(sequence_id=3, timestamp_ns=42, gid=gid[::-1]).to_bytes()
    assert Attachment.decode(theirs) == Attachment(3, 42, gid[::-1])
    for bad in (b"", data[:-1], struct.pack("<qqB", 1, 2, 4) + b"abcd"):
        with pytest.raises(ValueError):
            Attachment.decode(bad)
    assert Attachment.decode(data + b"\x00") == Attachment.decode(data)  # bytes after, as rmw_zenoh: ignored


def test_a_messages_attachment_is_read_when_asked_and_none_when_it_is_not_rmw_zenohs() -> None:
    data = Attachment(7, 42, bytes(range(16))).encode()
    info = MessageInfo("0/x", 1.0, data)
    assert info.attachment == Attachment(7, 42, bytes(range(16))) and info.attachment is info.attachment
    assert MessageInfo("0/x", 1.0, data[:-1]).attachment is None
    assert MessageInfo("0/x", 1.0, None).attachment is None


# --- over zenoh, against zenoh-ros2-sdk ---------------------------------------------------------


@pytest.fixture
def router() -> Iterator[tuple[Ros2Session, int]]:
    """A drd session in router mode on a free loopback port: what the served simulator will be."""
    with listening_router() as served:
        yield served


@pytest.fixture
def sdk(tmp_path: Path) -> Iterator[Any]:
    with ros2_sdk(jazzy(), SDK_TYPES, tmp_path / "msgs") as module:
        yield module


def test_the_sdk_receives_a_scan_drd_publishes(router: tuple[Ros2Session, int], sdk: Any) -> None:
    session, port = router
    got: list[Any] = []
    node = Ros2Node(session, "drd_scan", namespace="ranger1")
    sub = None
    try:
        scan = node.publisher("scan", SCAN, QoS.sensor_data())
        sub = sdk.ROS2Subscriber(topic="/ranger1/scan", msg_type=SCAN, callback=got.append, domain_id=0,
                                 router_port=port)
        assert sub.keyexpr == scan.key  # the SDK computed the same type hash from the .msg files
        values = _values(jazzy(), SCAN)

        def sent() -> bool:
            scan.publish(values)
            return bool(got)

        eventually(sent, "the SDK's subscriber to get a LaserScan")
        msg = got[0]
        assert msg.header.frame_id == "ranger1/base" and msg.header.stamp.sec == 1700000000
        assert (msg.angle_min, msg.angle_max, msg.range_max) == (-1.5, 1.5, 12.0)
        assert np.array_equal(msg.ranges, np.asarray(values["ranges"], dtype=np.float32))
        assert len(msg.intensities) == 0
    finally:
        if sub is not None:
            sub.close()
        node.close()


def test_drd_receives_a_twist_the_sdk_publishes(router: tuple[Ros2Session, int], sdk: Any) -> None:
    _session, port = router
    got: list[tuple[Any, MessageInfo]] = []
    lock = threading.Lock()

    def on_twist(msg: Any, info: MessageInfo) -> None:
        with lock:
            got.append((msg, info))

    # a client of the router, as drd's drivers are of a robot's router
    node = Ros2Node(f"tcp/127.0.0.1:{port}", "drd_drive", namespace="ranger1")
    pub = None
    try:
        sub = node.subscribe("cmd_vel", TWIST, on_twist)
        pub = sdk.ROS2Publisher(topic="/ranger1/cmd_vel", msg_type=TWIST, domain_id=0, router_port=port)
        assert pub.keyexpr == sub.key
        vector = pub.session_mgr.store.types["geometry_msgs/msg/Vector3"]
        before = time.time_ns()

        def sent() -> bool:
            pub.publish(linear=vector(x=0.25, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=-0.5))
            with lock:
                return bool(got)

        eventually(sent, "drd's subscription to get a Twist")
        msg, info = got[0]
        assert (msg.linear.x, msg.linear.y, msg.angular.z) == (0.25, 0.0, -0.5)
        assert info.key == sub.key and info.attachment is not None
        assert info.attachment.gid == pub.publisher_gid  # the SDK's attachment, read as rmw_zenoh's
        assert before - 10**9 <= info.attachment.source_timestamp <= time.time_ns()
        assert sub.received >= 1 and sub.dropped == 0
    finally:
        if pub is not None:
            pub.close()
        node.close()


def test_the_sdk_lists_drds_topics_types_and_node(router: tuple[Ros2Session, int], sdk: Any) -> None:
    session, port = router
    drive = Ros2Node(session, "drd_drive", namespace="ranger1")
    client = Ros2Node(f"tcp/127.0.0.1:{port}", "drd_sensors", namespace="ranger1")
    try:
        drive.publisher("cmd_vel", TWIST)
        drive.subscribe("odom", "nav_msgs/msg/Odometry", lambda msg, info: None)
        client.publisher("scan", SCAN, QoS.sensor_data())
        wanted = {"/ranger1/cmd_vel": [TWIST], "/ranger1/odom": ["nav_msgs/msg/Odometry"], "/ranger1/scan": [SCAN]}
        listed: dict[str, list[str]] = {}

        def shown() -> bool:
            listed.update(dict(sdk.get_topic_names_and_types(domain_id=0, router_port=port, timeout=0.5)))
            return all(listed.get(t) == types for t, types in wanted.items())

        eventually(shown, f"the SDK to list {wanted} (it lists {listed})")
        info = sdk.get_topic_info("/ranger1/scan", domain_id=0, router_port=port, verbose=True)
        assert info.publisher_count == 1 and info.topic_types == [SCAN]
        endpoint = info.publishers[0]
        assert (endpoint.node_name, endpoint.node_namespace) == ("drd_sensors", "/ranger1")
        assert endpoint.type_hash == jazzy().type_hash(SCAN) and endpoint.qos == "2::,5:,:,:,,"
        odom = sdk.get_topic_info("/ranger1/odom", domain_id=0, router_port=port, verbose=True)
        assert odom.subscriber_count == 1 and odom.subscribers[0].node_name == "drd_drive"
        # the raw liveliness tokens, as rmw_zenoh's graph cache reads them: both nodes are there
        nodes = {e.node for e in session.graph(0) if e.kind is EntityKind.NODE}
        assert {"/ranger1/drd_drive", "/ranger1/drd_sensors"} <= nodes
        client.close()
        eventually(lambda: "/ranger1/scan" not in dict(sdk.get_topic_names_and_types(
            domain_id=0, router_port=port, timeout=0.5)), "the closed node's topic to leave the graph")
    finally:
        client.close()
        drive.close()


def test_drd_to_drd_through_a_router_with_attachments(router: tuple[Ros2Session, int]) -> None:
    session, port = router
    got: list[MessageInfo] = []
    robot = Ros2Node(session, "fake_robot", namespace="ranger1")
    bus = ZenohBus(connect=[f"tcp/127.0.0.1:{port}"], options=FAST_OPEN, name="drd host")  # a daemon's own bus
    try:
        sub = robot.subscribe("cmd_vel", TWIST, lambda msg, info: got.append(info))
        driver = Ros2Node(bus, "drd_drive", namespace="ranger1")
        other = Ros2Node(bus, "drd_scan", namespace="ranger1")  # one session, one counter: ids never repeat
        cmd = driver.publisher("cmd_vel", TWIST)
        assert (driver.info.node_id, other.info.node_id) == (0, 1)
        assert cmd.token.startswith(f"@ros2_lv/0/{driver.session.zid}/0/2/MP/%/%ranger1/drd_drive/%ranger1%cmd_vel/")

        def sent() -> bool:
            cmd.publish({"linear": {"x": 0.1}})
            return bool(got)

        eventually(sent, "a Twist from drd to drd")
        first = got[0].attachment
        assert first is not None and first.gid == cmd.gid and first.sequence_number >= 1
        with pytest.raises(TypeError, match="publishes geometry_msgs/msg/Twist"):
            cmd.publish(jazzy().make(SCAN))
        attached = Attachment(7, 0, bytes(16)).encode()
        session.session.put(sub.key, b"not cdr", attachment=attached)  # a payload that does not decode: counted
        eventually(lambda: sub.dropped == 1, "the bad payload to be dropped")
        # a good Twist without rmw_zenoh's attachment (or with one too short to be it): dropped, as rmw_zenoh's
        # subscriptions drop it (ros2 audit 18, #2: a plain put claiming odometry at x = 50 broke a geofence)
        heard, twist = len(got), jazzy().serialize(jazzy().make(TWIST), TWIST)
        session.session.put(sub.key, twist)
        session.session.put(sub.key, twist, attachment=attached[:20])
        eventually(lambda: sub.dropped == 3, "the samples without an attachment to be dropped")
        session.session.put(sub.key, twist, attachment=attached)
        eventually(lambda: len(got) == heard + 1, "the attached one to be heard")
        driver.close()
        with pytest.raises(BusError, match="closed"):
            cmd.publish({"linear": {"x": 0.1}})
        with pytest.raises(BusError, match="closed"):
            driver.publisher("scan", SCAN)
        eventually(lambda: all(e.node != "/ranger1/drd_drive" for e in session.graph(0)), "drd_drive to leave")
        other.close()
    finally:
        robot.close()
        bus.close()


def test_a_one_thread_session_runs_every_callback_on_one_thread_in_arrival_order(
        router: tuple[Ros2Session, int]) -> None:
    """The lockstep's sessions: one callback thread for all their subscriptions, stopped when the session closes;
    and a publisher says when the router knows a subscription (a put before that reaches no one)."""
    session, port = router
    robot = Ros2Node(session, "fake_robot", namespace="ranger1")
    client = Ros2Session.connect(f"tcp/127.0.0.1:{port}", options=FAST_OPEN, one_thread=True)
    got: list[tuple[str, int, str]] = []
    try:
        odom, scan = robot.publisher("odom_x", TWIST), robot.publisher("scan_x", TWIST)
        assert not odom.matched()
        drd = Ros2Node(client, "drd", namespace="ranger1")
        for name in ("odom_x", "scan_x"):
            drd.subscribe(name, TWIST, lambda msg, info, n=name: got.append((n, int(msg.linear.x),
                                                                            threading.current_thread().name)))
        eventually(lambda: odom.matched() and scan.matched(), "the router to know both subscriptions")
        for k in range(20):
            (odom if k % 2 == 0 else scan).publish({"linear": {"x": float(k)}})
        eventually(lambda: len(got) == 20, "20 messages")
        assert [x for _, x, _ in got] == list(range(20))  # arrival order, across the two topics
        threads = {t for _, _, t in got}
        assert len(threads) == 1 and threads != {threading.current_thread().name}
        (thread,) = (t for t in threading.enumerate() if t.name in threads)
    finally:
        client.close()
        robot.close()
    thread.join(timeout=5)
    assert not thread.is_alive()


def test_a_node_refuses_bad_names_and_says_when_no_router_answers() -> None:
    for name, namespace in (("drd drive", ""), ("1drive", ""), ("drive", "ranger 1")):
        with pytest.raises(ValueError):
            Ros2Node("tcp/127.0.0.1:1", name, namespace)
    with pytest.raises(BusError, match="cannot open a zenoh session"):
        Ros2Node(f"tcp/127.0.0.1:{free_port()}", "drive")
