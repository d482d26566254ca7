"""Issue #15/#16: a component's state taken (`snapshot`) and given back elsewhere (`restore`), and journaled.

Each standard behavior whose state matters goes on from a snapshot as if it had never stopped (a Wait keeps its
deadline and its step count, a Watch its count and whom it reported, an Observe its frames), and is told when
its state is lost (`restore(None)`). The snapshot survives JSON in the mission's image (what the journal
stores); that a mission entered again by a new executive restores its running leaf from it (the Wait ends at
its original deadline) runs the executive, so it is in tests/integration/test_resume.py.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from components.behaviors.observe import Observe
from components.behaviors.wait import Wait
from components.behaviors.watch import Watch
from drd.manifests import parse_manifest
from drd.runtime.component import Component, Context, Status
from drd.runtime.snapshot import NodeImage
from dsl.catalog import Catalog


class Clock:
    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


Made = tuple[Component, list[str], list[tuple[str, dict[str, Any]]]]


def made(comp: Component, params: Mapping[str, Any], clock: Clock, devices: Mapping[str, Any] | None = None,
         state: Mapping[str, Any] | None | str = "fresh") -> Made:
    """`comp` set up over a context of its own, restored with `state` unless "fresh", and started."""
    logs: list[str] = []
    events: list[tuple[str, dict[str, Any]]] = []
    ctx = Context("M/x", dict(params), {}, lambda ev, **f: events.append((ev, f)), logs.append, clock,
                  devices=dict(devices or {}))
    comp.setup(ctx)
    if state != "fresh":
        comp.restore(None if isinstance(state, str) else state)
    comp.start()
    return comp, logs, events


def through_json(state: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    assert state is not None
    restored: Mapping[str, Any] = json.loads(json.dumps(state, allow_nan=False))
    return restored


def test_a_wait_restored_elsewhere_keeps_its_deadline_and_its_step_count() -> None:
    clock = Clock(2.0)
    first, _, _ = made(Wait(), {"duration": 10.0}, clock)
    for t in (3.0, 4.0, 5.0):
        assert first.step(t) is Status.RUNNING
    state = through_json(first.snapshot())
    clock.t = 7.5  # moved: set up and started again 2.5 s later, somewhere else
    second, logs, _ = made(Wait(), {"duration": 10.0}, clock, state=state)
    assert second.step(11.9) is Status.RUNNING
    assert second.step(12.0) is Status.SUCCESS  # began at 2 s: 10 s later, not 10 s after the move
    assert second.ctx.outputs["waited"]["steps"] == 5 and logs == []


def test_a_wait_told_its_state_is_lost_waits_its_whole_duration_again_and_says_so() -> None:
    clock = Clock(7.5)
    wait, logs, _ = made(Wait(), {"duration": 10.0}, clock, state="lost")
    assert wait.step(12.0) is Status.RUNNING and wait.step(17.5) is Status.SUCCESS
    assert logs and "state was lost" in logs[0]


class Camera:
    fov = math.radians(60)

    def __init__(self) -> None:
        self.seen = [SimpleNamespace(label="p1", distance=2.0, bearing=0.0)]

    def detections(self) -> list[Any]:
        return self.seen

    def brightness(self, regions: int) -> list[float]:
        return [0.5] * regions


def test_a_watch_restored_keeps_its_count_and_does_not_report_a_person_again() -> None:
    clock = Clock(0.0)
    camera = Camera()
    first, _, events = made(Watch(), {"duration": 30.0, "threshold": 0.05}, clock, {"camera": camera})
    first.step(1.0)
    camera.seen = [SimpleNamespace(label="p1", distance=2.0, bearing=0.6)]  # moved about 1.1 m
    first.step(2.0)
    assert len(events) == 2
    state = through_json(first.snapshot())
    clock.t = 5.0
    second, _, again = made(Watch(), {"duration": 30.0, "threshold": 0.05}, clock, {"camera": camera}, state=state)
    assert second.step(6.0) is Status.RUNNING
    assert again == []  # p1 stood still since its last event: not reported again
    camera.seen = [SimpleNamespace(label="p2", distance=1.0, bearing=0.0)]
    second.step(7.0)
    assert len(again) == 1 and second.snapshot() is not None and second.snapshot()["events"] == 3  # type: ignore[index]
    assert second.step(30.0) is Status.SUCCESS  # began at 0 s, not at the restore


def test_an_observe_restored_goes_on_with_its_frames_and_camera_time() -> None:
    clock = Clock(0.0)
    first, _, _ = made(Observe(), {"duration": 5.0}, clock, {"camera": Camera()})
    for t in (1.0, 2.0, 3.0):
        first.step(t)
    state = through_json(first.snapshot())
    clock.t = 10.0
    second, _, _ = made(Observe(), {"duration": 5.0}, clock, {"camera": Camera()}, state=state)
    assert second.step(11.0) is Status.RUNNING
    assert second.step(12.0) is Status.SUCCESS  # 3 s observed before, 2 s after
    assert second.ctx.outputs["observation"] == {"frames": 5}


def test_a_component_keeps_no_state_by_default() -> None:
    comp = Component()
    assert comp.snapshot() is None
    comp.restore({"anything": 1})  # ignored: it starts afresh


MANIFEST = {"name": "Roam", "kind": "behavior", "description": "d", "entry_point": "m:Roam", "movable": True}


def test_the_manifest_says_whether_a_component_can_move() -> None:
    ct, problems = parse_manifest(MANIFEST, "Roam/manifest.yaml")
    assert ct is not None and ct.movable and problems == []
    bound = {**MANIFEST, "needs": {"drive": {"type": "Drive"}}, "interfaces": ["Drive"]}
    _, problems = parse_manifest(bound, "Roam/manifest.yaml")
    assert [(p.key, "cannot move" in p.message) for p in problems] == [("movable", True)]


def test_every_standard_behavior_says_whether_it_can_move_and_only_the_wait_can(catalog: Catalog) -> None:
    behaviors = [t for t in catalog.components.values() if t.kind.value == "behavior"]
    for t in behaviors:
        assert "movable:" in Path(t.source).read_text(), t.source
    assert [t.name for t in behaviors if t.movable] == ["Wait"]


def test_an_image_without_component_snapshots_still_reads() -> None:
    """A journal written before snapshots existed: its leaves are restarted (and told so)."""
    image = NodeImage.from_dict({"path": "P", "state": "P", "phase": "active", "entered": 1.0,
                                 "children": [{"path": "P/W", "state": "W", "phase": "active", "entered": 1.0}]})
    assert [n.component for n in image.walk()] == [None, None]
    again = NodeImage.from_dict(json.loads(json.dumps(NodeImage("P/W", "W", "active", 1.0,
                                                                component=[{"began": 1.0}]).to_dict())))
    assert again.component == [{"began": 1.0}]
