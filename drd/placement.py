"""The Load Balancer's policy: which host should run a component. Pure: no I/O, no clock, no randomness.

The daemon gathers what it knows about every host into `HostView`s (its latest load report, its
devices, roles and the instances it runs) and asks `place`. The policy is a small framework on the
model of the Kubernetes scheduler: **filters** (`FILTERS`), each saying why a host cannot take the
component (down, excluded after a failed start, not offered there, missing devices, too few cores,
no worker role, outside the caller's affinity, multiplicity reached), then **scores** (`SCORES`) of the hosts left,
each plugin giving a value on one scale (percentage points) and a weight; the lowest total wins, ties
going to the smaller host name. Every answer carries a `Decision` record of it all, for the logs and
`missionctl status`. See docs/placement.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from drd.hosts import Host, Placement
from dsl.catalog import ComponentType, Kind
from dsl.errors import did_you_mean
from dsl.param_values import refuses

#: One running instance weighs as much as 10 percentage points of CPU or memory (before weighting).
INSTANCE_SCALE = 10.0
#: Subtracted from the score of a host the caller prefers (one of `prefer_hosts`).
PREFER_BONUS = 50.0
#: Points of a host holding all the devices the instance's mission state uses (`near`), before weighting.
AFFINITY_SCALE = 100.0


@dataclass(frozen=True, slots=True)
class HostView:
    """What the placer knows of one host: its last load report, hardware and running instances.

    `cpu` and `memory` are percentages (0-100); `devices` the RC types it has (`Camera`); `running`
    counts instances by component name; `cores` is None when unknown; `roles` as in hosts.yaml; `offers` the
    component types its daemon announced it can run (its catalog: a type whose manifest it lacks, it refuses
    to start), None while it has announced nothing.
    """

    name: str
    cpu: float = 0.0
    memory: float = 0.0
    instances: int = 0
    up: bool = True
    devices: frozenset[str] = frozenset()
    running: Mapping[str, int] = field(default_factory=dict, hash=False)
    cores: int | None = None
    roles: frozenset[str] = frozenset()
    offers: frozenset[str] | None = None


def view_of(host: Host, *, cpu: float = 0.0, memory: float = 0.0, up: bool = True,
            running: Mapping[str, int] | None = None, offers: Collection[str] | None = None) -> HostView:
    """A `HostView` of a configured host: devices, cores and roles from `hosts.yaml`, load from a report, the
    types it offers from its announcement."""
    running = dict(running or {})
    return HostView(host.name, cpu, memory, sum(running.values()), up, frozenset(d.type for d in host.devices),
                    running, host.cores, frozenset(str(r) for r in host.roles),
                    None if offers is None else frozenset(offers))


# ---------------------------------------------------------------- the decision record


@dataclass(frozen=True, slots=True)
class Part:
    """One score plugin's say on one host: `value` in points (lower is better), times `weight`."""

    plugin: str
    weight: float
    value: float

    @property
    def points(self) -> float:
        return self.weight * self.value + 0.0  # never -0.0 in an explanation


@dataclass(frozen=True, slots=True)
class Scored:
    """A host that passed every filter: its total (the sum of its parts' points) and the parts."""

    host: str
    total: float
    parts: tuple[Part, ...]

    def part(self, plugin: str) -> Part | None:
        return next((p for p in self.parts if p.plugin == plugin), None)


@dataclass(frozen=True, slots=True)
class Decision:
    """Why a host was chosen (or none): the candidates, each filtered host with its reasons, each scored host
    with its parts (best first), the winner (None: unplaceable, `problem` says why when no host was looked at)."""

    component: str
    candidates: tuple[str, ...] = ()
    filtered: Mapping[str, tuple[str, ...]] = field(default_factory=dict, hash=False)
    scored: tuple[Scored, ...] = ()
    winner: str | None = None
    problem: str = ""

    def summary(self) -> str:
        """One short line: the winner, the parts that made it beat the runner-up, the hosts filtered and why."""
        if self.winner is None:
            return f"unplaceable: {self.problem or _listed(self.filtered)}"
        best = self.scored[0]
        why = _versus(best, self.scored[1]) if len(self.scored) > 1 else "the only host left"
        out = f"{self.winner} ({why}"
        if self.filtered:
            out += "; filtered " + _listed(self.filtered)
        return out + ")"

    def as_dict(self) -> dict[str, Any]:
        """The whole record as plain JSON."""
        return {"component": self.component, "winner": self.winner, "candidates": list(self.candidates),
                "filtered": {h: list(r) for h, r in sorted(self.filtered.items())},
                "scored": [{"host": s.host, "total": s.total,
                            "parts": [{"plugin": p.plugin, "weight": p.weight, "value": p.value, "points": p.points}
                                      for p in s.parts]} for s in self.scored],
                "problem": self.problem, "summary": self.summary()}


@dataclass(frozen=True, slots=True)
class Placed:
    """The chosen host, its score (lowest wins) and why: the score's terms, then the refused hosts; `decision`
    is the full record (left out of equality: two answers are the same when they choose the same)."""

    host: str
    score: float
    reasons: tuple[str, ...] = ()
    decision: Decision | None = field(default=None, compare=False)


@dataclass(frozen=True, slots=True)
class Unplaceable:
    """No host can take the component. `reason` names every refused host and why (`refused` by host)."""

    reason: str
    refused: Mapping[str, tuple[str, ...]] = field(default_factory=dict, hash=False)
    decision: Decision | None = field(default=None, compare=False)


Outcome = Placed | Unplaceable


# ---------------------------------------------------------------- plugins


@dataclass(frozen=True, slots=True)
class Context:
    """What the plugins know besides the host: the component, the caller's constraints and the weights."""

    component: ComponentType
    weights: Placement
    cluster_count: int = 0
    exclude: frozenset[str] = frozenset()
    affinity: frozenset[str] | None = None
    role: str | None = None  # only hosts with it (None: the caller asks for none, or no candidate has it)
    prefer: frozenset[str] = frozenset()
    near: Mapping[str, float] = field(default_factory=dict, hash=False)  # host -> share of the devices, 0-1
    why: Mapping[str, str] = field(default_factory=dict, hash=False)  # excluded host -> why its start failed


@dataclass(frozen=True, slots=True)
class Filter:
    """A rule a host must pass: `check` says why it fails (None: it passes). `final`: a failure hides the others
    (a down host is only `down`); `alone`: checked only when no other filter refused the host (cluster-wide)."""

    name: str
    check: Callable[[HostView, Context], str | None]
    final: bool = False
    alone: bool = False


@dataclass(frozen=True, slots=True)
class Score:
    """A score plugin: its weight (from the configured `Placement`) and a host's value in points."""

    name: str
    weight: Callable[[Placement], float]
    value: Callable[[HostView, Context], float]


def _missing_devices(host: HostView, ctx: Context) -> str | None:
    missing = sorted(required_devices(ctx.component) - host.devices)
    return f"no {', '.join(missing)} device{'s' if len(missing) > 1 else ''}" if missing else None


def _excluded(host: HostView, ctx: Context) -> str | None:
    if host.name not in ctx.exclude:
        return None
    why = ctx.why.get(host.name, "")
    return f"excluded (its start there failed: {why})" if why else "excluded (a start there failed or timed out)"


def _not_offered(host: HostView, ctx: Context) -> str | None:
    """A host whose daemon does not announce the type would refuse its start (no manifest of it there, or its module
    imports a library not installed there); a host that lacks its devices is refused for those
    (`_missing_devices`), once."""
    name = ctx.component.name
    if host.offers is None or name in host.offers or required_devices(ctx.component) - host.devices:
        return None
    return f"does not offer {name} (its daemon has no manifest of it, or cannot import its module)"


def _cores(host: HostView, ctx: Context) -> str | None:
    wanted = ctx.component.scheduling.cores
    if wanted and host.cores is not None and max(wanted) >= host.cores:
        return f"has {host.cores} core{'s' if host.cores != 1 else ''}, the manifest pins core {max(wanted)}"
    return None


def _outside(host: HostView, ctx: Context) -> str | None:
    if ctx.affinity is not None and host.name not in ctx.affinity:
        return f"outside its affinity ({', '.join(sorted(ctx.affinity)) or 'none'})"
    return None


def _multiplicity(host: HostView, ctx: Context) -> str | None:
    limit = ctx.component.multiplicity
    return f"multiplicity {limit} reached" if limit is not None and ctx.cluster_count >= limit else None


#: The filters, in the order their reasons are given.
FILTERS: tuple[Filter, ...] = (
    Filter("up", lambda h, c: None if h.up else "down", final=True),
    Filter("excluded", _excluded),
    Filter("offers", _not_offered),
    Filter("devices", _missing_devices),
    Filter("cores", _cores),
    Filter("role", lambda h, c: f"no {c.role} role" if c.role is not None and c.role not in h.roles else None),
    Filter("affinity", _outside),
    Filter("multiplicity", _multiplicity, alone=True),
)

#: The score plugins, in the order their parts are listed; a total sums them in this order.
SCORES: tuple[Score, ...] = (
    Score("cpu", lambda w: w.cpu, lambda h, c: _percent(h.cpu)),
    Score("memory", lambda w: w.memory, lambda h, c: _percent(h.memory)),
    Score("instances", lambda w: w.instances, lambda h, c: max(0, h.instances) * INSTANCE_SCALE),
    Score("preferred", lambda w: 1.0, lambda h, c: -PREFER_BONUS if h.name in c.prefer else 0.0),
    Score("affinity", lambda w: w.affinity, lambda h, c: 0.0 - AFFINITY_SCALE * _share(c.near.get(h.name, 0.0))),
)


# ---------------------------------------------------------------- the policy


def with_more(view: HostView, component: str, n: int = 1) -> HostView:
    """The view with `n` more instances of `component`: placements made since the host last reported, so that
    several placed in one cycle spread instead of all going to the host that looked emptiest."""
    return replace(view, instances=view.instances + n,
                   running={**view.running, component: view.running.get(component, 0) + n})


@dataclass(frozen=True, slots=True)
class Recent:
    """A placement made lately (`at`, a monotonic time), which the host's announcements may not show yet: `seen` is
    how many instances of `component` the host announced when it was made."""

    host: str
    component: str
    seen: int
    at: float = 0.0


def refused_last(recent: Sequence[Recent], component: str, exclude: Collection[str]) -> bool:
    """Whether the latest placement's start failed: it is of `component` and this placement of it excludes its
    host (the retry; a mission's starts are made one at a time, so it follows the failure at once). Such a
    placement runs nowhere, so it must not count on its host."""
    return bool(recent) and recent[-1].component == component and recent[-1].host in exclude


def with_recent(views: Iterable[HostView], recent: Sequence[Recent], ended: Sequence[Recent] = ()) -> list[HostView]:
    """The views with the recent placements (oldest first) their hosts do not announce yet: each instance counts
    once. Of k placements of a type on a host that announced `seen` of it before the first, those beyond what it
    announces now (`seen + k - now`, 0 to k) are added (an instance that ended meanwhile hides one for a while).
    Likewise the instances that `ended` lately (`seen`: what the host announced as the first ended) and that it
    still announces (`now - (seen - k)`, 0 to k) are taken off: the next state's instance, placed in the instant
    the last one ended, counted it still there (placement audit 24, #3)."""
    out = []
    for view in views:
        announced = view  # both counts are of what the host announced, not of each other's result
        for (host, component), made in _groups(recent).items():
            if host == view.name:
                now = announced.running.get(component, 0)
                pending = min(len(made), max(0, made[0].seen + len(made) - now))
                view = with_more(view, component, pending) if pending else view
        for (host, component), gone in _groups(ended).items():
            if host == view.name:
                now = announced.running.get(component, 0)
                still = min(len(gone), max(0, now - (gone[0].seen - len(gone))))
                view = with_more(view, component, -still) if still else view
        out.append(view)
    return out


def _groups(recent: Sequence[Recent]) -> dict[tuple[str, str], list[Recent]]:
    """`recent` by (host, component), each in its order."""
    groups: dict[tuple[str, str], list[Recent]] = {}
    for r in recent:
        groups.setdefault((r.host, r.component), []).append(r)
    return groups


def required_devices(component: ComponentType) -> frozenset[str]:
    """The device types a host must have: an RC's own type, an ARC's part types; none for the others."""
    if component.kind is Kind.RC:
        return frozenset({component.name})
    if component.kind is Kind.ARC:
        return frozenset(component.parts.values())
    return frozenset()


def running_count(component: str, hosts: Iterable[HostView]) -> int:
    """Instances of `component` in the cluster; those on hosts that are down are gone (placed again)."""
    return sum(max(0, h.running.get(component, 0)) for h in hosts if h.up)


def shares(devices: Mapping[str, int]) -> dict[str, float]:
    """Each host's share (0-1) of the devices counted by host: what `near` takes from device counts."""
    total = sum(max(0, n) for n in devices.values())
    return {h: max(0, n) / total for h, n in devices.items() if n > 0} if total else {}


def parts(host: HostView, ctx: Context) -> tuple[Part, ...]:
    """Every score plugin's part for `host`."""
    return tuple(Part(s.name, s.weight(ctx.weights), s.value(host, ctx)) for s in SCORES)


def total(of: Iterable[Part]) -> float:
    value = 0.0
    for p in of:
        value += p.points
    return value


def score(host: HostView, weights: Placement, preferred: bool = False,
          near: Mapping[str, float] | None = None) -> float:
    """`cpu*w.cpu + memory*w.memory + instances*10*w.instances`, minus `PREFER_BONUS` if preferred, minus
    `w.affinity * 100 * share` for `near` (host -> its share of the devices).

    Loads are clamped to 0-100 (an unknown, NaN, load counts as full) and instances to >= 0.
    """
    ctx = Context(_ANY, weights, prefer=frozenset({host.name}) if preferred else frozenset(), near=near or {})
    return total(parts(host, ctx))


def refusals(component: ComponentType, host: HostView, *, cluster_count: int = 0,
             exclude: Collection[str] = (), affinity: Collection[str] | None = None) -> tuple[str, ...]:
    """Why `host` cannot run `component` (empty: it can). `cluster_count` is `running_count` of it."""
    ctx = Context(component, Placement(), cluster_count, frozenset(exclude),
                  None if affinity is None else frozenset(affinity))
    return filtered(host, ctx)


def filtered(host: HostView, ctx: Context) -> tuple[str, ...]:
    """The reasons of every filter `host` fails (empty: it passes them all)."""
    out: list[str] = []
    for f in FILTERS:
        if f.alone and out:
            continue
        why = f.check(host, ctx)
        if why is not None:
            out.append(why)
            if f.final:
                break
    return tuple(out)


def place(component: ComponentType, candidates: Sequence[HostView], weights: Placement, *,
          params: Mapping[str, object] | None = None, prefer_hosts: Collection[str] = (),
          exclude: Collection[str] | Mapping[str, str] = (), affinity: Collection[str] | None = None,
          role: str | None = None, near: Mapping[str, float] | None = None) -> Outcome:
    """Choose the host for one more instance of `component`, or say why none can take it; either answer carries
    the `Decision` record.

    `params` are checked against the manifest's (unknown names, missing required ones, scalar types)
    before any host is considered; `exclude` are hosts where a start already failed (the retry path), a mapping
    giving why (the host's refusal, kept in the decision);
    `affinity`, when given, restricts the choice to those hosts; `role`, when some candidate has it, to
    the hosts with that role (`worker`); `near` gives each host's share (0-1) of the devices the
    instance's mission state uses (`shares`), scored by the `affinity` weight. Candidates are taken by
    name: a name given twice keeps its first view.
    """
    problems = check_params(component, params or {})
    if problems:
        reason = f"{component.name}: {'; '.join(problems)}"
        return Unplaceable(reason, decision=Decision(component.name, problem=reason))
    views: dict[str, HostView] = {}
    for h in candidates:
        views.setdefault(h.name, h)
    hosts = list(views.values())
    if not hosts:
        reason = f"{component.name}: no hosts known"
        return Unplaceable(reason, decision=Decision(component.name, problem=reason))
    ctx = Context(component, weights, running_count(component.name, hosts), frozenset(exclude),
                  None if affinity is None else frozenset(affinity),
                  role if role is not None and any(role in h.roles for h in hosts) else None,
                  frozenset(prefer_hosts), dict(near or {}),
                  {h: str(w) for h, w in exclude.items() if w} if isinstance(exclude, Mapping) else {})
    return decide(hosts, ctx)


def decide(hosts: Sequence[HostView], ctx: Context) -> Outcome:
    """Filters, then scores, over distinct hosts: the framework's core."""
    refused = {h.name: r for h in hosts if (r := filtered(h, ctx))}
    ranked = sorted((Scored(h.name, total(ps), ps) for h in hosts if h.name not in refused
                     for ps in (parts(h, ctx),)), key=lambda s: (s.total, s.host))
    listed = _listed(refused)
    name = ctx.component.name
    record = Decision(name, tuple(sorted(h.name for h in hosts)), refused, tuple(ranked),
                      ranked[0].host if ranked else None)
    if not ranked:
        return Unplaceable(f"no host can run {name}: {listed}", refused, record)
    best = ranked[0]
    reasons = [_explain(best)]
    if len(ranked) > 1:
        reasons.append("next: " + ", ".join(f"{s.host} {s.total:g}" for s in ranked[1:4]))
    if refused:
        reasons.append(f"refused: {listed}")
    return Placed(best.host, best.total, tuple(reasons), record)


def check_params(component: ComponentType, params: Mapping[str, object]) -> list[str]:
    """What is wrong with instance parameters: unknown or missing names, and each value by the one rule the
    checker applies to a mission's constants (`dsl.param_values.refuses`: type, negative duration, range)."""
    specs = {p.name: p for p in component.params}
    out = []
    for name, value in params.items():
        spec = specs.get(name)
        if spec is None:
            hint = did_you_mean(name, specs) or (f"parameters: {', '.join(specs)}" if specs else "it has none")
            out.append(f"unknown parameter {name} ({hint})")
        elif why := refuses(spec, value):
            out.append(f"parameter {name} {why}")
    out.extend(f"parameter {p.name} is required" for p in component.params if p.required and p.name not in params)
    return out


_ANY = ComponentType("", Kind.BEHAVIOR)


def _percent(value: float) -> float:
    return 100.0 if math.isnan(value) else min(100.0, max(0.0, value))


def _share(value: float) -> float:
    """A share clamped to 0-1 (NaN: none), so a caller's odd figure cannot outweigh the loads."""
    return 0.0 if math.isnan(value) else min(1.0, max(0.0, value))


def _listed(refused: Mapping[str, tuple[str, ...]]) -> str:
    return "; ".join(f"{name}: {', '.join(why)}" for name, why in sorted(refused.items()))


def _explain(best: Scored) -> str:
    """`c: score 11 = cpu 1*5 + memory 0.5*0 + instances 0.2*3*10` (then the bonuses that applied)."""
    cpu, memory, instances = (best.part(n) or Part(n, 0.0, 0.0) for n in ("cpu", "memory", "instances"))
    terms = (f"cpu {cpu.weight:g}*{cpu.value:g} + memory {memory.weight:g}*{memory.value:g}"
             f" + instances {instances.weight:g}*{instances.value / INSTANCE_SCALE:g}*{INSTANCE_SCALE:g}")
    preferred, near = best.part("preferred"), best.part("affinity")
    if preferred is not None and preferred.value:
        terms += f" - preferred {-preferred.points:g}"
    if near is not None and near.points:
        terms += f" - affinity {near.weight:g}*{-near.value:g}"
    return f"{best.host}: score {best.total:g} = {terms}"


def _versus(best: Scored, runner: Scored) -> str:
    """`score 2 vs spare 12: instances 10 vs 10, affinity -20 vs 0`: the parts that told them apart, most first."""
    gaps = sorted(((r.points - b.points, b, r) for b, r in zip(best.parts, runner.parts, strict=True)
                   if r.points != b.points), key=lambda g: (-abs(g[0]), g[1].plugin))
    said = ", ".join(f"{b.plugin} {b.points:.3g} vs {r.points:.3g}" for _gap, b, r in gaps[:2])
    if not said:
        return f"score {best.total:.3g}, tied with {runner.host}: the smaller name"
    return f"score {best.total:.3g} vs {runner.host} {runner.total:.3g}: {said}"


__all__ = ["AFFINITY_SCALE", "FILTERS", "INSTANCE_SCALE", "PREFER_BONUS", "SCORES", "Context", "Decision", "Filter",
           "HostView", "Outcome", "Part", "Placed", "Recent", "Score", "Scored", "Unplaceable", "check_params",
           "decide", "filtered", "parts", "place", "refusals", "refused_last", "required_devices", "running_count",
           "score", "shares", "total", "view_of", "with_more", "with_recent"]
