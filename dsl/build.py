"""From a checked program to the statechart: instantiate behaviors, bind resources, linearize plans.

The mission is expanded from its root: each child becomes a state whose id is its path
(`CorridorSurveillance/RoomSurveillance[*]/FindNewDoor/DetectDoor`). Resource needs are
bound here, where the exact ancestors are known (the reference, "Resources"): by name,
else by type if exactly one is in scope, else through a part of an aggregate the
manifest prefers (`camera: Camera of [Scout, Ranger]`), else the state asks the Resource
Controller Manager itself. Completion transitions the language implies (plan order, and
"a child with no way out makes its behavior done") are generated, marked `generated`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from dsl import ast
from dsl.catalog import Catalog, Kind
from dsl.checker import Body, Checked
from dsl.errors import NOWHERE, Reporter, Span
from dsl.linearize import plan_graph, predecessors, total_order
from dsl.statechart import ResourceNeed, State, Statechart, StateKind, Transition


@dataclass(frozen=True, slots=True)
class _Held:
    """A resource in scope for binding: which state holds it, under which name and type."""

    state: str
    name: str
    type: str


class Builder:
    def __init__(self, checked: Checked, catalog: Catalog, report: Reporter):
        self.checked = checked
        self.catalog = catalog
        self.report = report
        self.states: dict[str, State] = {}
        self._reported: set[tuple[str, Span]] = set()

    def build(self, mission: ast.Behavior, file: str) -> Statechart:
        root = ast.Child(mission.name, span=mission.name_span)
        self._instance(mission.name, mission.name, root, None, 0, 1, ())
        return Statechart(mission.name, mission.name, dict(self.states), file, mission.priority or 1)

    # ------------------------------------------------------------- states
    def _child(self, parent: str, child: ast.Child, depth: int, prio: int, held: tuple[_Held, ...]) -> str:
        sid = f"{parent}/{child.key}"
        behavior = self.checked.behaviors.get(child.name)
        eff = child.priority or (behavior.priority if behavior else None) or prio
        if child.mult is None:
            self._instance(sid, child.key, child, parent, depth, eff, held)
            return sid
        self.states[sid] = State(sid, child.key, StateKind.MULTI, parent, depth, (sid + "[*]",),
                                 component=child.name, priority=eff, multiplicity=child.mult, span=child.span)
        self._instance(sid + "[*]", child.key + "[*]", child, sid, depth + 1, eff, held)
        return sid

    def _instance(self, sid: str, name: str, child: ast.Child, parent: str | None, depth: int, prio: int,
                  held: tuple[_Held, ...]) -> None:
        behavior = self.checked.behaviors.get(child.name)
        args = child.args or ()
        if behavior is None:
            ct = self.catalog.get(child.name)
            defaults = tuple(ast.Arg(p.name, _literal(p.default, p.type)) for p in (ct.params if ct else ())
                             if not p.required)
            self.states[sid] = State(sid, name, StateKind.LEAF, parent, depth, component=child.name, args=args,
                                     defaults=defaults, needs=self._leaf_needs(child, held), priority=prio,
                                     span=child.span)
            return
        body = self.checked.bodies[behavior.name]
        needs = tuple(self._need(n, held) for n in body.needs)
        defaults = tuple(ast.Arg(p.name, p.default, span=p.span) for p in behavior.params if p.default is not None)
        self.states[sid] = State(sid, name, StateKind.COMPOUND, parent, depth, component=behavior.name, args=args,
                                 defaults=defaults, needs=needs,
                                 shared=tuple((s.name, s.type.name) for s in body.shared),
                                 vars=tuple(body.vars), priority=prio, constraints=tuple(body.constraints),
                                 span=child.span)
        # A need bound to an ancestor's resource is that resource under a new name: it hides the old entry.
        hidden = {(n.bound_to[0], n.bound_to[1]) for n in needs if n.bound_to and n.bound_to[2] is None}
        inner = tuple(_Held(sid, n.name, n.type.name) for n in body.needs) + tuple(
            h for h in held if (h.state, h.name) not in hidden)
        kids = {key: self._child(sid, c, depth + 1, prio, inner) for key, c in body.children.items()}
        self.states[sid] = self._body(self.states[sid], body, kids)

    def _body(self, state: State, body: Body, kids: dict[str, str]) -> State:
        """Fill in kind, initial state, policy and transitions from the body's structure."""
        finals: dict[str, str] = {}
        sid = state.id

        def final(which: str) -> str:
            if which not in finals:
                fid = f"{sid}/{which}"
                self.states[fid] = State(fid, which, StateKind.FINAL, sid, state.depth + 1,
                                         priority=state.priority, success=which == "done", span=state.span)
                finals[which] = fid
            return finals[which]

        def target(name: str) -> str:
            return final(name) if name in ("done", "fail") else kids[name]

        written = [self._transition(t, sid, kids[t.source], target(t.target))
                   for t in body.transitions if t.source != "start"]
        starts = tuple(self._transition(t, sid, sid, target(t.target))
                       for t in body.transitions if t.source == "start")
        kind, initial, policy, until = StateKind.COMPOUND, None, None, None
        generated: list[Transition] = []
        if body.parallel is not None:
            kind, policy = StateKind.PARALLEL, body.parallel.policy
            until = kids[body.parallel.until] if body.parallel.until in kids else None
        elif body.plan is not None and body.plan.concurrent:
            kind, policy = StateKind.PARALLEL, ast.Policy.ALL
            for step, preds in predecessors(plan_graph(body.plan)).items():
                s = self.states[kids[step]]
                self.states[s.id] = replace(s, after=tuple(kids[p] for p in preds))
        else:
            order = total_order(plan_graph(body.plan)) if body.plan is not None else []
            ahead = body.plan is not None and body.plan.preallocate
            for a, b in zip(order, order[1:], strict=False):
                generated.append(_completion(sid, kids[a], kids[b], ahead))
            initial = kids[order[0]] if order else (starts[0].target if starts else next(iter(kids.values()), None))
            leads_on = {t.source for t in written + generated if t.kind is ast.TriggerKind.COMPLETION
                        and t.guard is None}
            generated.extend(_completion(sid, k, final("done")) for k in kids.values() if k not in leads_on)
        by_source: dict[str, list[Transition]] = {}
        for t in written + generated:
            by_source.setdefault(t.source, []).append(t)
        for src, ts in by_source.items():
            self.states[src] = replace(self.states[src], transitions=tuple(ts))
        for t in written + generated:
            if t.preallocate and not any(n.requested for n in self.states[t.target].needs):
                self.report.warning("preallocate", f"{self.states[t.target].name} asks for no resource of its own"
                                    " (its needs are its ancestors'): there is nothing to preallocate",
                                    t.span if t.span is not NOWHERE else state.span)
        children = tuple(kids.values()) + tuple(finals.values())
        return replace(self.states[sid], kind=kind, children=children, initial=initial, policy=policy,
                       until=until, starts=starts if len(starts) > 1 or any(t.guard for t in starts) else ())

    @staticmethod
    def _transition(t: ast.Transition, domain: str, source: str, target: str) -> Transition:
        delay = t.delay.seconds if isinstance(t.delay, ast.Duration) else t.delay
        return Transition(source, target, domain, t.kind, t.event, t.condition, delay, t.guard, t.actions,
                          preallocate=t.preallocate, span=t.span)

    # ------------------------------------------------------------- resources
    def _need(self, n: ast.Need, held: tuple[_Held, ...]) -> ResourceNeed:
        # A `where` selects a particular resource: then only a same-named or same-typed one is reused.
        bound = self._bind(n.name, n.type.name, (), held, n.span, parts=n.where is None)
        return ResourceNeed(n.name, n.type.name, n.where, n.quantity, n.slice.seconds if n.slice else None,
                            bound, span=n.span)

    def _leaf_needs(self, child: ast.Child, held: tuple[_Held, ...]) -> tuple[ResourceNeed, ...]:
        ct = self.catalog.get(child.name)
        if ct is None or ct.kind is not Kind.BEHAVIOR:
            return ()
        return tuple(ResourceNeed(spec.name, spec.type, None, spec.quantity, None,
                                  self._bind(spec.name, spec.type, spec.of, held, child.span, parts=True),
                                  span=child.span)
                     for spec in ct.needs)

    def _bind(self, name: str, typ: str, of: tuple[str, ...], held: tuple[_Held, ...], span: Span,
              parts: bool) -> tuple[str, str, str | None] | None:
        for h in held:  # by name, nearest ancestor first
            if h.name == name:
                if h.type == typ:
                    return h.state, h.name, None
                part = self.catalog.part_of(h.type, typ)
                if parts and part:
                    return h.state, h.name, part
        direct = _distinct([h for h in held if h.type == typ])
        if len(direct) == 1:
            return direct[0].state, direct[0].name, None
        if len(direct) > 1:
            self._ambiguous(name, typ, direct, span)
            return None
        if not parts:
            return None
        arcs = of or tuple(n for n in self.catalog.names(Kind.ARC) if self.catalog.part_of(n, typ))
        for arc in arcs:
            hits = _distinct([h for h in held if h.type == arc])
            if len(hits) == 1:
                part = self.catalog.part_of(arc, typ)
                return (hits[0].state, hits[0].name, part) if part else None
            if len(hits) > 1:
                self._ambiguous(name, typ, hits, span)
                return None
        return None

    def _ambiguous(self, name: str, typ: str, hits: list[_Held], span: Span) -> None:
        names = " or ".join(h.name for h in hits)
        msg = f"ambiguous resource binding: {name} ({typ}) could come from {names}"
        if (msg, span) in self._reported:
            return
        self._reported.add((msg, span))
        self.report.error("ambiguous-binding", msg, span,
                          f"name one of them {name} so it is chosen by name, or keep one {typ} in scope")


def _literal(value: object, type_name: str) -> ast.Expr:
    """A manifest default (a Python value) as a constant expression."""
    if type_name == "duration" and isinstance(value, int | float):
        return ast.Duration(float(value), f"{value:g}s")
    assert isinstance(value, bool | int | float | str), value
    return ast.Literal(value)


def _completion(domain: str, source: str, target: str, preallocate: bool = False) -> Transition:
    return Transition(source, target, domain, ast.TriggerKind.COMPLETION, generated=True, preallocate=preallocate)


def _distinct(hits: list[_Held]) -> list[_Held]:
    """Several ancestors may hold the same name: the nearest one hides the others."""
    seen: dict[str, _Held] = {}
    for h in hits:
        seen.setdefault(h.name, h)
    return list(seen.values())
