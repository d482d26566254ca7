"""An independent ROS 2 robot for drd's `ros2` drivers (a process of its own), written from ROS 2 conventions with
zenoh and zenoh-ros2-sdk only: no drd code. Adapted from the audit's fake robot (a Ranger in a corridor 2.5 m wide).

Usage: python3 tests/fake_ros2_robot.py PORT MSG_FOLDER CMD_LOG [POSE_FILE]. It runs its own zenoh router on
tcp/127.0.0.1:PORT (as rmw_zenohd would), reads its message definitions from MSG_FOLDER
(``<package>/msg/<Name>.msg``), publishes /ranger1/odom (integrating the cmd_vel it gets), scan, camera image and
detections, battery and an empty magazine, and appends every /ranger1/cmd_vel Twist it receives to CMD_LOG as a
JSON line {"v", "w"}; with POSE_FILE, it keeps there its odometry pose of the last tick, {"x", "y", "th"} (in its
own odom frame: 0, 0, 0 where it was switched on). Its laser sees the corridor's two walls, 1.25 m either side of
the line it started on (+inf where a beam hits neither within 8 m). Prints "serving" once ready; runs until
SIGTERM."""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import zenoh


def main() -> None:
    port, folder, cmd_log = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    pose_file = sys.argv[4] if len(sys.argv) > 4 else None
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    router = zenoh.open(config)
    from zenoh_ros2_sdk import message_registry

    message_registry._registry = message_registry.MessageRegistry(folder)
    import zenoh_ros2_sdk as sdk
    from zenoh_ros2_sdk.qos import QosProfile, QosReliability

    sensor = QosProfile(reliability=QosReliability.BEST_EFFORT, history_depth=5)
    kw: dict[str, Any] = {"router_port": port, "namespace": "/ranger1", "node_name": "fakebot"}
    pubs = {name: sdk.ROS2Publisher(topic, typ, qos=qos, **kw) for name, topic, typ, qos in [
        ("odom", "/ranger1/odom", "nav_msgs/msg/Odometry", None),
        ("scan", "/ranger1/scan", "sensor_msgs/msg/LaserScan", sensor),
        ("image", "/ranger1/camera/image_raw", "sensor_msgs/msg/Image", sensor),
        ("detections", "/ranger1/camera/detections", "vision_msgs/msg/Detection2DArray", sensor),
        ("battery", "/ranger1/battery_state", "sensor_msgs/msg/BatteryState", None),
        ("magazine", "/ranger1/launcher/magazine", "std_msgs/msg/String", None)]}
    types = pubs["odom"].session_mgr.store.types
    state = {"x": 0.0, "y": 0.0, "th": 0.0, "v": 0.0, "w": 0.0}
    lock = threading.Lock()
    log = open(cmd_log, "a", encoding="utf-8")  # noqa: SIM115 - open for the process's life

    def on_cmd(m: Any) -> None:
        with lock:
            state["v"], state["w"] = m.linear.x, m.angular.z
            log.write(json.dumps({"v": m.linear.x, "w": m.angular.z}) + "\n")
            log.flush()

    sub = sdk.ROS2Subscriber("/ranger1/cmd_vel", "geometry_msgs/msg/Twist", on_cmd, **kw)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print("serving", flush=True)
    k = 0
    while not stop.is_set():
        now = time.time()
        with lock:
            state["th"] += state["w"] * 0.05
            state["x"] += state["v"] * math.cos(state["th"]) * 0.05
            state["y"] += state["v"] * math.sin(state["th"]) * 0.05
            pose = dict(state)
        publish(pubs, types, pose, now, k)
        if pose_file is not None:
            keep(pose_file, pose)
        k += 1
        time.sleep(max(0.0, 0.05 - (time.time() - now)))
    for p in pubs.values():
        p.close()
    sub.close()
    router.close()


def keep(path: str, pose: dict[str, float]) -> None:
    """The pose, replacing the last one at once (a reader never sees half a file)."""
    tmp = Path(path + ".tmp")
    tmp.write_text(json.dumps({"x": pose["x"], "y": pose["y"], "th": pose["th"]}), encoding="utf-8")
    os.replace(tmp, path)


def publish(pubs: dict[str, Any], t: dict[str, Any], s: dict[str, float], now: float, k: int) -> None:
    """One 50 ms tick: odometry always, scan and camera every other tick, battery and magazine every tenth."""
    def header(frame: str) -> Any:
        stamp = t["builtin_interfaces/msg/Time"](sec=int(now), nanosec=int((now % 1) * 1e9))
        return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    v3, th = t["geometry_msgs/msg/Vector3"], s["th"]
    pose = t["geometry_msgs/msg/PoseWithCovariance"](pose=t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=s["x"], y=s["y"], z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2))),
        covariance=np.zeros(36))
    twist = t["geometry_msgs/msg/TwistWithCovariance"](twist=t["geometry_msgs/msg/Twist"](
        linear=v3(x=s["v"], y=0.0, z=0.0), angular=v3(x=0.0, y=0.0, z=s["w"])), covariance=np.zeros(36))
    pubs["odom"].publish(header=header("odom"), child_frame_id="base_link", pose=pose, twist=twist)
    if k % 2 == 0:
        amin, inc = -math.pi / 2, math.pi / 180
        ranges = []
        for i in range(181):
            sin = math.sin(amin + i * inc + th)
            wall = (1.25 - s["y"]) / sin if sin > 1e-6 else (-1.25 - s["y"]) / sin if sin < -1e-6 else math.inf
            ranges.append(wall if wall <= 8.0 else math.inf)
        pubs["scan"].publish(header=header("base_scan"), angle_min=amin, angle_max=-amin, angle_increment=inc,
                             time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=8.0,
                             ranges=np.array(ranges, dtype=np.float32), intensities=np.zeros(0, dtype=np.float32))
        pubs["image"].publish(header=header("camera"), height=1, width=16, encoding="32FC1", is_bigendian=0, step=64,
                              data=np.frombuffer(np.full(16, 0.5, dtype="<f4").tobytes(), dtype=np.uint8))
        pubs["detections"].publish(header=header("camera"), detections=[])
    if k % 10 == 0:
        nan = math.nan
        pubs["battery"].publish(
            header=header("base_link"), voltage=12.0, temperature=nan, current=nan, charge=nan, capacity=nan,
            design_capacity=nan, percentage=0.9, power_supply_status=2, power_supply_health=1,
            power_supply_technology=0, present=True, cell_voltage=np.zeros(0, dtype=np.float32),
            cell_temperature=np.zeros(0, dtype=np.float32), location="", serial_number="")
        pubs["magazine"].publish(data="[]")


if __name__ == "__main__":
    main()
