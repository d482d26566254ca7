"""A component instance (or a daemon service) as hosts announce it and the Component Database lists it: the one
record the Creator (`drd.cluster.creator`) and the daemon's view (`drd.daemon.view`) share."""

from __future__ import annotations

from drd.bus import Message, message


@message("drd.daemon.instance", 2)
class InstanceInfo(Message):
    """A running component instance (or a daemon service) and where it answers."""

    name: str
    component: str
    host: str
    state: str = "running"
    key: str = ""
    pid: int | None = None  # the worker process running a component instance (None for a daemon service)
    mission: str = ""  # the mission of a component instance (several may run the same paths)
