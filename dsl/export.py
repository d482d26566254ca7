"""The statechart as data for people and tools: JSON, Graphviz dot, Mermaid, one-line labels.

Pure string building; the CLI decides where it goes (and runs `dot` for SVG/PNG).
"""

from __future__ import annotations

import json
from typing import Any

from dsl import ast, printer
from dsl.dataflow import InputBinding
from dsl.statechart import ResourceNeed, State, Statechart, StateKind, Transition, waits_to_start

SCHEMA_VERSION = 1


def trigger_label(t: Transition) -> str:
    """`completion`, `when x > 1`, `on MotionDetected`, `on error`, `after 2min`, with guard and actions."""
    match t.kind:
        case ast.TriggerKind.CHANGE:
            out = f"when {printer.expr(t.condition)}" if t.condition is not None else "when"
        case ast.TriggerKind.EVENT:
            out = f"on {t.event}" + (f" from {t.sender}" if t.sender else "")
        case ast.TriggerKind.ERROR:
            out = "on error"
        case ast.TriggerKind.TIMEOUT:
            delay = t.delay
            out = f"after {printer.expr(delay) if isinstance(delay, ast.Expr) else _seconds(delay or 0.0)}"
        case _:
            out = ""
    if t.preallocate:
        out += " preallocate"
    if t.guard is not None:
        out += f" [{printer.expr(t.guard)}]"
    if t.actions:
        out += " / " + "; ".join(printer.action(a) for a in t.actions)
    return out.strip()


def state_label(s: State) -> str:
    """One line about a state: kind, component, policy, multiplicity, priority."""
    bits: list[str] = []
    if s.kind is StateKind.LEAF and (s.component != s.name or s.args):
        bits.append(f"{s.component}" + _args(s))
    elif s.kind is StateKind.MULTI and s.multiplicity is not None:
        m = s.multiplicity
        hi = "" if m.exact else ".." + ("*" if m.unbounded else printer.expr(m.high))  # type: ignore[arg-type]
        bits.append(f"{s.component}[{printer.expr(m.low)}{hi}]")
    elif s.kind in (StateKind.COMPOUND, StateKind.PARALLEL):
        if s.component != s.name.removesuffix("[*]") or s.args:
            bits.append(f"{s.component}" + _args(s))
        if s.policy is not None:
            bits.append(f"parallel {s.policy.value}" + (f" {s.until.rsplit('/', 1)[-1]}" if s.until else ""))
    if s.after:
        bits.append("after " + ", ".join(a.rsplit("/", 1)[-1] for a in s.after))
    if s.kind is not StateKind.FINAL:
        bits.append(f"priority {s.priority}")
    return " · ".join(bits)


def input_label(b: InputBinding) -> str:
    """`door ← FindNewDoor.door`, `visited ← shared visited (CorridorSurveillance)`, `n ← last(Tick.n)`."""
    source = (f"shared {b.field} ({b.state.rsplit('/', 1)[-1]})" if b.shared
              else f"{b.state.rsplit('/', 1)[-1]}.{b.field}")
    return f"{b.name} ← " + (f"last({source})" if b.last else source)


def need_label(n: ResourceNeed) -> str:
    out = f"{n.name}: {n.type}"
    if n.where is not None:  # of a bound need too: it must hold of the ancestor's resource, or the behavior fails
        out += f" where {printer.expr(n.where)}"
    if n.bound_to is not None:
        holder, name, part = n.bound_to
        out += f" ← {name}" + (f".{part}" if part else "")
    else:
        if n.reuse:
            out += " ← " + " or ".join(f"{name}.{part}" for _, name, part in n.reuse) + " if it qualifies, else asked"
        if n.quantity is not None:
            q = n.quantity
            out += f" quantity {printer.expr(q) if isinstance(q, ast.Expr) else f'{q:g}'}"
        if n.slice is not None:
            out += f" for {_seconds(n.slice)}"
    return out


def to_dict(chart: Statechart) -> dict[str, Any]:
    """A stable, versioned JSON form of the whole chart."""
    return {
        "schema": SCHEMA_VERSION,
        "mission": chart.name,
        "file": chart.file,
        "root": chart.root,
        "states": [_state_dict(s) for s in chart.walk()],
    }


def to_json(chart: Statechart) -> str:
    return json.dumps(to_dict(chart), indent=2, ensure_ascii=False)


def _state_dict(s: State) -> dict[str, Any]:
    return {
        "id": s.id,
        "name": s.name,
        "kind": s.kind.value,
        "parent": s.parent,
        "children": list(s.children),
        "initial": s.initial,
        "component": s.component,
        "args": {a.name: printer.expr(a.value) for a in s.args},
        "priority": s.priority,
        "policy": s.policy.value if s.policy else None,
        "until": s.until,
        "after": list(s.after),
        "multiplicity": _mult(s.multiplicity),
        "success": s.success,
        "needs": [{"name": n.name, "type": n.type, "bound_to": list(n.bound_to) if n.bound_to else None,
                   "where": printer.expr(n.where) if n.where is not None else None,
                   "quantity": (printer.expr(n.quantity) if isinstance(n.quantity, ast.Expr) else n.quantity),
                   "slice": n.slice} for n in s.needs],
        "shared": [{"name": n, "type": t} for n, t in s.shared],
        "inputs": [{"name": b.name, "from": b.state, "field": b.field, "shared": b.shared, "last": b.last}
                   for b in s.inputs],
        "entry": list(s.entry),
        "vars": [{"name": v.name, "type": v.type.name, "value": printer.expr(v.value) if v.value else None}
                 for v in s.vars],
        "transitions": [_transition_dict(t) for t in (*s.starts, *s.transitions)],
        "line": s.span.line,
    }


def _transition_dict(t: Transition) -> dict[str, Any]:
    return {
        "source": t.source, "target": t.target, "trigger": t.kind.value, "event": t.event,
        "condition": printer.expr(t.condition) if t.condition is not None else None,
        "delay": printer.expr(t.delay) if isinstance(t.delay, ast.Expr) else t.delay,
        "guard": printer.expr(t.guard) if t.guard is not None else None,
        "actions": [printer.action(a) for a in t.actions], "generated": t.generated,
    }


def _mult(m: ast.Multiplicity | None) -> dict[str, Any] | None:
    if m is None:
        return None
    return {"min": printer.expr(m.low),
            "max": None if m.unbounded else printer.expr(m.high if m.high is not None else m.low)}


def to_dot(chart: Statechart) -> str:
    """Graphviz: composite states as clusters, transitions as edges, start and final as dots."""
    out = ["digraph statechart {", '  compound=true; rankdir=LR; fontname="Helvetica";',
           '  node [shape=box, style="rounded,filled", fillcolor="#f4f6fb", fontname="Helvetica", fontsize=10];',
           '  edge [fontname="Helvetica", fontsize=9];']
    ids = {s.id: f"s{i}" for i, s in enumerate(chart.walk())}

    def anchor(sid: str) -> str:
        s = chart[sid]
        return ids[sid] + ("_in" if s.children and s.kind is not StateKind.FINAL else "")

    def emit(s: State, indent: str) -> None:
        label = _dot_escape(s.name + "\\n" + state_label(s) + "".join("\\n" + need_label(n) for n in s.needs)
                            + "".join("\\n" + input_label(b) for b in s.inputs))
        if s.kind is StateKind.FINAL:
            color = "#2e7d32" if s.success else "#c62828"
            out.append(f'{indent}{ids[s.id]} [label="{s.name}", shape=doublecircle, fillcolor="{color}", '
                       'fontcolor=white, width=0.3];')
            return
        if not s.children:
            out.append(f'{indent}{ids[s.id]} [label="{label}"];')
            return
        style = "dashed" if s.kind is StateKind.PARALLEL else "rounded"
        out.append(f"{indent}subgraph cluster_{ids[s.id]} {{")
        out.append(f'{indent}  label="{label}"; style="{style}"; color="#5c6bc0";')
        out.append(f'{indent}  {ids[s.id]}_in [shape=point, width=0.12, label=""];')
        for c in chart.children(s.id):
            if not waits_to_start(c):  # its transitions are drawn as the start's
                emit(c, indent + "  ")
        out.append(f"{indent}}}")
        for target, label in _starts(s):
            attrs = f' [label="{_dot_escape(label)}"]' if label else ""
            out.append(f"{indent}{ids[s.id]}_in -> {anchor(target)}{attrs};")

    emit(chart[chart.root], "  ")
    for t in chart.transitions():
        if waits_to_start(chart[t.source]):
            continue
        style = ", style=dashed, color=gray40" if t.generated else ""
        label = _dot_escape(trigger_label(t))
        clip = "".join(f", {end}=cluster_{ids[sid]}" for end, sid in (("ltail", t.source), ("lhead", t.target))
                       if chart[sid].children and chart[sid].kind is not StateKind.FINAL)
        out.append(f'  {anchor(t.source)} -> {anchor(t.target)} [label="{label}"{style}{clip}];')
    for s in chart.walk():  # data flow: a sibling's output to the input that reads it
        for b in s.inputs:
            if not b.shared and b.state in ids:
                clip = f", ltail=cluster_{ids[b.state]}" if chart[b.state].children else ""
                out.append(f'  {anchor(b.state)} -> {ids[s.id]} [label="{_dot_escape(b.field)}", style=dotted,'
                           f' color="#00897b", fontcolor="#00897b", constraint=false{clip}];')
    out.append("}")
    return "\n".join(out) + "\n"


def to_mermaid(chart: Statechart) -> str:
    """Mermaid `stateDiagram-v2` text (renders on GitHub and in most docs tools)."""
    ids = {s.id: f"s{i}" for i, s in enumerate(chart.walk())}
    out = ["stateDiagram-v2"]

    def emit(s: State, indent: str) -> None:
        label = _mm_escape(f"{s.name}: {state_label(s)}") if s.kind is not StateKind.FINAL else s.name
        out.append(f'{indent}state "{label}" as {ids[s.id]}')
        if not s.children:
            return
        out.append(f"{indent}state {ids[s.id]} {{")
        regions = [c for c in chart.children(s.id) if c.kind is not StateKind.FINAL]
        # Mermaid puts everything after the last `--` into the last region: a parallel state's
        # finals are drawn beside it instead, and its transitions cross the border.
        finals_outside = s.kind is StateKind.PARALLEL
        for i, c in enumerate(regions if finals_outside else list(chart.children(s.id))):
            if finals_outside and i > 0:
                out.append(f"{indent}  --")
            if not waits_to_start(c):  # its transitions are drawn as the start's
                emit(c, indent + "  ")
        edge_indent = indent if finals_outside else indent + "  "
        edges = [f"{indent}  [*] --> {ids[target]}" + (f" : {_mm_escape(label)}" if label else "")
                 for target, label in _starts(s)]
        for c in chart.children(s.id):
            if waits_to_start(c):
                continue
            for t in c.transitions:
                label = _mm_escape(trigger_label(t))
                arrow = f"{edge_indent}{ids[t.source]} --> {ids[t.target]}"
                edges.append(arrow + (f" : {label}" if label else ""))
            if c.kind is StateKind.FINAL and c.success and not finals_outside:
                edges.append(f"{edge_indent}{ids[c.id]} --> [*]")
        if not finals_outside:
            out.extend(edges)
        out.append(f"{indent}}}")
        if finals_outside:
            out.extend(f'{indent}state "{c.name}" as {ids[c.id]}' for c in chart.children(s.id)
                       if c.kind is StateKind.FINAL)
            out.extend(edges)

    emit(chart[chart.root], "  ")
    out.append(f"  [*] --> {ids[chart.root]}")
    return "\n".join(out) + "\n"


def _starts(s: State) -> list[tuple[str, str]]:
    """Where a composite starts, each with its start transition's label: its start transitions, or its initial
    child."""
    if s.starts:
        return [(t.target, trigger_label(t)) for t in s.starts]
    return [(s.initial, "")] if s.initial else []


def _args(s: State) -> str:
    return "(" + ", ".join(f"{a.name}: {printer.expr(a.value)}" for a in s.args) + ")" if s.args else ""


def _seconds(x: float) -> str:
    if x == 0:
        return "0s"  # as a mission writes it (`after 0s`), not `0ms`
    for unit, size in (("h", 3600), ("min", 60), ("s", 1)):
        if x >= size and x % size == 0:
            return f"{int(x // size)}{unit}"
    return f"{x * 1000:g}ms" if x < 1 else f"{x:g}s"


def _dot_escape(s: str) -> str:
    return s.replace("\\", "\\\\").replace('"', '\\"').replace("\\\\n", "\\n")


def _mm_escape(s: str) -> str:
    return s.replace('"', "'").replace(":", "∶").replace(";", ",").replace("{", "(").replace("}", ")")
