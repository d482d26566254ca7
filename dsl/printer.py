"""AST back to mission text: canonical layout, minimal parentheses.

Used to show guards and actions in `missionctl plan`, and by the round-trip property
`parse(pretty(ast)) == ast`, which pins the grammar and the AST to each other.
"""

from __future__ import annotations

from dsl import ast

# Binding strength of each operator: higher binds tighter.
_PREC = {"or": 1, "and": 2, "not": 3, "==": 4, "!=": 4, "<": 4, "<=": 4, ">": 4, ">=": 4,
         "+": 5, "-": 5, "*": 6, "/": 6, "%": 6, "neg": 7}
_ATOM = 8


def expr(e: ast.Expr) -> str:
    """An expression as source text."""
    return _expr(e)[0]


def _expr(e: ast.Expr) -> tuple[str, int]:
    match e:
        case ast.Literal(value=bool(v)):
            return ("true" if v else "false"), _ATOM
        case ast.Literal(value=str(v)):
            return string(v), _ATOM
        case ast.Literal(value=float(v)):
            return _float(v), _ATOM
        case ast.Literal(value=v):
            return str(v), _ATOM
        case ast.Duration(text=t):
            return t, _ATOM
        case ast.Interp(parts=parts):
            inner = "".join(_escape(p) if isinstance(p, str) else "{" + expr(p) + "}" for p in parts)
            return f'"{inner}"', _ATOM
        case ast.Name(id=n):
            return n, _ATOM
        case ast.Attr(obj=o, attr=a):
            return f"{_wrap(o, _ATOM)}.{a}", _ATOM
        case ast.Call(func=f, args=args, where=w):
            shown = [expr(a) for a in args]
            if w is not None and shown:
                shown[0] += f" where {expr(w)}"
            return f"{f}({', '.join(shown)})", _ATOM
        case ast.Unary(op="not", operand=x):
            return f"not {_wrap(x, _PREC['not'])}", _PREC["not"]
        case ast.Unary(op=_, operand=x):
            return f"-{_wrap(x, _PREC['neg'])}", _PREC["neg"]
        case ast.Binary(op=op, left=lhs, right=rhs):
            p = _PREC[op]
            if p == 4:  # comparisons do not chain: both sides must bind tighter
                return f"{_wrap(lhs, p + 1)} {op} {_wrap(rhs, p + 1)}", p
            return f"{_wrap(lhs, p)} {op} {_wrap(rhs, p + 1)}", p
    raise TypeError(f"not an expression: {e!r}")


def _wrap(e: ast.Expr, need: int) -> str:
    text, prec = _expr(e)
    return text if prec >= need else f"({text})"


def _float(v: float) -> str:
    text = repr(v)
    return text if "." in text or "e" in text or "inf" in text or "nan" in text else text + ".0"


def _escape(s: str) -> str:
    out = s.replace("\\", "\\\\").replace('"', '\\"').replace("{", "\\{").replace("}", "\\}")
    return out.replace("\n", "\\n").replace("\t", "\\t")


def string(s: str) -> str:
    return f'"{_escape(s)}"'


def action(a: ast.Action) -> str:
    match a:
        case ast.SetAction(name=n, value=v):
            return f"set {n} = {expr(v)}"
        case ast.EmitAction(event=ev, args=args):
            return f"emit {ev}" + (_args(args) if args is not None else "")
        case ast.ReleaseAction(resource=r):
            return f"release({r})"
        case ast.LogAction(message=m):
            return f"log {expr(m)}"
    raise TypeError(f"not an action: {a!r}")


def _args(args: tuple[ast.Arg, ...]) -> str:
    return "(" + ", ".join(f"{a.name}: {expr(a.value)}" for a in args) + ")"


def child(c: ast.Child) -> str:
    out = c.name + (_args(c.args) if c.args is not None else "")
    if c.mult is not None:
        m = c.mult
        hi = "" if m.exact else ".." + ("*" if m.unbounded else expr(m.high))  # type: ignore[arg-type]
        out += f"[{expr(m.low)}{hi}]"
    if c.alias:
        out += f" as {c.alias}"
    if c.priority is not None:
        out += f" priority {c.priority}"
    return out


def transition(t: ast.Transition) -> str:
    out = f"{t.source} -> {t.target}" + (" preallocate" if t.preallocate else "")
    match t.kind:
        case ast.TriggerKind.CHANGE:
            out += f" when {expr(t.condition)}"  # type: ignore[arg-type]
        case ast.TriggerKind.EVENT:
            out += f" on {t.event}" + (f" from {t.sender}" if t.sender else "")
        case ast.TriggerKind.ERROR:
            out += " on error"
        case ast.TriggerKind.TIMEOUT:
            out += f" after {expr(t.delay)}"  # type: ignore[arg-type]
    if t.guard is not None:
        out += f" [{expr(t.guard)}]"
    if t.actions:
        out += " / " + "; ".join(action(a) for a in t.actions)
    return out


def item(i: ast.Item, indent: str) -> list[str]:
    match i:
        case ast.Need(name=n, type=ty, where=w, quantity=q, slice=s):
            out = f"needs {n}: {ty.name}"
            out += f" where {expr(w)}" if w is not None else ""
            out += f" quantity {expr(q)}" if q is not None else ""
            out += f" for {s.text}" if s is not None else ""
            return [indent + out]
        case ast.Shared(name=n, type=ty):
            return [f"{indent}shared {n}: {ty.name}"]
        case ast.Var(name=n, type=ty, value=v):
            return [f"{indent}var {n}: {ty.name}" + (f" = {expr(v)}" if v is not None else "")]
        case ast.Child():
            return [indent + child(i)]
        case ast.Parallel(policy=p, until=u, explicit=explicit, children=kids):
            head = "parallel" + (f" {p.value}" if explicit else "") + (f" {u}" if u else "")
            return [f"{indent}{head} {{", *(indent + "    " + child(k) for k in kids), indent + "}"]
        case ast.Transition():
            return [indent + transition(i)]
        case ast.Plan(concurrent=c, chains=chains, preallocate=pre):
            head = "plan" + (" concurrent" if c else "") + (" preallocate" if pre else "") + " {"
            body = [indent + "    " + " < ".join(s.name for s in ch) for ch in chains]
            return [indent + head, *body, indent + "}"]
        case ast.Constraint(name=n, condition=cond):
            return [f"{indent}constraint {n}: {expr(cond)}"]
    raise TypeError(f"not an item: {i!r}")


def behavior(b: ast.Behavior) -> str:
    if b.is_mission:
        head = f"mission {b.name}" + (f" priority {b.priority}" if b.priority is not None else "")
    else:
        params = ", ".join(f"{p.name}: {p.type.name}" + (f" = {expr(p.default)}" if p.default is not None else "")
                           for p in b.params)
        head = f"behavior {b.name}" + (f"({params})" if b.params else "")
        head += f" priority {b.priority}" if b.priority is not None else ""
    lines = [head + " {"]
    for i in b.body:
        lines.extend(item(i, "    "))
    return "\n".join([*lines, "}"])


def pretty(f: ast.MissionFile) -> str:
    """A whole file in canonical layout."""
    parts = [f"import {string(i.path)}" for i in f.imports]
    parts.extend(behavior(b) for b in f.behaviors)
    return "\n\n".join(parts) + "\n"
