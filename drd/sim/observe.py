"""What a simulation's sensors give their drivers, as they read it: the one tap a dry-run's recorder and a cluster's
simulator host share (issue #13).

`SensorTap.tap(sim)` wraps that one simulation's `ranges`, `camera`, `brightness`, `launch`, `jump` and `set_door`
so each reading also goes to a `SensorSink`: the recorder itself in a dry-run (`drd.record.Recorder`), or, on the
cluster's simulator host, an `Observations` buffer that a recording client reads page by page over the bus
(`drd.sim.service`, key `drd/<cluster>/world`) and hands to its own recorder. Readings are plain data, so they
cross the bus as they are. No foxglove here: the simulator host does not need it.
"""

from __future__ import annotations

import functools
import math
import threading
from array import array
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

#: At most one scan per robot this often (s of sim time): the control period, the rate behaviors read at.
SCAN_EVERY = 0.1
#: Readings an `Observations` buffer keeps for its readers (the oldest go first: a reader that fell this far behind
#: misses some, and says so): at 20x real time a team of seven reads about 1,400 a second of wall time, and a
#: recording client asks five times a second. A scan's ranges are kept as 4-byte floats: 5,000 readings take a few MB.
KEPT = 5_000


class SensorSink(Protocol):
    """Where a tapped simulation's readings go (times are the simulation's)."""

    def scan(self, robot: str, at: float, ranges: list[float], max_range: float, fov: float) -> None: ...

    def camera(self, robot: str, at: float, fov: float, max_range: float, people: list[dict[str, float]]) -> None:
        ...

    def light(self, robot: str, at: float, fov: float, regions: list[float]) -> None: ...

    def view(self, robot: str, at: float, fov: float, max_range: float) -> None:
        """`robot`'s camera was read for the first time (a frame or its brightness), whether or not it saw anyone."""

    def flight(self, flight: dict[str, Any]) -> None: ...

    def door(self, door: str, at: float, state: str) -> None: ...


class SensorTap:
    """Wraps one simulation's sensor and actuator methods (see the module); scans thinned to `SCAN_EVERY`, camera
    frames to those that see someone and the first one after."""

    def __init__(self, sink: SensorSink) -> None:
        self.sink = sink
        self.sim: Any = None
        self.last_scan: dict[str, float] = {}
        self.saw: dict[str, bool] = {}  # robot -> did its last camera frame passed on see someone
        self.viewed: set[str] = set()  # robots whose camera was read (`SensorSink.view`)

    def tap(self, sim: Any) -> None:
        self.sim = sim
        for name in ("ranges", "camera", "brightness", "launch", "jump", "set_door"):
            setattr(sim, name, functools.partial(getattr(self, name), getattr(sim, name)))

    def ranges(self, read: Callable[..., list[float]], robot: str, n_beams: int, max_range: float,
               fov: float = math.pi) -> list[float]:
        out = read(robot, n_beams, max_range, fov)
        at = self.sim.time
        if at - self.last_scan.get(robot, -math.inf) >= SCAN_EVERY - 1e-9:
            self.last_scan[robot] = at
            self.sink.scan(robot, at, list(out), max_range, fov)
        return out

    def camera(self, read: Callable[..., list[Any]], robot: str, fov: float, max_range: float,
               min_light: float = 0.2) -> list[Any]:
        seen = read(robot, fov, max_range, min_light)
        self._viewed(robot, fov, max_range)
        if seen or self.saw.get(robot, False):  # a frame with people, and the first without after them
            self.saw[robot] = bool(seen)
            people = [{"label": d.label, "bearing": d.bearing, "distance": d.distance, "light": d.light}
                      for d in seen]
            self.sink.camera(robot, self.sim.time, fov, max_range, people)
        return seen

    def brightness(self, read: Callable[..., list[float]], robot: str, fov: float, n_regions: int,
                   max_range: float = 10.0) -> list[float]:
        out = read(robot, fov, n_regions, max_range)
        self._viewed(robot, fov, max_range)
        self.sink.light(robot, self.sim.time, fov, list(out))
        return out

    def _viewed(self, robot: str, fov: float, max_range: float) -> None:
        if robot not in self.viewed:
            self.viewed.add(robot)
            self.sink.view(robot, self.sim.time, fov, max_range)

    def launch(self, fly: Callable[..., Any], scout: str, heading: float, distance: float) -> Any:
        return self._flight(fly(scout, heading, distance))

    def jump(self, fly: Callable[..., Any], scout: str, dx: float) -> Any:
        return self._flight(fly(scout, dx))

    def _flight(self, f: Any) -> Any:
        self.sink.flight({"robot": f.robot, "kind": f.kind, "at": f.t0, "from": list(f.start), "to": list(f.end),
                          "lands_at": f.t1, "heading": f.heading, "blocked": f.blocked})
        return f

    def set_door(self, change: Callable[..., None], door: str, state: Any) -> None:
        change(door, state)
        self.sink.door(door, self.sim.time, str(getattr(state, "value", state)))


class Observations:
    """A `SensorSink` that keeps the readings, numbered, for readers on the bus (thread-safe: drivers in the
    simulator host's process read sensors while the bus asks for pages)."""

    def __init__(self, kept: int = KEPT) -> None:
        self.readings: deque[tuple[int, dict[str, Any]]] = deque(maxlen=kept)
        self.next = 0
        self.lock = threading.Lock()

    def _add(self, reading: dict[str, Any]) -> None:
        with self.lock:
            self.readings.append((self.next, reading))
            self.next += 1

    def scan(self, robot: str, at: float, ranges: list[float], max_range: float, fov: float) -> None:
        self._add({"reading": "scan", "robot": robot, "at": at, "max_range": max_range, "fov": fov,
                   "ranges": array("f", (r if math.isfinite(r) else max_range for r in ranges))})

    def camera(self, robot: str, at: float, fov: float, max_range: float, people: list[dict[str, float]]) -> None:
        self._add({"reading": "camera", "robot": robot, "at": at, "fov": fov, "max_range": max_range,
                   "people": people})

    def light(self, robot: str, at: float, fov: float, regions: list[float]) -> None:
        self._add({"reading": "light", "robot": robot, "at": at, "fov": fov, "regions": regions})

    def view(self, robot: str, at: float, fov: float, max_range: float) -> None:
        self._add({"reading": "view", "robot": robot, "at": at, "fov": fov, "max_range": max_range})

    def flight(self, flight: dict[str, Any]) -> None:
        self._add({"reading": "flight", **flight})

    def door(self, door: str, at: float, state: str) -> None:
        self._add({"reading": "door", "door": door, "at": at, "state": state})

    def after(self, seq: int, limit: int) -> tuple[list[dict[str, Any]], int, bool]:
        """Up to `limit` readings numbered `seq` or later, the number to ask from next, and whether some were
        already dropped (the reader fell more than `KEPT` behind)."""
        with self.lock:
            first = self.readings[0][0] if self.readings else self.next
            out = [r for n, r in self.readings if n >= seq][:limit]
        pages = [{**r, "ranges": r["ranges"].tolist()} if "ranges" in r else r for r in out]  # plain data for the bus
        return pages, max(seq, first) + len(out), seq < first


def replay(reading: dict[str, Any], sink: SensorSink, offset: float = 0.0) -> None:
    """Hand one `Observations` reading to `sink`, its times moved by `offset` (a client's mission time is the
    simulator's plus an offset)."""
    at = float(reading["at"]) + offset
    kind, robot = reading.get("reading"), str(reading.get("robot", ""))
    if kind == "scan":
        sink.scan(robot, at, [float(r) for r in reading["ranges"]], float(reading["max_range"]),
                  float(reading["fov"]))
    elif kind == "camera":
        sink.camera(robot, at, float(reading["fov"]), float(reading["max_range"]), list(reading["people"]))
    elif kind == "light":
        sink.light(robot, at, float(reading["fov"]), [float(r) for r in reading["regions"]])
    elif kind == "view":
        sink.view(robot, at, float(reading["fov"]), float(reading["max_range"]))
    elif kind == "flight":
        sink.flight({**{k: v for k, v in reading.items() if k != "reading"}, "at": at,
                     "lands_at": float(reading["lands_at"]) + offset})
    elif kind == "door":
        sink.door(str(reading["door"]), at, str(reading["state"]))
