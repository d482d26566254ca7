"""A running mission's state as plain data, and the plan to enter it again (issue #16: a mission survives its
controller).

`capture` reads the state tree after a macro step: for every live node its path and state, when it was entered
(so `after` timers keep their deadlines), its variables and shared data, its finished children's outputs, a
parallel state's finished regions, a multiplicity's counters and live instances, and the grant it held (with its
epochs). `Restore` is what the interpreter consults while it enters the mission again: instead of a compound
state's initial child it enters the child that was active, a parallel state only its unfinished regions, a
multiplicity its live instances with their counters, and each node takes back its entry time and variables.
Grants are asked for again (new epochs, so nothing the old controller sent is obeyed). A running leaf's
image holds its component's snapshot (`Component.snapshot`, plain data), and a leaf entered again is given it
(`Component.restore`), or None when it had none: it is restarted, and told so. Pure: no I/O (but the
components' `snapshot`); values are tagged so a resource comes back as the pool's resource, not as its id.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from drd.runtime.component import MAX_SNAPSHOT
from drd.runtime.pool import ResourceView
from drd.runtime.tree import DONE, Node

#: The version of the snapshot format (`drd.journal` refuses another). Version 1 images (no `component`) read as
#: leaves without a snapshot: their components are restarted, and told so.
VERSION = 1

_INDEX = re.compile(r"\[(\d+)\]$")


def encode(value: Any) -> Any:
    """A value as JSON carries it, tagged where plain JSON would lose what it is (`["$r", id]` for a resource,
    `["$t", [...]]` for a tuple); None for what cannot be carried (left out by the caller)."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else ["$f", repr(value)]
    if isinstance(value, ResourceView):
        return ["$r", value.id]
    if isinstance(value, tuple):
        return ["$t", [encode(v) for v in value]]
    if isinstance(value, list):
        return [encode(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): encode(v) for k, v in value.items()}
    return ["$s", str(value)]


def decode(data: Any, resource: Callable[[str], Any]) -> Any:
    """`encode`'s inverse (`resource(id)` gives back a resource's view)."""
    if isinstance(data, list):
        if len(data) == 2 and data[0] == "$r" and isinstance(data[1], str):
            return resource(data[1])
        if len(data) == 2 and data[0] == "$t" and isinstance(data[1], list):
            return tuple(decode(v, resource) for v in data[1])
        if len(data) == 2 and data[0] == "$f" and isinstance(data[1], str):
            return float(data[1])
        if len(data) == 2 and data[0] == "$s":
            return str(data[1])
        return [decode(v, resource) for v in data]
    if isinstance(data, dict):
        return {k: decode(v, resource) for k, v in data.items()}
    return data


@dataclass
class NodeImage:
    """One live node as `capture` saw it."""

    path: str
    state: str
    phase: str
    entered: float
    data: dict[str, Any] = field(default_factory=dict)  # variables and shared data (encoded)
    outputs: dict[str, Any] = field(default_factory=dict)
    finished: list[str] = field(default_factory=list)
    counters: list[int] = field(default_factory=list)  # multi: instances, succeeded, failed, low, high
    grant: dict[str, str] = field(default_factory=dict)  # need -> resource id (of the needs it still held)
    released: list[str] = field(default_factory=list)  # needs it gave back early (`release(x)`)
    epochs: dict[str, int] = field(default_factory=dict)  # unit -> epoch
    children: list[NodeImage] = field(default_factory=list)
    component: list[Any] | None = None  # a running leaf's: [its component's snapshot] (plain data, or None)

    def to_dict(self) -> dict[str, Any]:
        d = {"path": self.path, "state": self.state, "phase": self.phase, "entered": self.entered,
             "data": self.data, "outputs": self.outputs, "finished": self.finished, "counters": self.counters,
             "grant": self.grant, "released": self.released, "epochs": self.epochs,
             "children": [c.to_dict() for c in self.children]}
        if self.component is not None:
            d["component"] = self.component
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> NodeImage:
        return cls(str(d["path"]), str(d["state"]), str(d["phase"]), float(d["entered"]), dict(d.get("data", {})),
                   dict(d.get("outputs", {})), [str(x) for x in d.get("finished", [])],
                   [int(x) for x in d.get("counters", [])], {str(k): str(v) for k, v in d.get("grant", {}).items()},
                   [str(x) for x in d.get("released", [])], {str(k): int(v) for k, v in d.get("epochs", {}).items()},
                   [cls.from_dict(c) for c in d.get("children", [])], _component(d.get("component")))

    def walk(self) -> list[NodeImage]:
        out, stack = [], [self]
        while stack:
            n = stack.pop()
            out.append(n)
            stack.extend(reversed(n.children))
        return out


def _component(value: Any) -> list[Any] | None:
    return [value[0] if isinstance(value[0], dict) else None] if isinstance(value, list) and value else None


def component_state(node: Node) -> list[Any] | None:
    """`[snapshot]` of a leaf's running component (`[None]`: it keeps none, its `snapshot` raised, or it is larger
    than `MAX_SNAPSHOT`), None for a node without one."""
    comp = node.component
    if comp is None or node.context is None:
        return None
    try:
        state = comp.snapshot()
        if state is None:
            return [None]
        plain = json.loads(json.dumps(dict(state), allow_nan=False))  # plain JSON, or it raises
    except Exception:  # component code is not ours to trust: it is restarted, and told so
        return [None]
    return [plain] if len(json.dumps(plain)) <= MAX_SNAPSHOT else [None]


def component_states(root: Node) -> dict[str, Any]:
    """The snapshots of the running components under `root`, by path (to tell whether they changed)."""
    out, stack = {}, [root]
    while stack:
        n = stack.pop()
        if n.phase is not DONE:
            state = component_state(n)
            if state is not None:
                out[n.path] = state[0]
            stack.extend(n.children)
    return out


def capture(root: Node) -> NodeImage:
    """The live tree under `root` (see the module)."""
    def image(n: Node) -> NodeImage:
        own = {name for name, _t in n.state.shared} | {v.name for v in n.state.vars}
        data = {k: encode(v) for k, v in n.scope.items() if k in own}
        counters = [n.instances, n.succeeded, n.failed, *n.bounds] if n.state.kind.value == "multi" else []
        gone = n.released
        grant = {k: v for k, v in (n.grant or {}).items() if k.partition(".")[0] not in gone}
        return NodeImage(n.path, n.state.id, n.phase.value, n.entered, data,
                         {k: encode(v) for k, v in n.outputs.items()}, sorted(n.finished), counters,
                         grant, sorted(gone), dict(n.epochs), [image(c) for c in n.children if c.phase is not DONE],
                         component_state(n))
    return image(root)


class Restore:
    """What entering a mission again follows (see the module): images by path, each used once."""

    def __init__(self, root: NodeImage, resource: Callable[[str], Any]) -> None:
        self.images = {n.path: n for n in root.walk()}
        self.resource = resource

    def __bool__(self) -> bool:
        return bool(self.images)

    def take(self, node: Node) -> NodeImage | None:
        """The image of `node` (by path and state), restored into it: entry time, data, outputs, counters."""
        image = self.images.get(node.path)
        if image is None or image.state != node.state.id:
            return None
        del self.images[node.path]
        node.entered = image.entered
        node.scope.update({k: decode(v, self.resource) for k, v in image.data.items()})
        node.outputs.update({k: decode(v, self.resource) for k, v in image.outputs.items()})
        node.finished.update(image.finished)
        node.released = frozenset(image.released)
        if len(image.counters) == 5:
            node.instances, node.succeeded, node.failed = image.counters[:3]
            node.bounds = (image.counters[3], image.counters[4])
        return image


    def forget(self, path: str) -> None:
        """`path` exits: the saved states inside it are not to be entered again."""
        for p in [p for p in self.images if p.startswith((path + "/", path + "["))]:
            del self.images[p]


def live_children(image: NodeImage) -> list[tuple[str, int | None]]:
    """(state id, multiplicity index or None) of the children an image had live, in order."""
    out: list[tuple[str, int | None]] = []
    for c in image.children:
        m = _INDEX.search(c.path)
        out.append((c.state, int(m.group(1)) if m else None))
    return out


def property_changes(resources: Iterable[Any], pool: Any) -> dict[str, dict[str, Any]]:
    """The Static Dependency Database's values (`pool.properties`) that differ from the resources' own (hosts.yaml):
    resource -> key -> value (a launched Scout's `carrier`), what a resumed mission must find again."""
    out: dict[str, dict[str, Any]] = {}
    for r in resources:
        now = pool.properties(r.id)
        diff = {k: v for k, v in now.items() if r.properties.get(k, _MISSING) != v}
        if diff:
            out[r.id] = diff
    return out


_MISSING = object()
