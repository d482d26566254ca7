"""The Load Balancer's policy: which host should run a component. Pure: no I/O, no clock, no randomness.

The daemon gathers what it knows about every host into `HostView`s (its latest load report, its
devices, the instances it runs) and asks `place`. Only hosts that are up, not excluded (a start there
timed out), able to run the component (devices, core indices, the caller's affinity) and below the
component's cluster-wide multiplicity are eligible; among them the lowest weighted score wins, ties
going to the smaller host name. See docs/placement.md.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from drd.hosts import Host, Placement
from dsl.catalog import ComponentType, Kind, ParamSpec
from dsl.errors import did_you_mean

#: One running instance weighs as much as 10 percentage points of CPU or memory (before weighting).
INSTANCE_SCALE = 10.0
#: Subtracted from the score of a host the caller prefers (one of `prefer_hosts`).
PREFER_BONUS = 50.0


@dataclass(frozen=True, slots=True)
class HostView:
    """What the placer knows of one host: its last load report, hardware and running instances.

    `cpu` and `memory` are percentages (0-100); `devices` the RC types it has (`Camera`); `running`
    counts instances by component name; `cores` is None when unknown.
    """

    name: str
    cpu: float = 0.0
    memory: float = 0.0
    instances: int = 0
    up: bool = True
    devices: frozenset[str] = frozenset()
    running: Mapping[str, int] = field(default_factory=dict, hash=False)
    cores: int | None = None


def view_of(host: Host, *, cpu: float = 0.0, memory: float = 0.0, up: bool = True,
            running: Mapping[str, int] | None = None) -> HostView:
    """A `HostView` of a configured host: devices and cores from `hosts.yaml`, load from a report."""
    running = dict(running or {})
    return HostView(host.name, cpu, memory, sum(running.values()), up, frozenset(d.type for d in host.devices),
                    running, host.cores)


@dataclass(frozen=True, slots=True)
class Placed:
    """The chosen host, its score (lowest wins) and why: the score's terms, then the refused hosts."""

    host: str
    score: float
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Unplaceable:
    """No host can take the component. `reason` names every refused host and why (`refused` by host)."""

    reason: str
    refused: Mapping[str, tuple[str, ...]] = field(default_factory=dict, hash=False)


Decision = Placed | Unplaceable


def with_more(view: HostView, component: str, n: int = 1) -> HostView:
    """The view with `n` more instances of `component`: placements made since the host last reported, so that
    several placed in one cycle spread instead of all going to the host that looked emptiest."""
    running = {**view.running, component: view.running.get(component, 0) + n}
    return HostView(view.name, view.cpu, view.memory, view.instances + n, view.up, view.devices, running, view.cores)


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


def score(host: HostView, weights: Placement, preferred: bool = False) -> float:
    """`cpu*w.cpu + memory*w.memory + instances*10*w.instances`, minus `PREFER_BONUS` if preferred.

    Loads are clamped to 0-100 (an unknown, NaN, load counts as full) and instances to >= 0.
    """
    value = (weights.cpu * _percent(host.cpu) + weights.memory * _percent(host.memory)
             + weights.instances * max(0, host.instances) * INSTANCE_SCALE)
    return value - PREFER_BONUS if preferred else value


def refusals(component: ComponentType, host: HostView, *, cluster_count: int = 0,
             exclude: Collection[str] = (), affinity: Collection[str] | None = None) -> tuple[str, ...]:
    """Why `host` cannot run `component` (empty: it can). `cluster_count` is `running_count` of it."""
    if not host.up:
        return ("down",)
    out: list[str] = []
    if host.name in exclude:
        out.append("excluded (a start there failed or timed out)")
    missing = sorted(required_devices(component) - host.devices)
    if missing:
        out.append(f"no {', '.join(missing)} device{'s' if len(missing) > 1 else ''}")
    wanted = component.scheduling.cores
    if wanted and host.cores is not None and max(wanted) >= host.cores:
        out.append(f"has {host.cores} core{'s' if host.cores != 1 else ''}, the manifest pins core {max(wanted)}")
    if affinity is not None and host.name not in affinity:
        out.append(f"outside its affinity ({', '.join(sorted(affinity)) or 'none'})")
    limit = component.multiplicity
    if not out and limit is not None and cluster_count >= limit:  # cluster-wide: named where it is the only bar
        out.append(f"multiplicity {limit} reached")
    return tuple(out)


def place(component: ComponentType, candidates: Sequence[HostView], weights: Placement, *,
          params: Mapping[str, object] | None = None, prefer_hosts: Collection[str] = (),
          exclude: Collection[str] = (), affinity: Collection[str] | None = None) -> Decision:
    """Choose the host for one more instance of `component`, or say why none can take it.

    `params` are checked against the manifest's (unknown names, missing required ones, scalar types)
    before any host is considered; `exclude` are hosts where a start already timed out (the retry path);
    `affinity`, when given, restricts the choice to those hosts (where the behavior's robot lives).
    Candidates are taken by name: a name given twice keeps its first view.
    """
    problems = check_params(component, params or {})
    if problems:
        return Unplaceable(f"{component.name}: {'; '.join(problems)}")
    views: dict[str, HostView] = {}
    for h in candidates:
        views.setdefault(h.name, h)
    hosts = list(views.values())
    if not hosts:
        return Unplaceable(f"{component.name}: no hosts known")
    count = running_count(component.name, hosts)
    refused = {h.name: r for h in hosts if (r := refusals(component, h, cluster_count=count, exclude=exclude,
                                                          affinity=affinity))}
    eligible = [h for h in hosts if h.name not in refused]
    listed = "; ".join(f"{name}: {', '.join(why)}" for name, why in sorted(refused.items()))
    if not eligible:
        return Unplaceable(f"no host can run {component.name}: {listed}", refused)
    ranked = sorted((score(h, weights, h.name in prefer_hosts), h.name, h) for h in eligible)
    best, name, host = ranked[0]
    reasons = [_explain(host, weights, best, name in prefer_hosts)]
    if len(ranked) > 1:
        reasons.append("next: " + ", ".join(f"{n} {s:g}" for s, n, _ in ranked[1:4]))
    if refused:
        reasons.append(f"refused: {listed}")
    return Placed(name, best, tuple(reasons))


def check_params(component: ComponentType, params: Mapping[str, object]) -> list[str]:
    """What is wrong with instance parameters: unknown or missing names, values of the wrong scalar type."""
    specs = {p.name: p for p in component.params}
    out = []
    for name, value in params.items():
        spec = specs.get(name)
        if spec is None:
            hint = did_you_mean(name, specs) or (f"parameters: {', '.join(specs)}" if specs else "it has none")
            out.append(f"unknown parameter {name} ({hint})")
        elif not _fits(spec, value):
            out.append(f"parameter {name} expects {spec.type}, got {type(value).__name__} {value!r}")
    out.extend(f"parameter {p.name} is required" for p in component.params if p.required and p.name not in params)
    return out


def _fits(spec: ParamSpec, value: object) -> bool:
    """Scalars are checked; resource and data types (ids chosen by the executive) are left to the Creator."""
    number = isinstance(value, int | float) and not isinstance(value, bool)
    checks = {"int": isinstance(value, int) and not isinstance(value, bool), "float": number,
              "duration": number, "bool": isinstance(value, bool), "str": isinstance(value, str)}
    return checks.get(spec.type, True)


def _percent(value: float) -> float:
    return 100.0 if math.isnan(value) else min(100.0, max(0.0, value))


def _explain(host: HostView, weights: Placement, total: float, preferred: bool) -> str:
    terms = (f"cpu {weights.cpu:g}*{_percent(host.cpu):g} + memory {weights.memory:g}*{_percent(host.memory):g}"
             f" + instances {weights.instances:g}*{max(0, host.instances)}*{INSTANCE_SCALE:g}")
    bonus = f" - preferred {PREFER_BONUS:g}" if preferred else ""
    return f"{host.name}: score {total:g} = {terms}{bonus}"


__all__ = ["INSTANCE_SCALE", "PREFER_BONUS", "Decision", "HostView", "Placed", "Unplaceable", "check_params",
           "place", "refusals", "required_devices", "running_count", "score", "view_of", "with_more"]
