"""drd on a ROS 2 graph through rmw_zenoh's wire format (ROS 2 Jazzy), with no ROS installed.

A ROS 2 robot running rmw_zenoh publishes on zenoh keys ``<domain>/<topic>/<type>/<RIHS01 hash>`` with CDR
payloads and an attachment, and announces its nodes and topics with liveliness tokens under ``@ros2_lv``. This
package speaks the same: :class:`Ros2Node` publishes and subscribes, its entities show in ``ros2 node list`` and
``ros2 topic list``. ``names`` is the naming (pure), ``msgtypes`` the messages (rosbags), ``attachment`` what
rides with each sample, ``session`` and ``node`` the zenoh side.

    with Ros2Node("tcp/192.168.1.20:7447", "drd_drive", namespace="ranger1") as node:
        cmd = node.publisher("cmd_vel", "geometry_msgs/msg/Twist")
        cmd.publish({"linear": {"x": 0.2}})
        node.subscribe("odom", "nav_msgs/msg/Odometry", lambda msg, info: print(msg.pose.pose.position))
"""

from __future__ import annotations

from .attachment import Attachment
from .msgtypes import MessageTypes, jazzy
from .names import (
    DEFAULT_ENCLAVE,
    Durability,
    EntityKind,
    GraphEntity,
    History,
    Liveliness,
    NodeInfo,
    QoS,
    Reliability,
    TopicInfo,
    dds_type_name,
    liveliness_token,
    parse_token,
    resolve_topic,
    ros_type_name,
    topic_key,
)
from .node import MessageCallback, MessageInfo, Publisher, Ros2Node, Subscription
from .session import Ros2Session

__all__ = [
    "DEFAULT_ENCLAVE",
    "Attachment",
    "Durability",
    "EntityKind",
    "GraphEntity",
    "History",
    "Liveliness",
    "MessageCallback",
    "MessageInfo",
    "MessageTypes",
    "NodeInfo",
    "Publisher",
    "QoS",
    "Reliability",
    "Ros2Node",
    "Ros2Session",
    "Subscription",
    "TopicInfo",
    "dds_type_name",
    "jazzy",
    "liveliness_token",
    "parse_token",
    "resolve_topic",
    "ros_type_name",
    "topic_key",
]
