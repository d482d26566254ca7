"""Semantic checks: everything the reference's Errors section names, all reported in one run.

The checker works per behavior, out of context: what a behavior may see of its ancestors
(shared data and resources) is computed once over the call graph as the names visible in
*every* context that instantiates it, so a check that passes holds wherever the behavior
is used. Resource bindings, which depend on the exact ancestors, are checked while the
statechart is built (`dsl.build`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

import networkx as nx

from dsl import ast
from dsl.catalog import SCALAR_TYPES, Catalog, ComponentType, Kind, ParamSpec, RecordSpec, possessive
from dsl.errors import NOWHERE, Reporter, Span, did_you_mean
from dsl.exprtypes import ANY, Scope, Type, Typer, assignable, constant, show
from dsl.limits import DEFAULT_INSTANCES
from dsl.linearize import find_cycle, plan_graph
from dsl.param_values import out_of_bounds

#: Deeper chains of behaviors calling behaviors are rejected (they only come from generators).
MAX_BEHAVIOR_DEPTH = 64
#: The parameter types a manifest may give a range (`min`, `max`, `unit`).
NUMERIC = ("int", "float", "duration")
#: A var's type and its zero, as a `declare it: var x: T = ZERO` hint writes them.
ZEROS = {"int": "0", "float": "0.0", "bool": "false", "str": '""', "duration": "0s"}
#: The default most instances a multiplicity may create (written as a constant, or evaluated when it starts): each is
#: a statechart and components; a mission of more is a mistake or an attack (`Wait[1000000000]`). A cluster may
#: raise it (`dsl.limits`, hosts.yaml `cluster.limits.instances`).
MAX_INSTANCES = DEFAULT_INSTANCES


#: The runtime's control cycle (seconds), which a time slice must outlast: a holder is resumed at one cycle and
#: preempted at the next, so a shorter slice never lets it run (users audit 9, D3: `for 100ms` starved both).
CONTROL_CYCLE = 0.1
MIN_SLICE = 2 * CONTROL_CYCLE


@dataclass
class Program:
    """A mission file and its imports, parsed."""

    main: str
    files: dict[str, ast.MissionFile]
    sources: dict[str, str]

    @property
    def mission(self) -> ast.Behavior | None:
        f = self.files.get(self.main)
        return f.mission if f else None

    def behaviors(self) -> Iterable[ast.Behavior]:
        for f in self.files.values():
            yield from f.behaviors


@dataclass
class Body:
    """A behavior body sorted by kind of item. `children` holds declared and implicit ones."""

    needs: list[ast.Need] = field(default_factory=list)
    shared: list[ast.Shared] = field(default_factory=list)
    vars: list[ast.Var] = field(default_factory=list)
    children: dict[str, ast.Child] = field(default_factory=dict)
    declared: list[ast.Child] = field(default_factory=list)
    parallels: list[ast.Parallel] = field(default_factory=list)
    plans: list[ast.Plan] = field(default_factory=list)
    transitions: list[ast.Transition] = field(default_factory=list)
    constraints: list[ast.Constraint] = field(default_factory=list)
    implicit: set[str] = field(default_factory=set)  # named only in transitions or plans

    @property
    def parallel(self) -> ast.Parallel | None:
        return self.parallels[0] if self.parallels else None

    @property
    def plan(self) -> ast.Plan | None:
        return self.plans[0] if self.plans else None


def summarize(b: ast.Behavior) -> Body:
    """Sort a body's items; names used only in transitions or plans become default children."""
    body = Body()
    for item in b.body:
        match item:
            case ast.Need():
                body.needs.append(item)
            case ast.Shared():
                body.shared.append(item)
            case ast.Var():
                body.vars.append(item)
            case ast.Child():
                body.declared.append(item)
            case ast.Parallel():
                body.parallels.append(item)
                body.declared.extend(item.children)
            case ast.Plan():
                body.plans.append(item)
            case ast.Transition():
                body.transitions.append(item)
            case ast.Constraint():
                body.constraints.append(item)
    for child in body.declared:
        body.children.setdefault(child.key, child)

    def implicit(name: str, span: Span) -> None:
        if name not in body.children:
            body.children[name] = ast.Child(name, span=span)
            body.implicit.add(name)

    for plan in body.plans:
        for chain in plan.chains:
            for step in chain:
                implicit(step.name, step.span)
    for t in body.transitions:
        if t.source != "start":
            implicit(t.source, t.source_span)
        if t.target not in ("done", "fail"):
            implicit(t.target, t.target_span)
    return body


@dataclass
class Checked:
    """What the builder needs from the checker."""

    behaviors: dict[str, ast.Behavior]
    bodies: dict[str, Body]
    events: dict[str, RecordSpec]
    sound: frozenset[str] = frozenset()  # the behaviors that can be expanded: not recursive, not nested too deep
    called: frozenset[str] = frozenset()  # the behaviors another behavior uses as a child


class Checker:
    def __init__(self, program: Program, catalog: Catalog, report: Reporter):
        self.program = program
        self.catalog = catalog
        self.report = report
        self.typer = Typer(catalog, report)
        self.behaviors: dict[str, ast.Behavior] = {}
        self.bodies: dict[str, Body] = {}
        self.events: dict[str, RecordSpec] = dict(catalog.events)
        self.inherited: dict[str, dict[str, Type]] = {}
        self.reachable: set[str] = set()

    # ------------------------------------------------------------- entry point
    def run(self) -> Checked:
        self._declarations()
        self._collect_emitted_events()
        order = self._call_graph()
        for name in order:
            self.report.check_budget(self.behaviors[name].name_span)
            self._behavior(self.behaviors[name])
        called = frozenset(c.name for body in self.bodies.values() for c in body.children.values())
        return Checked(self.behaviors, self.bodies, self.events, frozenset(order), called)

    # ------------------------------------------------------------- declarations
    def _declarations(self) -> None:
        for f in self.program.files.values():
            missions = [b for b in f.behaviors if b.is_mission]
            for extra in missions[1:]:
                self.report.error("duplicate", f"a file holds at most one mission; {missions[0].name} came first",
                                  extra.name_span, "make it a behavior and use it as a child of the mission")
            for b in f.behaviors:
                if b.name in self.behaviors:
                    first = self.behaviors[b.name]
                    self.report.error("duplicate", f"behavior {b.name} is declared twice", b.name_span,
                                      notes=[("first declared here", first.name_span)])
                    continue
                ct = self.catalog.get(b.name)
                if ct is not None:
                    self.report.error("duplicate", f"{b.name} is already {_kind_word(ct)} component",
                                      b.name_span, f"rename the behavior (declared in {ct.source})")
                    continue
                self.behaviors[b.name] = b
                self.bodies[b.name] = summarize(b)

    def _collect_emitted_events(self) -> None:
        for body in self.bodies.values():
            for t in body.transitions:
                for a in t.actions:
                    if isinstance(a, ast.EmitAction) and a.event not in self.events:
                        fields = {arg.name: _written_type(arg.value) for arg in a.args or ()}
                        self.events[a.event] = RecordSpec(a.event, fields, "event")

    def _call_graph(self) -> list[str]:
        """Reject recursion and absurd depth; compute inherited scopes; return a checking order."""
        g: nx.DiGraph = nx.DiGraph()
        g.add_nodes_from((name, {"rank": i}) for i, name in enumerate(self.behaviors))
        for name, body in self.bodies.items():
            for child in body.children.values():
                if child.name in self.behaviors:
                    g.add_edge(name, child.name, span=child.span)
        cyclic: set[str] = set()
        for comp in nx.strongly_connected_components(g):
            if len(comp) > 1 or any(g.has_edge(n, n) for n in comp):
                cycle = find_cycle(g.subgraph(comp).copy()) if len(comp) > 1 else [next(iter(comp))]
                assert cycle is not None
                first = cycle[0]
                path = " > ".join([*cycle, first])
                self.report.error("recursion", f"behavior {first} includes itself: {path}",
                                  g.edges[first, cycle[1] if len(cycle) > 1 else first]["span"],
                                  "a behavior cannot contain itself; use a transition back to a state instead")
                cyclic |= comp
        dag = g.subgraph(set(g) - cyclic).copy()
        if dag.number_of_nodes() and nx.dag_longest_path_length(dag) > MAX_BEHAVIOR_DEPTH:
            path = nx.dag_longest_path(dag)
            self.report.error("nesting", f"behaviors nested too deeply ({len(path)} levels, at most "
                              f"{MAX_BEHAVIOR_DEPTH})", self.behaviors[path[0]].name_span)
            cyclic |= set(path)
        order = [n for n in nx.topological_sort(dag) if n not in cyclic]
        mission = self.program.mission
        for name in order:
            parents = list(dag.predecessors(name))
            if not parents:
                self.inherited[name] = {}
                continue
            views = [self._visible_to_children(p) for p in parents]
            common = set.intersection(*(set(v) for v in views))
            self.inherited[name] = {
                k: (views[0][k] if all(v[k] == views[0][k] for v in views) else ANY) for k in common}
        self.reachable = set(nx.descendants(dag, mission.name)) | {mission.name} if (
            mission is not None and mission.name in dag) else set()
        return order

    def _visible_to_children(self, name: str) -> dict[str, Type]:
        body = self.bodies[name]
        own: dict[str, Type] = {n.name: n.type.name for n in body.needs}
        own.update({s.name: s.type.name for s in body.shared})
        return {**self.inherited.get(name, {}), **own}

    # ------------------------------------------------------------- one behavior
    def _behavior(self, b: ast.Behavior) -> None:
        body = self.bodies[b.name]
        locals_: dict[str, Type] = {}
        seen: dict[str, Span] = {}

        def declare(name: str, typ: Type, span: Span, what: str) -> None:
            if name in seen:
                self.report.error("duplicate", f"{name} is declared twice in {b.name}", span,
                                  notes=[("first declared here", seen[name])])
            seen[name] = span
            locals_[name] = typ

        for p in b.params:
            declare(p.name, self._type_ref(p.type) or ANY, p.span, "parameter")
        scope = self._scope(b, locals_)
        for p in b.params:
            if p.default is not None and (t := self._type_ref(p.type)):
                self.typer.expect(p.default, t, scope, f"parameter {p.name}")
        if b.priority is not None and b.priority < 1:
            self.report.error("priority", "priority must be 1 or more (1 is the highest)", b.name_span)
        for n in body.needs:  # all needs first: `where` may relate them (solved together)
            declare(n.name, n.type.name, n.span, "resource")
        vars_ = {v.name: (f"var {v.name} cannot be read in a need's where", "a var is read by its behavior's "
                          "transitions, guards and actions only; give the value to a child behavior as a parameter"
                          f" and declare the need there: behavior Child({v.name}: {v.type.name}) {{ needs ..."
                          f" where ... == {v.name} }}") for v in body.vars}
        for n in body.needs:
            self._need(n, replace(self._scope(b, locals_), hidden=vars_))
        for s in body.shared:
            t = self._type_ref(s.type, data=True)
            declare(s.name, t or ANY, s.span, "shared")
        for v in body.vars:
            t = self._type_ref(v.type)
            if v.value is not None and t:
                self.typer.expect(v.value, t, scope, f"var {v.name}")
            declare(v.name, t or ANY, v.span, "var")
        scope = self._scope(b, locals_)
        self._constraints(b, body, scope)
        self._children(b, body, scope, seen)
        self._structure(b, body)
        self._transitions(b, body, scope)

    def _constraints(self, b: ast.Behavior, body: Body, scope: Scope) -> None:
        named: dict[str, Span] = {}
        for c in body.constraints:
            if c.name in named:
                self.report.error("duplicate", f"constraint {c.name} is declared twice in {b.name}", c.span,
                                  notes=[("first declared here", named[c.name])])
            named[c.name] = c.span
            self.typer.expect(c.condition, "bool", scope, f"constraint {c.name}")

    def _scope(self, b: ast.Behavior, locals_: Mapping[str, Type]) -> Scope:
        body = self.bodies[b.name]
        children = {k: c.name for k, c in body.children.items()}
        out_of_context = b.name not in self.reachable and not b.is_mission
        return Scope({**self.inherited.get(b.name, {}), **locals_}, children, False, out_of_context)

    def _type_ref(self, ref: ast.TypeRef, data: bool = False) -> str | None:
        if ref.name in SCALAR_TYPES:
            return ref.name
        ct = self.catalog.get(ref.name)
        if ct is not None and ct.kind is not Kind.BEHAVIOR:
            return ref.name
        known = list(SCALAR_TYPES) + self.catalog.names(Kind.RC, Kind.ARC, Kind.DATA)
        what = "data type" if data else "type"
        self.report.error("unknown-type", f"unknown {what} {ref.name}", ref.span, did_you_mean(ref.name, known))
        return None

    def _need(self, n: ast.Need, scope: Scope) -> None:
        ct = self.catalog.get(n.type.name)
        if ct is None or not ct.is_resource:
            self.report.error("unknown-resource", f"unknown resource type {n.type.name}", n.type.span,
                              did_you_mean(n.type.name, self.catalog.names(Kind.RC, Kind.ARC))
                              or f"resources: {', '.join(sorted(self.catalog.names(Kind.RC, Kind.ARC)))}")
            return
        inner = scope.with_names({n.name: n.type.name})
        if n.where is not None:
            self.typer.expect(n.where, "bool", inner, "where")
        if n.quantity is not None:
            if not ct.sharable:
                self.report.error("quantity", f"quantity applies to sharable resources; {ct.name} is not sharable",
                                  n.quantity.span, "remove quantity: the resource is granted whole")
            t = self.typer.infer(n.quantity, scope)
            if not assignable("float", t):
                self.report.error("type", f"quantity expects a number, got {show(t)}", n.quantity.span)
            q = constant(n.quantity)
            if q is not None and not q > 0:
                self.report.error("quantity", f"quantity {q:g} asks for nothing: it must be above 0", n.quantity.span,
                                  "leave quantity out to take the whole resource")
        if n.slice is not None and not n.slice.seconds >= MIN_SLICE - 1e-9:
            self.report.error("slice", f"a time slice of {n.slice.text} never lets the holder run: it is resumed at"
                              f" one control cycle ({CONTROL_CYCLE:g}s) and preempted at the next; give at least"
                              f" {MIN_SLICE * 1000:g}ms", n.slice.span,
                              "a slice of 1s or more leaves most of it to the work; leave `for` out to hold the"
                              " resource until released")

    # ------------------------------------------------------------- children
    def _children(self, b: ast.Behavior, body: Body, scope: Scope, seen: dict[str, Span]) -> None:
        keys: dict[str, ast.Child] = {}
        for child in body.declared:
            if child.key in keys:
                self.report.error("duplicate", f"two children of {b.name} are named {child.key}", child.span,
                                  f"give one an alias: {child.name}(...) as other_name",
                                  notes=[("first here", keys[child.key].span)])
            keys[child.key] = child
            if child.key in seen:
                self.report.error("duplicate", f"{child.key} names both a child and a declaration in {b.name}",
                                  child.span)
        for key, child in body.children.items():
            self._child(child, scope, b.name if key in body.implicit else None, b.name)

    def _child(self, child: ast.Child, scope: Scope, implicit_in: str | None = None, within: str = "") -> None:
        target = self._callee(child.name, child.span, implicit_in, within)
        if child.priority is not None and child.priority < 1:
            self.report.error("priority", "priority must be 1 or more (1 is the highest)", child.span)
        if child.mult is not None:
            self._multiplicity(child.mult, scope)
        if target is None:
            return
        params = _signature(target)
        given: dict[str, ast.Arg] = {}
        for arg in child.args or ():
            if arg.name in given:
                self.report.error("duplicate", f"{arg.name} is given twice", arg.span)
            given[arg.name] = arg
            spec = params.get(arg.name)
            if spec is None and isinstance(target, ComponentType) and target.input(arg.name) is not None:
                continue  # binds an input: checked where the scope is known (dsl.build)
            if spec is None:
                inputs = [i.name for i in target.inputs] if isinstance(target, ComponentType) else []
                self.report.error("unknown-parameter", f"{child.name} has no parameter {arg.name}", arg.span,
                                  did_you_mean(arg.name, [*params, *inputs]) or
                                  (f"its parameters: {', '.join(params)}" if params else f"{child.name} takes none")
                                  + (f"; its inputs: {', '.join(inputs)}" if inputs else ""))
                continue
            self.typer.expect(arg.value, spec.type, scope, arg.name)
            self._in_range(target, spec, arg)
        for spec in params.values():
            if spec.required and spec.name not in given:
                self.report.error("missing-parameter", f"{child.name} needs parameter {spec.name}", child.span,
                                  f"write {child.name}({spec.name}: ...)")

    def _in_range(self, target: ast.Behavior | ComponentType, spec: ParamSpec, arg: ast.Arg) -> None:
        """A constant argument within the bounds of its parameter (`dsl.param_values.out_of_bounds`: no negative
        duration, inside the range its manifest declares: `FollowCorridor(speed: 50)` is refused here, where it is
        written); an expression is checked when the state is entered (`drd.runtime.interpreter`)."""
        value = constant(arg.value) if spec.type in NUMERIC else None
        why = out_of_bounds(spec, value) if value is not None else ""
        if not why:
            return
        negative = spec.type == "duration" and value is not None and value < 0
        if negative or spec.limit is None or not isinstance(target, ComponentType):
            self.report.error("duration" if negative else "range", f"{arg.name}: {why}", arg.span)
            return
        default = spec.default
        keep = (f", or leave it out for the default {spec.limit.show(default)}"
                f"{' ' + spec.limit.unit if spec.limit.unit else ''}"
                if isinstance(default, int | float) and not isinstance(default, bool) else "")
        self.report.error("range", f"{arg.name} {why} ({possessive(target.name)} manifest, {target.source})",
                          arg.value.span, f"give {arg.name} a value within {spec.limit.text}{keep}")

    def _callee(self, name: str, span: Span, implicit_in: str | None = None,
                within: str = "") -> ast.Behavior | ComponentType | None:
        """The behavior or component a child names; an unknown one is reported with a suggestion, never the behavior
        it is written in (`Liar` in `mission Lies` suggested `Lies`, which then includes itself: users audit 18, #4)."""
        if name in self.behaviors:
            return self.behaviors[name]
        ct = self.catalog.get(name)
        if ct is not None and ct.kind is Kind.BEHAVIOR:
            return ct
        if ct is not None:
            self.report.error("not-a-behavior", f"{name} is {_kind_word(ct)}, not a behavior", span,
                              f"resources are acquired with needs: needs x: {name}" if ct.is_resource else
                              f"data is declared with shared: shared x: {name}")
            return None
        known = [k for k in (*self.behaviors, *self.catalog.names(Kind.BEHAVIOR)) if k != within]
        if implicit_in is not None:  # named only in a transition or plan: the user meant a state
            body = self.bodies[implicit_in]
            siblings = [k for k in body.children if k not in body.implicit]  # not the typo itself
            self.report.error("unknown-state", f"unknown state {name}: no child of {implicit_in} and no behavior "
                              "has this name", span, did_you_mean(name, [*siblings, *known, "done", "fail"]))
            return None
        self.report.error("unknown-behavior", f"unknown behavior {name}", span, did_you_mean(name, known) or (
            "a behavior is a component with a manifest: drd's own, or one in a folder given with -C DIR or"
            " $DRD_COMPONENTS (on a cluster, to the controller's `drd start`, which compiles the mission;"
            " docs/components.md)"))
        return None

    def _multiplicity(self, m: ast.Multiplicity, scope: Scope) -> None:
        for bound in (m.low, m.high):
            if bound is not None:
                self.typer.expect(bound, "int", scope, "multiplicity")
        low, high = _const(m.low), _const(m.high) if m.high is not None else None
        for value in (low, high):
            limit = self.report.limits.instances
            if isinstance(value, int) and value > limit:
                self.report.error("multiplicity", f"multiplicity {value} is above the limit of {limit} instances",
                                  m.span, "an instance per robot or task: use [1..*] to create as many as the"
                                  " resources allow; a cluster may raise the limit (hosts.yaml cluster.limits)")
        if isinstance(low, int) and low < 0:
            self.report.error("multiplicity", f"multiplicity {low} can never hold: it must be 0 or more", m.span)
        if m.exact and low == 0:
            self.report.error("multiplicity", "multiplicity [0] creates no instance", m.span,
                              "remove the child, or write [0..n]")
        if isinstance(low, int) and isinstance(high, int):
            if high < low:
                self.report.error("multiplicity", f"multiplicity [{low}..{high}] can never hold: "
                                  f"the minimum is above the maximum", m.span)
            elif high == 0:
                self.report.error("multiplicity", f"multiplicity [{low}..0] creates no instance", m.span)

    # ------------------------------------------------------------- body structure
    def _structure(self, b: ast.Behavior, body: Body) -> None:
        if len(body.parallels) > 1 or len(body.plans) > 1 or (body.parallels and body.plans):
            blocks: list[ast.Parallel | ast.Plan] = [*body.parallels, *body.plans]
            extra = blocks[1]
            self.report.error("structure", f"{b.name} has more than one parallel block or plan", extra.span,
                              "put the extra block in a behavior of its own and use that as a child")
            return
        if body.parallel is not None:
            par = body.parallel
            inside = {c.key for c in par.children}
            outside = [c for c in body.children.values() if c.key not in inside]
            for c in outside:
                self.report.error("structure", f"{c.key} is outside the parallel block of {b.name}", c.span,
                                  "a body with a parallel block holds all of its children inside it")
            keys = {c.key for c in par.children}
            typo_inside = any(c.name not in self.behaviors and self.catalog.get(c.name) is None
                              for c in par.children)  # then the unknown child is the error to show
            if par.policy is ast.Policy.UNTIL and par.until not in keys and not typo_inside:
                self.report.error("unknown-state", f"parallel until {par.until}: no such child in the block",
                                  par.span, did_you_mean(par.until or "", keys))
            return
        if body.plan is not None:
            self._plan(body.plan)
            steps = {s.name for chain in body.plan.chains for s in chain}
            self._reachability(b, body, steps)
            return
        starts = [t for t in body.transitions if t.source == "start"]
        if len(body.children) > 1 and not starts:
            names = ", ".join(list(body.children)[:4])
            first = next(iter(body.children))
            self.report.error("structure", f"{b.name} has several children ({names}) and no way to start",
                              b.name_span,
                              f"say which runs first (start -> {first}), or use a plan or a parallel block")
            return
        if any(self._unknown(body, t.target) for t in starts):
            return  # an unknown start target is reported as such; every child "never reached" would be its echo
        entry = {t.target for t in starts} or set(list(body.children)[:1])
        self._reachability(b, body, entry)

    def _unknown(self, body: Body, key: str) -> bool:
        """Whether `key` names nothing a state can be: no child, or a child of no known behavior or component (a
        transition to an undeclared name makes one, reported as an unknown state)."""
        if key in ("done", "fail"):
            return False
        child = body.children.get(key)
        return child is None or (child.name not in self.behaviors and self.catalog.get(child.name) is None)

    def _plan(self, plan: ast.Plan) -> None:
        if plan.preallocate and plan.concurrent:
            self.report.error("preallocate", "plan concurrent preallocate: a concurrent plan starts each step when "
                              "its predecessors are done, so there is no next step to preallocate", plan.span,
                              "remove preallocate, or make the plan sequential")
        g = plan_graph(plan)
        cycle = find_cycle(g)
        if cycle is not None:
            path = " < ".join([*cycle, cycle[0]])
            self.report.error("plan-cycle", f"plan cycle: {path}", plan.span,
                              "a step cannot (even indirectly) precede itself; remove one of these precedences",
                              notes=[(f"{a} < {b}", g.edges[a, b]["span"])
                                     for a, b in zip(cycle, [*cycle[1:], cycle[0]], strict=True)])

    def _reachability(self, b: ast.Behavior, body: Body, entry: set[str]) -> None:
        g: nx.DiGraph = nx.DiGraph()
        g.add_nodes_from(body.children)
        g.add_node("start")
        g.add_edges_from(("start", e) for e in entry)
        g.add_edges_from((t.source, t.target) for t in body.transitions if t.source != "start")
        reached = nx.descendants(g, "start")
        for key, child in body.children.items():
            if key not in reached:
                src = next((e for e in entry if e not in ("done", "fail")), "start")  # no transition leaves those
                self.report.error("unreachable", f"{key} is never reached: no transition leads to it", child.span,
                                  f"add a transition such as `{src} -> {key}`, or remove it")

    # ------------------------------------------------------------- transitions
    def _transitions(self, b: ast.Behavior, body: Body, scope: Scope) -> None:
        concurrent = body.parallel is not None or (body.plan is not None and body.plan.concurrent)
        for t in body.transitions:
            if concurrent and t.source != "start" and t.target not in ("done", "fail", t.source):
                self.report.error("structure", f"{t.source} -> {t.target}: in a parallel block or concurrent "
                                  "plan a transition leads only to done, fail or back to its source",
                                  t.target_span)
            if body.parallel is not None and t.source == "start":
                self.report.error("structure", "a parallel block starts all its children: remove start ->",
                                  t.source_span)
            elif body.plan is not None and t.source == "start":  # one or the other says what runs first (spec)
                self.report.error("structure", "a plan starts its first step: remove start ->, or put its target"
                                  " first in the plan", t.source_span)
            elif t.source == "start" and t.kind is ast.TriggerKind.ERROR:
                self.report.error("structure", f"start -> {t.target} on error: starting cannot fail, so this is"
                                  " never taken", t.span, "remove `on error`, or put it on a transition from a child")
            event: RecordSpec | None | bool = False
            if t.kind is ast.TriggerKind.EVENT and t.event is not None:
                event = self.events.get(t.event)
                if event is None:
                    self.report.error("unknown-event", f"unknown event {t.event}", _or(t.event_span, t.span),
                                      did_you_mean(t.event, [*self.events, "error"])  # `on error` too
                                      or f"known events: {', '.join(sorted(self.events)) or 'none'}; and"
                                         " `on error` when a child fails")
                if t.sender is not None and t.sender not in body.children:
                    self.report.error("unknown-state", f"on {t.event} from {t.sender}: {b.name} has no child"
                                      f" {t.sender}", _or(t.sender_span, t.span), did_you_mean(t.sender, body.children)
                                      or f"its children: {', '.join(body.children) or 'none'}")
            if t.preallocate:
                self._preallocating(t)
            tscope = Scope(scope.names, scope.children, event, scope.open)
            if t.condition is not None:
                self.typer.expect(t.condition, "bool", tscope, "when")
            if t.delay is not None:
                self.typer.expect(t.delay, "duration", tscope, "after")
                delay = constant(t.delay)
                if delay is not None and delay < 0:  # users audit 9: it fired at once, as `after 0s` does
                    self.report.error("duration", f"after {delay:g}s: a duration cannot be negative (the source"
                                      " cannot have been active for less than no time)", t.delay.span,
                                      "write `after 0s` to leave as soon as the source is active")
            if t.guard is not None:
                self.typer.expect(t.guard, "bool", tscope, "a guard")
            for a in t.actions:
                self._action(b, body, a, tscope)

    def _preallocating(self, t: ast.Transition) -> None:
        if t.kind is not ast.TriggerKind.COMPLETION:
            self.report.error("preallocate", f"{t.source} -> {t.target} preallocate: only a completion transition "
                              "preallocates (entering the source reserves the target's needs)", t.span,
                              "remove the trigger, or remove preallocate")
        elif t.source == "start":
            self.report.error("preallocate", "start -> ... preallocate: the first state is entered at once, there "
                              "is nothing to reserve ahead", t.source_span, "remove preallocate")
        elif t.target in ("done", "fail"):
            self.report.error("preallocate", f"{t.source} -> {t.target} preallocate: {t.target} needs no resources",
                              t.target_span, "remove preallocate")

    def _action(self, b: ast.Behavior, body: Body, a: ast.Action, scope: Scope) -> None:
        match a:
            case ast.SetAction(name=name, value=value):
                var = next((v for v in body.vars if v.name == name), None)
                param = next((p for p in b.params if p.name == name), None)
                if var is None and param is not None:  # users audit 9, D12: the hint said to declare a var of
                    self.report.error("read-only", f"set {name}: {name} is a parameter of {b.name}, which a"  # that
                                      " transition cannot change", a.span,  # name, which was then declared twice
                                      f"copy it into a var and set that: var current_{name}: {param.type.name}"
                                      f" = {name}")
                elif var is None:
                    kind = self.typer.infer(value, scope)  # the hint declares it with the type of what is set
                    kind, zero = (kind, ZEROS[kind]) if isinstance(kind, str) and kind in ZEROS else ("int", "0")
                    self.report.error("unknown-name", f"set {name}: {b.name} has no var {name}", a.span,
                                      did_you_mean(name, [v.name for v in body.vars])
                                      or f"declare it: var {name}: {kind} = {zero}")
                else:
                    self.typer.expect(value, var.type.name, scope, f"var {name}")
            case ast.EmitAction(event=event, args=args):
                spec = self.events.get(event)
                for arg in args or ():
                    t = self.typer.infer(arg.value, scope)
                    if spec and spec.fields and arg.name not in spec.fields:
                        self.report.error("unknown-parameter", f"event {event} has no field {arg.name}", arg.span,
                                          did_you_mean(arg.name, spec.fields))
                    elif spec and arg.name in spec.fields and not assignable(spec.fields[arg.name], t):
                        self.report.error("type", f"{arg.name} expects {spec.fields[arg.name]}, got {show(t)}",
                                          arg.value.span)
            case ast.ReleaseAction(resource=res):
                held = {n.name for n in body.needs} | {
                    k for k, v in scope.names.items() if isinstance(v, str) and _is_resource(self.catalog, v)}
                if res not in held:
                    self.report.error("unknown-name", f"release({res}): no resource {res} is held here", a.span,
                                      did_you_mean(res, held))
            case ast.LogAction(message=msg):
                self.typer.infer(msg, scope)


def _signature(target: ast.Behavior | ComponentType) -> dict[str, ParamSpec]:
    if isinstance(target, ComponentType):
        return {p.name: p for p in target.params}
    return {p.name: ParamSpec(p.name, p.type.name, None, p.default is None) for p in target.params}


def _const(e: ast.Expr | None) -> object:
    """The value of a literal integer expression (with unary minus), else None."""
    if isinstance(e, ast.Literal) and isinstance(e.value, int) and not isinstance(e.value, bool):
        return e.value
    if isinstance(e, ast.Unary) and e.op == "-":
        v = _const(e.operand)
        return -v if isinstance(v, int) else None
    return None


def _is_resource(catalog: Catalog, type_name: str) -> bool:
    ct = catalog.get(type_name)
    return ct is not None and ct.is_resource


def _kind_word(ct: ComponentType) -> str:
    return {Kind.BEHAVIOR: "an elementary behavior", Kind.RC: "a resource", Kind.ARC: "a resource",
            Kind.DATA: "a data type"}[ct.kind]


def _written_type(e: ast.Expr) -> str:
    """An emitted field's type where the expression says it without a scope (its literal, a duration added to
    something, a string with interpolation), else ANY: the events are collected before any behavior's names are
    known. Users audit 9, D9: every field was ANY, so a duration printed as `10`, not `10s`, and `event.who > 5`
    of a text passed the checker."""
    match e:  # a plain number stays ANY: `emit E(n: 1)` here and `emit E(n: 0.5)` there are one field
        case ast.Literal(value=bool()):
            return "bool"
        case ast.Literal(value=str()) | ast.Interp():
            return "str"
        case ast.Duration():
            return "duration"
        case ast.Unary(op="-", operand=operand) if _written_type(operand) == "duration":
            return "duration"
        case ast.Binary(op="+" | "-", left=left, right=right) if "duration" in (_written_type(left),
                                                                               _written_type(right)):
            return "duration"
    return ANY


def _or(span: Span, whole: Span) -> Span:
    """`span`, or `whole` where the parser gave none (a transition built in code)."""
    return whole if span == NOWHERE else span
