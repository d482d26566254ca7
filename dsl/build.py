"""From a checked program to the statechart: instantiate behaviors, bind resources, linearize plans.

The mission is expanded from its root: each child becomes a state whose id is its path
(`CorridorSurveillance/RoomSurveillance[*]/FindNewDoor/DetectDoor`). Resource needs are
bound here, where the exact ancestors are known (the reference, "Resources"): by name,
else by type if exactly one is in scope, else through a part of an aggregate the
manifest prefers (`camera: Camera of [Scout, Ranger]`), else (none preferred is held)
one robot of the team's own type with every such part, else the state asks the Resource
Controller Manager itself. Completion transitions the language implies (plan order, and
"a child with no way out makes its behavior done") are generated, marked `generated`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import PurePath

from dsl import ast
from dsl.catalog import Catalog, ComponentType, InputSpec, Kind, Limit
from dsl.checker import MAX_BEHAVIOR_DEPTH, Body, Checked
from dsl.dataflow import UNTYPED, Ambiguous, InputBinding, Level, Offer, Scope, bind, producer_order
from dsl.errors import NOWHERE, Reporter, Span
from dsl.exprtypes import constant
from dsl.linearize import find_cycle, plan_graph, predecessors, total_order
from dsl.statechart import ResourceNeed, State, Statechart, StateKind, Transition

#: The data in scope of a child, nearest level first (`dsl.dataflow`).
_Levels = tuple[Level, ...]


@dataclass(frozen=True, slots=True)
class _Held:
    """A resource in scope for binding: which state holds it, under which name and type."""

    state: str
    name: str
    type: str


#: How deep a broken program (`diagnose`) is expanded: the checker refuses deeper nesting anyway.
_MAX_DIAGNOSE_DEPTH = 2 * MAX_BEHAVIOR_DEPTH + 4


class Builder:
    """`diagnose`: the checker found errors; the statechart is built only for the binding errors it finds (all of a
    file's errors in one run): a behavior that is not sound (recursive) is not expanded, a cyclic plan not ordered,
    and an input that an unknown sibling might have fed is not reported missing. `open`: a library's behaviors,
    built with no ancestors: what an ancestor may provide (a shared datum, an input) is not reported missing."""

    def __init__(self, checked: Checked, catalog: Catalog, report: Reporter, diagnose: bool = False):
        self.checked = checked
        self.catalog = catalog
        self.report = report
        self.diagnose = diagnose
        self.open = False
        self.states: dict[str, State] = {}
        self._reported: set[tuple[str, Span]] = set()

    def build(self, mission: ast.Behavior, file: str) -> Statechart:
        root = ast.Child(mission.name, span=mission.name_span)
        self._instance(mission.name, mission.name, root, None, 0, 1, (), ())
        self._nested_instances(mission.name)
        return Statechart(mission.name, mission.name, dict(self.states), file, mission.priority or 1,
                          self.report.limits.instances)

    def _nested_instances(self, root: str) -> None:
        """Refuse constant multiplicities whose instances multiply past the limit: `Outer[1000] { Inner[1000] }` is a
        million live instances, each multiplicity within the limit alone (semantics audit 18, #2). Counted as the
        runtime counts them, every level's instances (`Outer[40] { Inner[25] }` is 40 + 1,000); the runtime also
        bounds what evaluated counts and sibling multiplicities add up to."""
        limit = self.report.limits.instances
        stack = [(root, 1, 0, "")]
        while stack:
            sid, factor, total, outer = stack.pop()
            state = self.states[sid]
            m = state.multiplicity
            count = constant(m.high if m.high is not None else m.low) if m is not None else None
            if m is not None and count is not None and 0 < count <= limit:
                factor, inner = factor * int(count), f"{state.name}[{int(count)}]"
                total += factor
                if total > limit and outer:
                    if ("multiplicity", m.span) not in self._reported:
                        self._reported.add(("multiplicity", m.span))
                        self.report.error(
                            "multiplicity", f"{inner} inside {outer} makes {total:,} instances alive at once, above "
                            f"the limit of {limit:,} in a mission", m.span, "nested multiplicities multiply: an "
                            "instance per robot or task at one level, or raise the limit (hosts.yaml "
                            "cluster.limits.instances)")
                    continue
                outer = f"{inner} inside {outer}" if outer else inner
            stack.extend((child, factor, total, outer) for child in reversed(state.children))

    def build_library(self) -> None:
        """Build each behavior no other one uses as if a mission that holds nothing ran it: its binding errors
        that hold wherever it is used (two cameras of its own for one `camera`) are reported in the library."""
        self.open = True
        for name, behavior in self.checked.behaviors.items():
            if name not in self.checked.called and name in self.checked.sound:
                self._instance(name, name, ast.Child(name, span=behavior.name_span), None, 0, 1, (), ())

    def _expands(self, behavior: ast.Behavior | None, depth: int) -> bool:
        return behavior is not None and (not self.diagnose or (
            behavior.name in self.checked.sound and depth <= _MAX_DIAGNOSE_DEPTH))

    # ------------------------------------------------------------- states
    def _child(self, parent: str, child: ast.Child, depth: int, prio: int, held: tuple[_Held, ...],
               data: _Levels) -> str:
        sid = f"{parent}/{child.key}"
        behavior = self.checked.behaviors.get(child.name)
        eff = child.priority or (behavior.priority if behavior else None) or prio
        if child.mult is None:
            self._instance(sid, child.key, child, parent, depth, eff, held, data)
            return sid
        self.states[sid] = State(sid, child.key, StateKind.MULTI, parent, depth, (sid + "[*]",),
                                 component=child.name, priority=eff, multiplicity=child.mult, span=child.span)
        self._instance(sid + "[*]", child.key + "[*]", child, sid, depth + 1, eff, held, data)
        return sid

    def _instance(self, sid: str, name: str, child: ast.Child, parent: str | None, depth: int, prio: int,
                  held: tuple[_Held, ...], data: _Levels) -> None:
        if not len(self.states) % 256:
            self.report.check_budget(child.span)
        behavior = self.checked.behaviors.get(child.name)
        args = child.args or ()
        if not self._expands(behavior, depth):
            ct = self.catalog.get(child.name) if behavior is None else None
            defaults = tuple(ast.Arg(p.name, _literal(p.default, p.type)) for p in (ct.params if ct else ())
                             if not p.required)
            inputs = self._inputs(child, ct, data) if ct is not None else ()
            bound = {i.name for i in ct.inputs} if ct is not None else set()
            self.states[sid] = State(sid, name, StateKind.LEAF, parent, depth, component=child.name,
                                     args=tuple(a for a in args if a.name not in bound), defaults=defaults,
                                     needs=self._leaf_needs(child, held), priority=prio, inputs=inputs,
                                     ranges=_evaluated_ranges(ct, args), span=child.span)
            return
        assert behavior is not None
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
        offers = [o for key, c in body.children.items() if c.mult is None
                  for o in self._offers(f"{sid}/{key}", key, c.name, ())]
        offers += [Offer(sid, s.name, s.type.name, True) for s in body.shared]
        scope = Scope(offers, self.diagnose and self._opaque(body))
        kids = {key: self._child(sid, c, depth + 1, prio, inner, (Level(scope, key), *data))
                for key, c in body.children.items()}
        self.states[sid] = self._body(self.states[sid], body, kids)

    def _opaque(self, body: Body) -> bool:
        """Whether a child or shared datum of `body` is unknown (then what it would offer is unknown)."""
        return any(c.name not in self.checked.sound and (c.name in self.checked.behaviors or
                                                          self.catalog.get(c.name) is None)
                   for c in body.children.values()) or any(self.catalog.get(s.type.name) is None for s in body.shared)

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
        waiting = self._waiting_start(state, body, written, target)
        kind, initial, policy, until = StateKind.COMPOUND, None, None, None
        generated: list[Transition] = []
        entry: tuple[str, ...] = ()
        if body.parallel is not None and kids:  # with no child, a sequence's empty body: done at once
            kind, policy = StateKind.PARALLEL, body.parallel.policy
            until = kids[body.parallel.until] if body.parallel.until in kids else None
            entry = self._producers_first(list(kids.values()), body.parallel.span)
        elif body.plan is not None and body.plan.concurrent and kids:
            kind, policy = StateKind.PARALLEL, ast.Policy.ALL
            for step, preds in predecessors(plan_graph(body.plan)).items():
                s = self.states[kids[step]]
                self.states[s.id] = replace(s, after=tuple(kids[p] for p in preds))
        else:
            graph = plan_graph(body.plan) if body.plan is not None else None
            order = total_order(graph) if graph is not None and find_cycle(graph) is None else []
            ahead = body.plan is not None and body.plan.preallocate
            steps = {st.name: st.span for chain in body.plan.chains for st in chain} if body.plan is not None else {}
            for a, b in zip(order, order[1:], strict=False):  # located at the step it leads to, in the plan
                generated.append(_completion(sid, kids[a], kids[b], ahead, steps.get(b, NOWHERE)))
            # an empty body is done at once (spec: a behavior whose children have all finished is done)
            initial = kids[order[0]] if order else (starts[0].target if starts else next(iter(kids.values()),
                                                                                          final("done")))
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
        children = tuple(kids.values()) + waiting + tuple(finals.values())
        plain = len(starts) == 1 and not (starts[0].guard or starts[0].actions or waiting)  # `initial` says it all
        return replace(self.states[sid], kind=kind, children=children, initial=initial, policy=policy,
                       until=until, starts=() if plain else starts, entry=entry)

    def _waiting_start(self, state: State, body: Body, written: list[Transition],
                       target: Callable[[str], str]) -> tuple[str, ...]:
        """The `start` state of a behavior with a `start -> X when/after/on ...`: when no start transition is
        enabled on entry, the behavior waits there (no child runs) until one of those fires. Its transitions are
        those start transitions, so timeouts, changes and events work as from any state (appended to `written`)."""
        triggered = [t for t in body.transitions if t.source == "start" and t.kind is not ast.TriggerKind.COMPLETION]
        if not triggered or body.parallel is not None or body.plan is not None:
            return ()
        wid = f"{state.id}/start"
        self.states[wid] = State(wid, "start", StateKind.COMPOUND, state.id, state.depth + 1,
                                 priority=state.priority, span=triggered[0].source_span)
        written.extend(self._transition(t, state.id, wid, target(t.target)) for t in triggered)
        return (wid,)

    @staticmethod
    def _transition(t: ast.Transition, domain: str, source: str, target: str) -> Transition:
        delay = t.delay.seconds if isinstance(t.delay, ast.Duration) else t.delay
        return Transition(source, target, domain, t.kind, t.event, t.condition, delay, t.guard, t.actions,
                          preallocate=t.preallocate, sender=t.sender, span=t.span)

    # ------------------------------------------------------------- data flow
    def _offers(self, state: str, key: str, callee: str, seen: tuple[str, ...]) -> list[Offer]:
        """What a child produces: a component's outputs, or those of every child of a behavior, all the way down
        (a composite's outputs are its finished children's: FindNewDoor's `door` is DetectDoor's)."""
        behavior = self.checked.behaviors.get(callee)
        if behavior is None:
            ct = self.catalog.get(callee)
            return [Offer(state, o.name, o.type, False, key) for o in (ct.outputs if ct else ())]
        if callee in seen:
            return []
        body = self.checked.bodies[behavior.name]
        return [o for c in body.children.values() if c.mult is None
                for o in self._offers(state, key, c.name, (*seen, callee))]

    def _inputs(self, child: ast.Child, ct: ComponentType, data: _Levels) -> tuple[InputBinding, ...]:
        given = {a.name: a for a in child.args or ()}
        out = []
        for spec in ct.inputs:
            arg = given.get(spec.name)
            if arg is not None:
                binding = self._explicit(child, spec, arg, data)
                if binding is not None:
                    out.append(binding)
                continue
            found = bind(spec, data)
            if isinstance(found, Offer):
                out.append(InputBinding(spec.name, found.state, found.name, found.shared))
            elif isinstance(found, Ambiguous):
                names = " or ".join(o.describe() for o in found.offers)
                self._error("ambiguous-input", f"{child.name}'s input {spec.name} ({spec.type}) could read {names}",
                            child.span, f"bind it: {child.name}({spec.name}: {_reference(found.offers[0])})")
            elif not spec.optional and not self.open and not any(level.scope.opaque for level in data):
                self._error("missing-input", f"{child.name} needs input {spec.name} ({spec.type}): nothing in scope"
                            f" is called {spec.name} or is a {spec.type}", child.span,
                            f"run a behavior that outputs a {spec.type} before it, declare `shared {spec.name}:"
                            f" {spec.type}` in an enclosing behavior, or bind it: {child.name}({spec.name}: ...)")
        return tuple(out)

    def _explicit(self, child: ast.Child, spec: InputSpec, arg: ast.Arg, data: _Levels) -> InputBinding | None:
        """`X(door: finder.door)`, `X(visited: doors)`, `X(door: last(finder.door))`."""
        value, last = arg.value, False
        if isinstance(value, ast.Call) and value.func == "last" and len(value.args) == 1 and value.where is None:
            value, last = value.args[0], True
        offer: Offer | None
        if isinstance(value, ast.Attr) and isinstance(value.obj, ast.Name):
            key, field = value.obj.id, value.attr
            # the nearest level where `key` is a sibling: the behavior's own, or an enclosing behavior's, as a
            # binding by name or type searches (the ambiguous-input hint names those: users audit 12, D3)
            near = next((level for level in data if level.outputs_of(key)), data[0] if data else Level(Scope(())))
            hits = [o for o in near.outputs_of(key) if o.name == field]
            if not hits:
                outputs = sorted({o.name for o in near.outputs_of(key)})
                keys = sorted({o.key for level in data for o in level if not o.shared})
                self._error("unknown-input-source", f"{key}.{field} is not an output of a sibling of {child.name}"
                            " or of an enclosing behavior", arg.span, f"{key}'s outputs: {', '.join(outputs)}"
                            if outputs else f"siblings with outputs: {', '.join(keys)}" if keys else
                            "no sibling in scope has outputs")
                return None
            offer = hits[0]
        elif isinstance(value, ast.Name):
            offer = next((o for level in data for o in level.named(value.id) if o.shared), None)
            if offer is None and (self.open or any(level.scope.opaque for level in data)):
                return None  # an ancestor's (or an unknown sibling's) datum, perhaps
            if offer is None:
                self._error("unknown-input-source", f"{value.id} is no shared datum in scope of {child.name}",
                            arg.span, "an input reads a sibling's output (sibling.output) or a `shared` datum")
                return None
        else:
            self._error("input-binding", f"input {spec.name} of {child.name} reads a sibling's output"
                        " (sibling.output) or a shared datum (its name), not an expression", arg.span,
                        f"e.g. {child.name}({spec.name}: finder.{spec.name})")
            return None
        if offer.type not in (spec.type, UNTYPED):
            self._error("type", f"{child.name}'s input {spec.name} is a {spec.type}; {_reference(offer)} is a"
                        f" {offer.type}", arg.span)
            return None
        return InputBinding(spec.name, offer.state, offer.name, offer.shared, last)

    def _producers_first(self, kids: list[str], span: Span) -> tuple[str, ...]:
        """Concurrent children, each producer before those that read its outputs this cycle; a cycle of such reads
        is an error (one of them must read `last(...)`)."""
        feeds = []
        for consumer in kids:
            for leaf in self._leaves_under(consumer):
                for b in self.states[leaf].inputs:
                    if not b.shared and not b.last and b.state in kids:
                        feeds.append((b.state, consumer))
        if not feeds:
            return ()
        order = producer_order(kids, feeds)
        if order[-1] is None:
            cycle = " -> ".join(self.states[s].name for s in order if s is not None)
            self._error("input-cycle", f"concurrent behaviors feed each other every cycle: {cycle}", span,
                        "read one of these inputs as last(sibling.output): the previous cycle's value")
            return ()
        return tuple(s for s in order if s is not None)

    def _leaves_under(self, sid: str) -> Iterator[str]:
        state = self.states.get(sid)
        if state is None:
            return
        if state.kind is StateKind.LEAF:
            yield sid
        for c in state.children:
            yield from self._leaves_under(c)

    def _error(self, code: str, message: str, span: Span, hint: str | None = None) -> None:
        if (message, span) in self._reported:  # a behavior used twice is built twice
            return
        self._reported.add((message, span))
        self.report.error(code, message, span, hint)

    # ------------------------------------------------------------- resources
    def _need(self, n: ast.Need, held: tuple[_Held, ...]) -> ResourceNeed:
        # A `where` selects a particular resource: a same-named or same-typed one is reused (the `where` must hold of
        # it), a part of an ancestor's robot only when the `where` holds of it on entry (`reuse`), else the manager
        # is asked: a behavior may want another robot's camera than the one its mission's Ranger carries.
        bound = self._bind(n.name, n.type.name, (), held, n.span, parts=n.where is None)
        reuse = self._part_in_scope(n.name, n.type.name, held) if n.where is not None and bound is None else ()
        return ResourceNeed(n.name, n.type.name, n.where, n.quantity, n.slice.seconds if n.slice else None,
                            bound, span=n.span, reuse=reuse)

    def _part_in_scope(self, name: str, typ: str, held: tuple[_Held, ...]) -> tuple[tuple[str, str, str], ...]:
        """The parts of type `typ` of the ancestors' robots (a same-named one first), nearest first."""
        hits = sorted(_distinct(list(held)), key=lambda h: h.name != name)
        return tuple((h.state, h.name, part) for h in hits if (part := self.catalog.part_of(h.type, typ)))

    def _leaf_needs(self, child: ast.Child, held: tuple[_Held, ...]) -> tuple[ResourceNeed, ...]:
        ct = self.catalog.get(child.name)
        if ct is None or ct.kind is not Kind.BEHAVIOR:
            return ()
        bound = [self._bind(spec.name, spec.type, spec.of, held, child.span, parts=True) for spec in ct.needs]
        if not any(b is not None for b, spec in zip(bound, ct.needs, strict=True) if spec.of):
            served = self._team_robot(ct, bound, held, child.span)
            if served is not bound:  # under a team's own robot: so are the robots it acts on (users audit 17, D1)
                bound = self._team_carried(ct, served, held, child.span)
        else:
            bound = self._same_robot(ct, bound, held)
        self._property_params(ct, child, bound, held)
        return tuple(ResourceNeed(spec.name, spec.type, None, spec.quantity, None, b, span=child.span)
                     for spec, b in zip(ct.needs, bound, strict=True))

    def _property_params(self, ct: ComponentType, child: ast.Child,
                         bound: list[tuple[str, str, str | None] | None], held: tuple[_Held, ...]) -> None:
        """Each `str` parameter naming a property of the robot a need is bound to (`property_of` in the manifest):
        the robot's type (a subtype's, or one it extends) must have it. LaunchScout's `carrier_property` left at
        `carrier` for a team's Probe naming its carrier `dock` cleared nothing, and the next `where probe.dock ==
        hauler` picked the thrown Probe again (users audit 18, #2)."""
        for p in ct.params:
            if p.property_of is None:
                continue
            arg = next((a for a in child.args or () if a.name == p.name), None)
            value = arg.value.value if arg is not None and isinstance(arg.value, ast.Literal) else (
                p.default if arg is None else None)
            index = next((i for i, n in enumerate(ct.needs) if n.name == p.property_of), None)
            if not isinstance(value, str) or index is None:
                continue  # an expression is evaluated on entry; a manifest naming no need was refused at load
            b, spec = bound[index], ct.needs[index]
            robot = next((h.type for h in held if b is not None and b[2] is None and (h.state, h.name) == b[:2]),
                         spec.type if b is None else None)
            if robot is None:
                continue
            kinds = {*self.catalog.subtypes(robot), *self.catalog.supertypes(robot)}
            has = sorted({k for t in kinds for k in getattr(self.catalog.get(t), "properties", {})})
            if value not in has:
                self._error("parameter", f"{ct.name}'s {p.name} {value!r} is not a property of {robot}, whose "
                            f"{spec.name} it names" + (f" (it has {', '.join(has)})" if has else ""),
                            arg.span if arg is not None else child.span,
                            f"pass {p.name}: \"...\" naming the property of {robot} it means")

    def _same_robot(self, ct: ComponentType, bound: list[tuple[str, str, str | None] | None],
                    held: tuple[_Held, ...]) -> list[tuple[str, str, str | None] | None]:
        """`ct`'s needs that name the robots they prefer (`of`) and that nothing bound, while its others are bound
        to one robot: served by that robot's parts where it has them, so one behavior's drive and sensors stay on one
        robot. A Watch given a team's Probe by name for its `drive` (the ambiguity error's own hint) watched through
        another Probe's camera, asked of the manager (users audit 18, #1)."""
        robots = {(b[0], b[1]) for b, spec in zip(bound, ct.needs, strict=True) if b is not None and spec.of}
        if len(robots) != 1 or all(b is not None for b in bound):
            return bound
        (state, name), = robots
        robot = next(h for h in held if (h.state, h.name) == (state, name))
        return [(state, name, part) if b is None and spec.of and (part := self.catalog.part_of(robot.type, spec.type))
                else b for spec, b in zip(ct.needs, bound, strict=True)]

    def _team_robot(self, ct: ComponentType, bound: list[tuple[str, str, str | None] | None],
                    held: tuple[_Held, ...], span: Span) -> list[tuple[str, str, str | None] | None]:
        """`ct`'s needs that name the robots they prefer (`of`), none of which is held: all served by one robot of
        a type its manifest's folder does not define (a team's own `Crawler` under a standard behavior), the one
        the nearest ancestor holds that has a part for every such need, rather than each asked of the manager,
        which granted another robot's (users audit 15, D1: FollowCorridor drove the Hauler on another host).
        A type the manifest's folder defines and `of` leaves out (a Scout under a Ranger-only behavior) is left
        out on purpose; a robot lacking one of the parts (a laser) serves none, so one behavior's drive and
        sensors stay on one robot; two such robots held by that ancestor are ambiguous."""
        wanted = [spec for spec in ct.needs if spec.of]
        if not wanted:
            return bound
        home = _folder(ct.source)
        fits = _distinct([h for h in held if _folder(getattr(self.catalog.get(h.type), "source", "")) != home
                          and all(self.catalog.part_of(h.type, spec.type) for spec in wanted)])
        nearest = [h for h in fits if h.state == fits[0].state]
        if len(nearest) > 1:
            self._ambiguous(wanted[0].name, wanted[0].type, nearest, span)
        if len(nearest) != 1:
            return bound
        robot = nearest[0]
        return [(robot.state, robot.name, self.catalog.part_of(robot.type, spec.type)) if spec.of else b
                for spec, b in zip(ct.needs, bound, strict=True)]

    def _team_carried(self, ct: ComponentType, bound: list[tuple[str, str, str | None] | None],
                      held: tuple[_Held, ...], span: Span) -> list[tuple[str, str, str | None] | None]:
        """Under a team's own robot (`_team_robot` served `ct`'s parts from it), `ct`'s needs of a robot type its
        manifest's folder defines that nothing held serves (LaunchScout's `scout: Scout` under a Crawler carrying
        Beacons): each served by the robot of a team's own type that the nearest ancestor holds and that no other
        need of `ct` uses, rather than asked of the manager for a type the team has none of (users audit 17, D1);
        two such robots held there are ambiguous."""
        home = _folder(ct.source)
        used = {(b[0], b[1]) for b in bound if b is not None}
        carriers = {h.type for h in held if (h.state, h.name) in used}  # the team's robot serving the parts
        out = list(bound)
        for i, (spec, b) in enumerate(zip(ct.needs, bound, strict=True)):
            need_type = self.catalog.get(spec.type)
            if b is not None or spec.of or need_type is None or need_type.kind is not Kind.ARC or (
                    _folder(need_type.source) != home):
                continue
            # a robot of a team's own type that names such a carrier in a property (a Beacon's `mothership:
            # Crawler`), as the standard `Scout` names its `carrier: Ranger`; the one named as the need first
            fits = _distinct([h for h in held if (h.state, h.name) not in used and self._team_arc(h.type, home)
                              and self._carried_by(h.type, carriers)])
            nearest = [h for h in fits if h.state == fits[0].state]
            nearest = [h for h in nearest if h.name == spec.name] or nearest
            if len(nearest) > 1:
                self._ambiguous(spec.name, spec.type, nearest, span)
            elif nearest:
                out[i] = (nearest[0].state, nearest[0].name, None)
                used.add((nearest[0].state, nearest[0].name))
        return out

    def _carried_by(self, name: str, carriers: set[str]) -> bool:
        """Whether robot type `name` has a property typed with one of `carriers` (or a type they extend)."""
        kinds = {k for c in carriers for k in (c, *self.catalog.supertypes(c))}
        return any(t in kinds for t in self.catalog.properties(name).values())

    def _team_arc(self, name: str, home: str) -> bool:
        """Whether `name` is a robot type (an arc) of a folder other than `home`: a team's own."""
        t = self.catalog.get(name)
        return t is not None and t.kind is Kind.ARC and _folder(t.source) != home

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


def _reference(offer: Offer) -> str:
    """How a mission names a datum in an explicit binding."""
    return offer.name if offer.shared else f"{offer.key}.{offer.name}"


def _literal(value: object, type_name: str) -> ast.Expr:
    """A manifest default (a Python value) as a constant expression."""
    if type_name == "duration" and isinstance(value, int | float):
        return ast.Duration(float(value), f"{value:g}s")
    assert isinstance(value, bool | int | float | str), value
    return ast.Literal(value)


def _completion(domain: str, source: str, target: str, preallocate: bool = False, span: Span = NOWHERE) -> Transition:
    return Transition(source, target, domain, ast.TriggerKind.COMPLETION, generated=True, preallocate=preallocate,
                      span=span)


def _folder(source: str) -> str:
    """The components folder a manifest (`DIR/Name/manifest.yaml`) comes from."""
    return str(PurePath(source).parent.parent) if source else ""


def _distinct(hits: list[_Held]) -> list[_Held]:
    """Several ancestors may hold the same name: the nearest one hides the others."""
    seen: dict[str, _Held] = {}
    for h in hits:
        seen.setdefault(h.name, h)
    return list(seen.values())


def _evaluated_ranges(ct: ComponentType | None, args: tuple[ast.Arg, ...]) -> tuple[tuple[str, Limit], ...]:
    """The ranges of the parameters given as expressions (`speed: s * 2`): checked on entry, when they have a
    value; a constant was checked by the compiler, where it is written."""
    if ct is None:
        return ()
    given = {a.name: a.value for a in args}
    return tuple((p.name, p.limit) for p in ct.params
                 if p.limit is not None and p.name in given and constant(given[p.name]) is None)
