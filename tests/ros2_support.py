"""Helpers for tests against zenoh-ros2-sdk, the independent pure-Python rmw_zenoh client.

The SDK reads ``.msg`` files from a folder (and would clone ROS repositories from the internet for the ones
missing); :func:`write_msg_files` writes them from rosbags' bundled Jazzy definitions, and :func:`ros2_sdk`
points the SDK at them and at a router port, and closes its singleton session after.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from drd.bus.ros2 import MessageTypes, Ros2Session
from drd.hosts import Cluster
from drd.hw.ros2 import message_types
from drd.sim import Simulation, load_world
from drd.sim.ros2 import ServedRobots, serve
from tests.net_support import eventually as wait
from tests.net_support import free_port

ROOT = Path(__file__).resolve().parents[1]

_SEPARATOR = re.compile(r"^=+\nMSG: ", re.M)
_SHORT = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)/([A-Za-z][A-Za-z0-9_]*)$")
WAIT = 5.0




def eventually(predicate: Callable[[], object], what: str, timeout: float = WAIT) -> None:
    """`net_support.eventually`, waiting `WAIT` by default."""
    wait(predicate, what, timeout)


def msg_definitions(types: MessageTypes, type_names: Iterable[str]) -> dict[str, str]:
    """Each type's own ``.msg`` text (and its dependencies'), from rosbags' concatenated definition."""
    out: dict[str, str] = {}
    for type_name in type_names:
        text, _md5 = types.store.generate_msgdef(type_name, ros_version=2)
        first, *others = _SEPARATOR.split(text)
        out[type_name] = first
        for other in others:
            short, _, body = other.partition("\n")
            m = _SHORT.fullmatch(short.strip())
            assert m is not None, short
            out[f"{m[1]}/msg/{m[2]}"] = body
    return out


def write_msg_files(types: MessageTypes, type_names: Iterable[str], folder: Path) -> Path:
    """``folder/<package>/msg/<Name>.msg`` for every type named and every type they use."""
    for type_name, text in msg_definitions(types, type_names).items():
        package, _msg, name = type_name.split("/")
        path = folder / package / "msg" / f"{name}.msg"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text.strip() + "\n", encoding="utf-8")
    return folder


@contextmanager
def ros2_sdk(types: MessageTypes, type_names: Iterable[str], folder: Path) -> Iterator[ModuleType]:
    """The SDK, reading its message definitions from ``folder``; its shared session is closed after."""
    sdk = pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk is not installed (pip install -e '.[test]')")
    from zenoh_ros2_sdk import message_registry, session

    message_registry._registry = message_registry.MessageRegistry(str(write_msg_files(types, type_names, folder)))
    try:
        yield sdk
    finally:
        instance = session.ZenohSession._instance
        if instance is not None:
            instance.close()
        session.ZenohSession._instance = None
        message_registry._registry = None


#: zenoh's scouting delay at open, shortened: a test's sessions find each other at once on loopback.
FAST_OPEN = {"scouting/delay": 50}


@contextmanager
def served_team(cluster: Cluster, speed: float) -> Iterator[tuple[ServedRobots, int]]:
    """The corridor world's team of `cluster` served as ROS 2 robots (at `speed` x real time) on a free loopback
    port, on a thread of this process; stopped and closed afterwards."""
    port = free_port()
    session = Ros2Session.listen(f"tcp/127.0.0.1:{port}", options=FAST_OPEN, types=message_types())
    robots = ServedRobots(Simulation(load_world(ROOT / "worlds" / "corridor.yaml")), cluster, session)
    stop = threading.Event()
    thread = threading.Thread(target=serve, args=(robots, stop), kwargs={"speed": speed}, daemon=True)
    thread.start()
    try:
        yield robots, port
    finally:
        stop.set()
        thread.join(timeout=5)
        robots.close()
        session.close()


@contextmanager
def listening_router() -> Iterator[tuple[Any, int]]:
    """A drd session in router mode on a free loopback port (what the served simulator is), and its port."""
    from drd.bus.ros2 import Ros2Session

    port = free_port()
    session = Ros2Session.listen(f"tcp/127.0.0.1:{port}", options=FAST_OPEN)
    try:
        yield session, port
    finally:
        session.close()
