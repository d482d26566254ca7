"""Component manifests: `components/<Name>/manifest.yaml` loaded into a `dsl.catalog.Catalog`.

A manifest is the single description of a component type, so loading is strict: every
problem in every manifest is collected and raised once, as a `ManifestError`, and a broken
catalog is fixed in one pass. `parse_manifest` (one manifest) and `check_references`
(between manifests) are pure; only `load_catalog` touches the file system. Entry points
are checked for form only, never imported: a host imports just the drivers it runs.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from enum import Enum
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

import yaml

import components
from drd.config import (
    ConfigError,
    ConfigProblem,
    ConfigReader,
    TextError,
    display_path,
    load_yaml,
    read_config_text,
)
from drd.entrypoints import ENTRY_POINT
from dsl.ast import KEYWORDS, parse_duration
from dsl.catalog import (
    BUILTIN_PROPERTIES,
    SCALAR_TYPES,
    Catalog,
    ComponentType,
    InputSpec,
    Kind,
    Limit,
    NeedSpec,
    ParamSpec,
    Process,
    RecordSpec,
    Scheduling,
    inherit,
)
from dsl.errors import did_you_mean, edit_distance

MANIFEST = "manifest.yaml"
#: Extra component folders, os.pathsep-separated; later folders override earlier ones.
ENV_VAR = "DRD_COMPONENTS"

_COMMON = ("name", "kind", "description")
_RUNNABLE = ("entry_point", "process", "multiplicity", "scheduling", "params")
#: The keys each kind may use, in the order manifests write them.
_TYPE = ("abstract", "extends")  # type inheritance: a resource type is a kind of the abstract types it extends
KEYS: Mapping[Kind, tuple[str, ...]] = {
    Kind.BEHAVIOR: (*_COMMON, *_RUNNABLE, "movable", "needs", "inputs", "outputs", "events", "interfaces"),
    Kind.RC: (*_COMMON, *_TYPE, *_RUNNABLE, "interfaces", "sharable", "capacity", "properties", "limits"),
    Kind.ARC: (*_COMMON, *_TYPE, "properties", "limits", "parts"),
    Kind.DATA: (*_COMMON, "fields"),
}
REQUIRED: Mapping[Kind, tuple[str, ...]] = {
    Kind.BEHAVIOR: (*_COMMON, "entry_point"),
    Kind.RC: (*_COMMON, "entry_point", "interfaces"),
    Kind.ARC: (*_COMMON, "parts"),
    Kind.DATA: _COMMON,
}
#: The keys of an abstract type (`abstract: true`): properties for its subtypes, nothing to run or hold.
ABSTRACT_KEYS = (*_COMMON, *_TYPE, "properties", "limits")
#: Every manifest key, in canonical order (each kind's keys keep their order in it: the type keys come right
#: after the common ones, before a runnable's).
KEY_ORDER: tuple[str, ...] = tuple(dict.fromkeys((*_COMMON, *_TYPE, *(k for keys in KEYS.values() for k in keys))))

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_A = {Kind.BEHAVIOR: "a behavior", Kind.RC: "an rc", Kind.ARC: "an arc", Kind.DATA: "a data type"}
_PYTYPES: Mapping[str, Any] = {"int": int, "float": (int, float), "bool": bool, "str": str}
_E = TypeVar("_E", bound=Enum)


ManifestProblem = ConfigProblem


class ManifestError(ConfigError):
    """The component manifests have problems; carries all of them, from every manifest."""


# ---------------------------------------------------------------- one manifest (pure)


def parse_manifest(data: object, source: str) -> tuple[ComponentType | None, list[ManifestProblem]]:
    """Check one manifest's YAML data and convert it; `source` names it in problems.

    The type is built whenever name and kind are usable, even if other keys have problems,
    so that references to it from other manifests still resolve; any problem is fatal.
    """
    c = _Checker(source)
    if not isinstance(data, dict):
        c.fail("", f"expected a mapping of manifest keys, got {got(data)}")
        return None, c.problems
    # a misspelt kind (`behaviour`) is reported, and the rest is checked as the kind it is closest to, so that every
    # other problem of the file is reported with it (users audit 15, D8: its unknown types were not)
    kind = c.choice(data["kind"], "kind", Kind) or _closest(data["kind"], Kind) if "kind" in data else None
    allowed = KEYS[kind] if kind else KEY_ORDER
    abstract = data.get("abstract") is True and kind in (Kind.RC, Kind.ARC)
    if abstract:
        allowed = ABSTRACT_KEYS
    for key in data:
        if kind and key in KEY_ORDER and key not in allowed:
            c.fail(key, f"does not apply to {'an abstract' if abstract else _A[kind]} manifest")
        elif key not in allowed:
            c.fail(str(key), f"unknown key{_hint(str(key), allowed)}")
    for key in _COMMON if abstract else REQUIRED[kind] if kind else _COMMON:
        if key not in data:
            c.fail(key, "required key missing")
    name = c.name(data["name"], "name") if "name" in data else None
    if name in SCALAR_TYPES:
        c.fail("name", f"{name} is a built-in type")
        name = None
    fields = {k: parse(c, data[k], k) for k, parse in _PARSERS.items() if k in data and k in allowed}
    if kind is None or name is None:
        return None, c.problems
    _check_rules(c, kind, data, fields)
    return ComponentType(name=name, kind=kind, source=source, **fields), c.problems


def _closest(value: object, enum: type[_E]) -> _E | None:
    """The member of `enum` whose value `value` is a misspelling of: within two edits, as `did_you_mean` says."""
    text = str(value).lower()  # ties go to the first by name, as `did_you_mean`'s hint names it
    best = min(sorted(enum, key=lambda m: str(m.value)), key=lambda m: edit_distance(text, str(m.value)))
    return best if edit_distance(text, str(best.value)) <= 2 else None


def _check_rules(c: _Checker, kind: Kind, data: Mapping[str, Any], fields: Mapping[str, Any]) -> None:
    """Rules that tie keys of one manifest together."""
    if kind is Kind.RC and isinstance(data.get("interfaces"), list) and len(fields["interfaces"]) != 1:
        c.fail("interfaces", f"an rc implements exactly one interface, got {len(fields['interfaces'])}")
    if fields.get("movable") and data.get("needs"):  # its devices are on one host: it runs there
        c.fail("movable", "a behavior with device needs runs where its devices are: it cannot move")
    if fields.get("sharable") and data.get("capacity") is None:
        c.fail("capacity", "required when sharable is true")
    if not data.get("sharable") and data.get("capacity") is not None:
        c.fail("capacity", "only a sharable rc has a capacity")
    needs = {n.name for n in fields.get("needs", ())}
    for p in fields.get("params", ()):
        if p.property_of is not None and p.property_of not in needs:
            c.fail(f"params.{p.name}.property_of", f"{p.property_of!r} is not one of the behavior's needs"
                   + (f" ({', '.join(sorted(needs))})" if needs else ""))
    for clash in fields.get("properties", {}).keys() & fields.get("parts", {}).keys():
        c.fail(f"properties.{clash}", "also the name of a part")
    for name in fields.get("limits", {}):
        if fields.get("properties", {}).get(name) not in ("int", "float", "duration"):
            c.fail(f"limits.{name}", "limits a numeric property (int, float or duration) the manifest declares")


class _Checker(ConfigReader):
    """Collects the problems of one manifest; typed readers report and return a safe value."""

    def text(self, value: object, key: str) -> str:
        if isinstance(value, str):
            return value
        self.fail(key, f"expected a string, got {got(value)}")
        return ""

    def name(self, value: object, key: str) -> str | None:
        text = self.text(value, key)
        if text in KEYWORDS:
            self.fail(key, f"{text!r} is a reserved word of the mission language; choose another name")
            return None
        if _NAME.fullmatch(text):
            return text
        if isinstance(value, str):
            self.fail(key, f"{value!r} is not a name (letters, digits and _, not starting with a digit)")
        return None

    def names(self, value: object, key: str) -> tuple[str, ...]:
        if not isinstance(value, list):
            self.fail(key, f"expected a list of names, got {got(value)}")
            return ()
        return tuple(n for n in (self.name(v, key) for v in value) if n)

    def flag(self, value: object, key: str) -> bool:
        if isinstance(value, bool):
            return value
        self.fail(key, f"expected true or false, got {got(value)}")
        return False

    def positive(self, value: object, key: str, integer: bool = False) -> Any:
        if is_number(value, integer) and 0 < value < math.inf:  # type: ignore[operator]
            return value if integer else float(value)  # type: ignore[arg-type]
        self.fail(key, f"expected a positive {'integer' if integer else 'number'}, got {got(value)}")
        return None

    def choice(self, value: object, key: str, enum: type[_E]) -> _E | None:
        options = [str(m.value) for m in enum]
        if isinstance(value, str) and value in options:
            return enum(value)
        hint = _hint(str(value), options) or f" (expected one of {', '.join(options)})"
        self.fail(key, f"unknown {key} {show(value)}{hint}")
        return None

    def entries(self, value: object, key: str, item: type) -> Iterator[tuple[str, Any, str]]:
        """The (name, item, key path) of a mapping whose keys are names and items `item`s."""
        if not isinstance(value, dict):
            self.fail(key, f"expected a mapping, got {got(value)}")
            return
        for k, v in value.items():
            path = f"{key}.{k}"
            if self.name(k, path) is None:
                continue
            if isinstance(v, item):
                yield k, v, path
            else:
                self.fail(path, f"expected {'a mapping' if item is dict else 'a type name'}, got {got(v)}")


def _entry_point(c: _Checker, value: object, key: str) -> str | None:
    text = c.text(value, key)
    if text and not ENTRY_POINT.fullmatch(text):
        c.fail(key, f"expected 'package.module:Class', got {text!r}")
    return text or None


def _scheduling(c: _Checker, value: object, key: str) -> Scheduling:
    data = value if isinstance(value, dict) else {}
    if not isinstance(value, dict):
        c.fail(key, f"expected a mapping, got {got(value)}")
    c.keys(data, key, ("cores", "nice"))
    cores = data.get("cores")
    if cores is not None and not (isinstance(cores, list) and all(_is_core(n) for n in cores)):
        c.fail(f"{key}.cores", f"expected a list of core numbers or null, got {got(cores)}")
        cores = None
    nice = data.get("nice", 0)
    if not (is_number(nice, True) and -20 <= nice <= 19):
        c.fail(f"{key}.nice", f"expected an integer from -20 to 19, got {got(nice)}")
        nice = 0
    return Scheduling(None if cores is None else tuple(cores), nice)


def _params(c: _Checker, value: object, key: str) -> tuple[ParamSpec, ...]:
    out = []
    for name, spec, path in c.entries(value, key, dict):
        c.keys(spec, path, PARAM_KEYS, required=("type",))
        type_ = c.text(spec.get("type", ""), f"{path}.type")
        default = spec.get("default")
        if "default" in spec and type_ in SCALAR_TYPES:
            default = _default(c, default, type_, f"{path}.default")
        limit = _param_range(c, spec, path, type_)
        if limit is not None and isinstance(default, int | float) and not isinstance(default, bool):
            why = limit.refuses(float(default))
            if why:
                c.fail(f"{path}.default", f"{why}: a default must lie in its own range")
        description = c.text(spec.get("description", ""), f"{path}.description")
        of = c.text(spec["property_of"], f"{path}.property_of") or None if "property_of" in spec else None
        if of is not None and type_ != "str":
            c.fail(f"{path}.property_of", f"names a property: the parameter must be a str, not {type_}")
        out.append(ParamSpec(name, type_, default, "default" not in spec, description, limit, of))
    return tuple(out)


#: The keys of one parameter: its range (`min`, `max`, `unit`) is declared beside its type and default.
PARAM_KEYS = ("type", "default", "min", "max", "unit", "description", "property_of")
#: The parameter types that take a range.
NUMERIC = ("int", "float", "duration")


def _param_range(c: _Checker, spec: Mapping[str, Any], path: str, type_: str) -> Limit | None:
    """`speed: {type: float, min: 0, max: 2, unit: m/s}` -> Limit(0, 2, "m/s"); a duration's bounds are durations
    (`min: 0s, max: 24h`) and carry their unit. None when the parameter declares no range."""
    written = [k for k in ("min", "max", "unit") if k in spec]
    if not written:
        return None
    if type_ not in NUMERIC:
        if type_:
            c.fail(f"{path}.{written[0]}",
                   f"a range applies to a numeric parameter (int, float or duration), not {type_}")
        return None
    duration = type_ == "duration"
    if duration and "unit" in spec:
        c.fail(f"{path}.unit", "a duration's unit is written in its bounds (min: 0s, max: 24h)")
    low, high = _bounds(c, spec, path, duration)
    unit = "" if duration else c.text(spec.get("unit", ""), f"{path}.unit")
    return Limit(low, high, unit, duration)


def _bounds(c: _Checker, spec: Mapping[str, Any], path: str, duration: bool = False,
            ) -> tuple[float | None, float | None]:
    """A range's `min` and `max` (finite numbers, or durations), each None when not written, and not crossed."""
    bounds: list[float | None] = []
    for b in ("min", "max"):
        v = spec.get(b)
        if v is None:
            bounds.append(None)
        elif duration:
            seconds = parse_duration(v) if isinstance(v, str) else None
            if seconds is None:
                c.fail(f"{path}.{b}", f"expected a duration such as 0s or 24h, got {got(v)}")
            bounds.append(seconds)
        elif is_number(v) and math.isfinite(v):
            bounds.append(float(v))
        else:
            c.fail(f"{path}.{b}", f"expected a finite number, got {got(v)}")
            bounds.append(None)
    low, high = bounds
    if low is not None and high is not None and low > high:
        shown = Limit(duration=duration).show
        c.fail(path, f"min {shown(low)} is above max {shown(high)}")
        return None, None  # reported once: no value is then refused again for being outside it
    return low, high


def _default(c: _Checker, value: object, type_: str, key: str) -> object:
    """The default as a Python value: durations in seconds, ints widened for floats."""
    if type_ == "duration":
        seconds = parse_duration(value) if isinstance(value, str) else None
        if seconds is None:
            c.fail(key, f"expects a duration such as 60s or 250ms, got {got(value)}")
        return seconds
    if isinstance(value, bool) != (type_ == "bool") or not isinstance(value, _PYTYPES[type_]):
        c.fail(key, f"expects {type_}, got {got(value)}")
        return None
    if isinstance(value, float) and not math.isfinite(value):
        c.fail(key, f"expects a finite {type_}, got {got(value)}")
        return None
    return float(value) if type_ == "float" else value


def _needs(c: _Checker, value: object, key: str) -> tuple[NeedSpec, ...]:
    out = []
    for name, spec, path in c.entries(value, key, dict):
        c.keys(spec, path, ("type", "of", "quantity", "description"), required=("type",))
        quantity = spec.get("quantity")
        out.append(NeedSpec(
            name,
            c.text(spec.get("type", ""), f"{path}.type"),
            c.names(spec.get("of", []), f"{path}.of"),
            None if quantity is None else c.positive(quantity, f"{path}.quantity"),
            c.text(spec.get("description", ""), f"{path}.description"),
        ))
    return tuple(out)


def _records(c: _Checker, value: object, key: str) -> tuple[RecordSpec, ...]:
    out = []
    for name, spec, path in c.entries(value, key, dict):
        c.keys(spec, path, ("type", "fields", "description") if key == "outputs" else ("fields", "description"))
        fields = _typemap(c, spec.get("fields", {}), f"{path}.fields")
        description = c.text(spec.get("description", ""), f"{path}.description")
        type_ = c.text(spec.get("type", "record"), f"{path}.type") if key == "outputs" else "record"
        out.append(RecordSpec(name, fields, type_ or "record", description=description))
    return tuple(out)


def _inputs(c: _Checker, value: object, key: str) -> tuple[InputSpec, ...]:
    out = []
    for name, spec, path in c.entries(value, key, dict):
        c.keys(spec, path, ("type", "optional", "description"), required=("type",))
        out.append(InputSpec(name, c.text(spec.get("type", ""), f"{path}.type"),
                             c.flag(spec.get("optional", False), f"{path}.optional"),
                             c.text(spec.get("description", ""), f"{path}.description")))
    return tuple(out)


def _typemap(c: _Checker, value: object, key: str) -> dict[str, str]:
    return {name: type_ for name, type_, _ in c.entries(value, key, str)}


def _properties(c: _Checker, value: object, key: str) -> dict[str, str]:
    props = _typemap(c, value, key)
    for name in props.keys() & BUILTIN_PROPERTIES.keys():
        c.fail(f"{key}.{name}", f"{name} is built in: every resource has {' and '.join(BUILTIN_PROPERTIES)}")
    return props


def _limits(c: _Checker, value: object, key: str) -> dict[str, Limit]:
    """`limits: {beams: {min: 1, max: 4096}, max_range: {min: 0.1, max: 100, unit: m}}`."""
    out: dict[str, Limit] = {}
    for name, spec, path in c.entries(value, key, dict):
        c.keys(spec, path, ("min", "max", "unit"))
        low, high = _bounds(c, spec, path)
        out[name] = Limit(low, high, str(spec.get("unit", "")))
    return out


_Parser = Callable[[_Checker, Any, str], Any]
_PARSERS: dict[str, _Parser] = {
    "description": _Checker.text,
    "entry_point": _entry_point,
    "process": lambda c, v, k: c.choice(v, k, Process) or Process.CONTAINER,
    "multiplicity": lambda c, v, k: None if v is None else c.positive(v, k, integer=True),
    "scheduling": _scheduling,
    "params": _params,
    "needs": _needs,
    "inputs": _inputs,
    "outputs": _records,
    "fields": _typemap,
    "events": _records,
    "interfaces": _Checker.names,
    "sharable": _Checker.flag,
    "movable": _Checker.flag,
    "capacity": lambda c, v, k: None if v is None else c.positive(v, k),
    "properties": _properties,
    "limits": _limits,
    "parts": _typemap,
    "abstract": _Checker.flag,
    "extends": lambda c, v, k: c.names([v] if isinstance(v, str) else v, k),
}


# ---------------------------------------------------------------- between manifests (pure)


def check_references(types: Iterable[ComponentType]) -> list[ManifestProblem]:
    """Problems that need the whole catalog: unknown types, needs no ARC can serve, clashes."""
    by_name = {t.name: t for t in types}
    problems: list[ManifestProblem] = []
    events: dict[str, tuple[RecordSpec, ComponentType]] = {}
    for t in by_name.values():
        problems += _References(t, by_name).check()
        problems += _supertype_problems(t, by_name)
        for e in t.events:
            first, owner = events.setdefault(e.name, (e, t))
            if dict(first.fields) != dict(e.fields):
                message = f"fields differ from {e.name} in {owner.name} ({owner.source})"
                problems.append(ManifestProblem(t.source, f"events.{e.name}", message))
    return problems


def _replaced(source: str, user: str) -> bool:
    """Whether the type defined at `source` comes from another folder than drd's own and than the manifest that
    uses it (`user`): a folder given with -C/DRD_COMPONENTS replacing a standard type, which the errors of the
    standard manifests that use it must name, or nothing in them points at the user's file."""
    def folder(path: str) -> Path:
        p = Path(path)
        return p.parent.parent.resolve() if p.name == "manifest.yaml" else p

    own = Path(components.__file__).parent.resolve()
    return folder(source) not in (own, folder(user)) and folder(user) == own


def _supertype_problems(t: ComponentType, types: Mapping[str, ComponentType]) -> list[ManifestProblem]:
    """`extends`: known abstract types of the same kind, no cycle, and one type per inherited property."""
    out: list[ManifestProblem] = []
    for sup in t.extends:
        s = types.get(sup)
        if s is None:
            known = [n for n, o in types.items() if o.abstract and o.kind is t.kind]
            out.append(ManifestProblem(t.source, "extends", f"unknown type {sup!r}{_hint(sup, known)}"))
        elif s.kind is not t.kind or not s.abstract:
            what = f"{_A[s.kind]}, not {_A[t.kind]}" if s.kind is not t.kind else "not abstract"
            out.append(ManifestProblem(t.source, "extends", f"{sup} is {what}: a type extends abstract types of its"
                                       " own kind (abstract: true)"))
    cycle = _cycle(t.name, types)
    if cycle:
        out.append(ManifestProblem(t.source, "extends", f"a cycle: {' -> '.join(cycle)}"))
        return out
    declared: dict[str, tuple[str, str]] = {n: (ty, t.name) for n, ty in t.properties.items()}
    for sup in Catalog(types).supertypes(t.name):
        for name, type_ in getattr(types.get(sup), "properties", {}).items():
            first, owner = declared.setdefault(name, (type_, sup))
            if first != type_:
                out.append(ManifestProblem(t.source, f"properties.{name}" if owner == t.name else "extends",
                                           f"{name} is {first} in {owner} but {type_} in {sup}"))
    return out


def _cycle(name: str, types: Mapping[str, ComponentType]) -> list[str]:
    """The way back to `name` through `extends` (`Robot -> Machine -> Robot`), if there is one, else []."""
    path: list[str] = [name]
    seen: set[str] = set()

    def walk(at: str) -> bool:
        for sup in getattr(types.get(at), "extends", ()):
            path.append(sup)
            if sup == name:
                return True
            if sup not in seen:
                seen.add(sup)
                if walk(sup):
                    return True
            path.pop()
        return False

    return path if walk(name) else []


class _References:
    """Checks the type names one manifest uses against the other manifests."""

    def __init__(self, t: ComponentType, types: Mapping[str, ComponentType]) -> None:
        self.t, self.types = t, types
        self.problems: list[ManifestProblem] = []

    def fail(self, key: str, message: str) -> None:
        self.problems.append(ManifestProblem(self.t.source, key, message))

    def ref(self, type_: str, key: str, *kinds: Kind, scalars: bool = False) -> ComponentType | None:
        """The component `type_` names, if it exists and is of one of `kinds` (any if none)."""
        target = self.types.get(type_)
        wanted = " or ".join(_A[k] for k in kinds)
        if not type_ or (scalars and type_ in SCALAR_TYPES):
            return None
        if type_ in SCALAR_TYPES:
            self.fail(key, f"{type_} is a value type, expected {wanted}")
        elif target is None:
            known = [n for n, t in self.types.items() if not kinds or t.kind in kinds]
            known += SCALAR_TYPES if scalars else ()
            self.fail(key, f"unknown type {type_!r}{_hint(type_, known)}")
        elif kinds and target.kind not in kinds:  # a user's folder replaced a type this manifest uses: say where
            where = f" (defined in {target.source})" if _replaced(target.source, self.t.source) else ""
            self.fail(key, f"{type_} is {_A[target.kind]}{where}, expected {wanted}")
            return None
        return target

    def check(self) -> list[ManifestProblem]:
        t = self.t
        for p in t.params:
            target = self.ref(p.type, f"params.{p.name}.type", scalars=True)
            if target and not p.required and not isinstance(p.default, str):
                self.fail(f"params.{p.name}.default", f"expects a {p.type} id, got {got(p.default)}")
        for n in t.needs:
            self.need(n)
        for kind, records in (("outputs", t.outputs), ("events", t.events)):
            for r in records:
                for field, type_ in r.fields.items():
                    self.ref(type_, f"{kind}.{r.name}.fields.{field}", scalars=True)
        for r in t.outputs:
            if r.type != "record":
                self.ref(r.type, f"outputs.{r.name}.type", Kind.DATA)
        for spec in t.inputs:
            self.ref(spec.type, f"inputs.{spec.name}.type", Kind.DATA)
            if t.param(spec.name) is not None:
                self.fail(f"inputs.{spec.name}", "is a parameter too: an argument must mean one thing")
        for name, type_ in t.fields.items():
            self.ref(type_, f"fields.{name}", scalars=True)
        for name, type_ in t.properties.items():
            self.ref(type_, f"properties.{name}", scalars=True)
        for name, type_ in t.parts.items():
            self.concrete(self.ref(type_, f"parts.{name}", Kind.RC), f"parts.{name}")
        for i in t.interfaces:
            self.ref(i, "interfaces", Kind.RC)
        if t.kind is Kind.BEHAVIOR:
            for n in t.needs:
                if n.type not in t.interfaces and getattr(self.types.get(n.type), "kind", None) is Kind.RC:
                    self.fail("interfaces", f"does not list {n.type}, used by needs.{n.name}")
        return self.problems

    def concrete(self, target: ComponentType | None, key: str) -> ComponentType | None:
        """A part or a need names a type of devices or robots that exist, not an abstract one (`Robot`)."""
        if target is not None and target.abstract:
            self.fail(key, f"{target.name} is abstract: name one of its subtypes")
            return None
        return target

    def need(self, n: NeedSpec) -> None:
        key = f"needs.{n.name}"
        target = self.concrete(self.ref(n.type, f"{key}.type", Kind.RC, Kind.ARC), f"{key}.type")
        for arc_name in n.of:
            arc = self.ref(arc_name, f"{key}.of", Kind.ARC)
            hits = [p for p, ty in arc.parts.items() if ty == n.type] if arc and target else [""]
            if not hits:
                self.fail(f"{key}.of", f"{arc_name} has no {n.type} part")
            elif len(hits) > 1:
                self.fail(f"{key}.of", f"{arc_name} has several {n.type} parts ({', '.join(hits)})")
        if n.quantity is None or target is None:
            return
        if not target.sharable:
            self.fail(f"{key}.quantity", f"{n.type} is not sharable; only a sharable rc has a quantity")
        elif target.capacity is not None and n.quantity > target.capacity:
            self.fail(f"{key}.quantity", f"{n.quantity:g} exceeds the capacity of {n.type}"
                      f" ({target.capacity:g})")


# ---------------------------------------------------------------- loading (I/O)


def default_dirs() -> list[Path]:
    """The standard components, then the folders of `DRD_COMPONENTS`, later overriding earlier."""
    extra = os.environ.get(ENV_VAR, "").split(os.pathsep)
    return [Path(components.__file__).parent, *(Path(p).expanduser() for p in extra if p)]


def load_catalog(dirs: Sequence[Path] | None = None) -> Catalog:
    """Every `*/manifest.yaml` under `dirs` (default: `default_dirs()`), checked, as a Catalog.

    A later folder's component replaces an earlier one of the same name.

    Raises:
        ManifestError: with every problem of every manifest, once all have been read.
    """
    cwd = Path.cwd()
    problems: list[ManifestProblem] = []
    merged: dict[str, ComponentType] = {}
    for root in dict.fromkeys(Path(d).resolve() for d in (default_dirs() if dirs is None else dirs)):
        if not root.is_dir():
            problems.append(ManifestProblem(display_path(root, cwd), "", "no such component directory"))
            continue
        here: dict[str, ComponentType] = {}
        for path in sorted(root.glob(f"*/{MANIFEST}")):
            t, found = _read(path, display_path(path, cwd))
            problems += found
            if t is None:
                continue
            if t.name != path.parent.name:
                problems.append(ManifestProblem(t.source, "name", f"{t.name} does not match its folder"
                                                f" {path.parent.name}"))
            if t.name in here:
                problems.append(ManifestProblem(t.source, "name", f"duplicate component {t.name},"
                                                f" also in {here[t.name].source}"))
            here.setdefault(t.name, t)
        merged.update(here)
    problems += check_references(merged.values())
    if problems:
        raise ManifestError(sorted(problems, key=lambda p: p.file))
    return Catalog.of(inherit(merged.values()))


def _read(path: Path, source: str) -> tuple[ComponentType | None, list[ManifestProblem]]:
    try:
        stat = path.stat()
    except OSError as e:
        return None, [ManifestProblem(source, "", f"cannot read: {e}")]
    t, problems = _read_stamped(path, source, stat.st_mtime_ns, stat.st_size)
    return t, list(problems)


@lru_cache(maxsize=512)
def _read_stamped(path: Path, source: str, mtime_ns: int, size: int,
                  ) -> tuple[ComponentType | None, tuple[ManifestProblem, ...]]:
    """Parse one file, cached on its stamp: daemons and tests reload unchanged manifests often."""
    try:
        data = load_yaml(read_config_text(path))
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 1 if mark else None
        return None, (ManifestProblem(source, "", f"invalid YAML: {e.problem or e.context}", line),)
    except TextError as e:
        return None, (ManifestProblem(source, "", str(e), e.line),)
    except (OSError, ValueError, yaml.YAMLError) as e:
        return None, (ManifestProblem(source, "", f"cannot read: {e}"),)
    t, problems = parse_manifest(data, source)
    return t, tuple(problems)






# ---------------------------------------------------------------- small helpers


def is_number(value: object, integer: bool = False) -> bool:
    return isinstance(value, int if integer else (int, float)) and not isinstance(value, bool)


def _is_core(value: object) -> bool:
    return is_number(value, integer=True) and value >= 0  # type: ignore[operator]


def got(value: object) -> str:
    """How a wrong value is named in a message: `str 'fast'`, `null`, `a list`."""
    if value is None:
        return "null"
    if isinstance(value, dict | list):
        return "a mapping" if isinstance(value, dict) else "a list"
    return f"{type(value).__name__} {show(value)}"


#: A value echoed in a message is cut to this many characters, its length said (a pasted 1 MB string stays one
#: readable line).
SHOWN_CHARS = 60


def show(value: object) -> str:
    """`value` as a message shows it: whole when short, else its start and its length (a string's own length, not
    its quoted form's)."""
    text = repr(value) if isinstance(value, str) else str(value)
    if len(text) <= SHOWN_CHARS:
        return text
    size = len(value) if isinstance(value, str) else len(text)
    return f"{text[:SHOWN_CHARS - 1]}… ({size:,} characters)"


def _hint(value: str, candidates: Iterable[str]) -> str:
    hint = did_you_mean(value, candidates)
    return f" ({hint})" if hint else ""
