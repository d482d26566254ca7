"""What a component may emit: the events its manifest declares, with exactly their fields, of their types.

A mission's `on E` and its guards (`[event.size > 1.0]`) were checked against the manifests when it was compiled;
an emit that breaks the manifest would make them misfire at run time, blamed on the mission. So every emit of a
component is checked here, in the one place the dry-run and the cluster share (`drd.runtime.hosting`: a component
in a worker process has its events replayed there), and refused with an `EmitError` that names the component,
the event and the field. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from drd.errors import ComponentFailure
from drd.runtime.records import python_scalar
from dsl.catalog import RecordSpec


class EmitError(ComponentFailure, ValueError):
    """An emit its component's manifest does not allow: the emitting state fails with this reason."""


def check_emit(component: str, declared: Iterable[RecordSpec], name: str, fields: Mapping[str, Any]
               ) -> dict[str, Any]:
    """The fields of an event `component` emits, numpy scalars as the Python values they hold (`python_scalar`);
    refuse (EmitError) one that its manifest's `events` do not declare, or with a field missing, unknown or of the
    wrong type. Fields of a non-scalar type (a data type, a resource id) are checked for presence only."""
    fields = {k: python_scalar(v) for k, v in fields.items()}
    specs = {e.name: e for e in declared}
    spec = specs.get(name)
    if spec is None:
        have = ", ".join(sorted(specs)) or "none"
        raise EmitError(f"{component} emits {name}, which its manifest does not declare (its events: {have})")
    missing = [f for f in spec.fields if f not in fields]
    if missing:
        raise EmitError(f"{component} emits {name} without field {', '.join(missing)}"
                        f" (its manifest declares {_declared(spec)})")
    unknown = [f for f in fields if f not in spec.fields]
    if unknown:
        raise EmitError(f"{component} emits {name} with field {', '.join(unknown)}, which its manifest does not"
                        f" declare (it declares {_declared(spec)})")
    for field, type_ in spec.fields.items():
        value = fields[field]
        if not _fits(type_, value):
            raise EmitError(f"{component} emits {name} with {field}={value!r} ({type(value).__name__})"
                            f" where its manifest declares {field}: {type_}")
    return fields


def _declared(spec: RecordSpec) -> str:
    return ", ".join(f"{f}: {t}" for f, t in spec.fields.items()) or "no field"


def _fits(type_: str, value: Any) -> bool:
    """Whether `value` is of the scalar manifest type `type_` (any other type: yes). An int is a float, a bool is
    neither; a float is finite (a guard compares it)."""
    if type_ == "bool":
        return isinstance(value, bool)
    if type_ == "str":
        return isinstance(value, str)
    if type_ == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if type_ in ("float", "duration"):
        return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return True
