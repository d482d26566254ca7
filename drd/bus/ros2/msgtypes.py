"""ROS 2 message types through ``rosbags``: classes, CDR bytes and RIHS01 type hashes, with no ROS installed.

rosbags ships the Jazzy standard messages (``Stores.ROS2_JAZZY``) and computes the RIHS01 hash rmw_zenoh puts in
every key (``rosidl_stringify_type_hash`` in rmw_zenoh_cpp's ``rmw_publisher_data.cpp``). Its ``serialize_cdr``
writes the payload rmw_zenoh sends: the 4-byte encapsulation header, then little-endian CDR. No serializer here.
:meth:`MessageTypes.make` only fills in what a caller leaves out (zeros, empty strings, nested defaults) and
turns plain lists of numbers into the numpy arrays rosbags wants.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

#: numpy dtypes of ROS 2 primitive types, for arrays (rosbags reads and writes them as numpy arrays).
_DTYPES: dict[str, type[np.generic]] = {
    "bool": np.bool_, "byte": np.uint8, "octet": np.uint8, "char": np.uint8, "uint8": np.uint8, "int8": np.int8,
    "uint16": np.uint16, "int16": np.int16, "uint32": np.uint32, "int32": np.int32, "uint64": np.uint64,
    "int64": np.int64, "float32": np.float32, "float64": np.float64,
}
_STRINGS = ("string", "wstring")
#: Default values the .msg files give and rosbags does not keep (the others are zero, empty, false).
_MSG_DEFAULTS: dict[str, dict[str, Any]] = {"geometry_msgs/msg/Quaternion": {"w": 1.0}}
#: A type's plan for `MessageTypes.make`: class, field names, .msg defaults, and per field (name, descriptor,
#: constant default, or the function that makes a fresh one: nested messages and arrays are never shared).
_Plan = tuple[Any, frozenset[str], dict[str, Any], tuple[tuple[str, Any, Any, Any], ...]]


class MessageTypes:
    """One rosbags type store: message classes by ROS 2 name, CDR both ways, type hashes (cached)."""

    def __init__(self, store: Typestore | None = None) -> None:
        self.store = store if store is not None else get_typestore(Stores.ROS2_JAZZY)
        self._lock = threading.Lock()
        self._hashes: dict[str, str] = {}
        self._plans: dict[str, _Plan] = {}

    def known(self, type_name: str) -> bool:
        return type_name in self.store.types

    def check(self, type_name: str) -> str:
        """The name, or a ValueError that says the type is not in the store (and how to add one)."""
        if not self.known(type_name):
            raise ValueError(f"unknown ROS 2 message type {type_name!r}: not in rosbags' Jazzy types; "
                             "register its .msg definition first (MessageTypes.register)")
        return type_name

    def register(self, type_name: str, msgdef: str) -> None:
        """Add a type from its ``.msg`` text (e.g. ``vision_msgs/msg/Detection2D``, not shipped by rosbags)."""
        with self._lock:
            self.store.register(get_types_from_msg(msgdef, type_name))
            self._hashes.clear()
            self._plans = {}

    def type_hash(self, type_name: str) -> str:
        """``RIHS01_<sha256 hex>``, as rmw_zenoh puts it in keys and tokens."""
        with self._lock:
            if type_name not in self._hashes:
                self._hashes[type_name] = self.store.hash_rihs01(self.check(type_name))
            return self._hashes[type_name]

    def serialize(self, message: object, type_name: str) -> bytes:
        """The CDR payload (encapsulation header included) of a message object of ``type_name``."""
        return bytes(self.store.serialize_cdr(message, type_name))

    def deserialize(self, data: bytes | memoryview, type_name: str) -> Any:
        """A message object from a CDR payload."""
        return self.store.deserialize_cdr(data, type_name)

    def make(self, type_name: str, **fields: Any) -> Any:
        """A message of ``type_name`` with the fields given and defaults for the others.

        A nested message may be given as a mapping of its fields; a number array as any sequence.
        """
        plan = self._plans.get(type_name) or self._plan(type_name)
        cls, names, defaults, slots = plan
        if not fields.keys() <= names:
            unknown = set(fields) - names
            raise ValueError(f"{type_name} has no field {', '.join(sorted(unknown))}")
        if defaults:
            fields = {**defaults, **fields}
        values = []
        for name, desc, constant, fresh in slots:
            if name in fields:
                value = fields[name]
                values.append(value if desc[0] == Nodetype.BASE else self._value(desc, value))
            else:
                values.append(constant if fresh is None else fresh(desc))
        return cls(*values)

    def _plan(self, type_name: str) -> _Plan:
        """How ``make`` builds a ``type_name`` (its class, field names, and per field a constant default or how to
        make a fresh one), worked out once: a message built every control cycle should not re-read its definition."""
        cls = self.store.types[self.check(type_name)]
        _consts, fielddefs = self.store.fielddefs[type_name]
        slots: list[tuple[str, Any, Any, Any]] = []
        for name, desc in fielddefs:
            if desc[0] == Nodetype.BASE:
                slots.append((name, desc, self._default(desc), None))
            else:
                slots.append((name, desc, None, self._default))
        plan = (cls, frozenset(name for name, _ in fielddefs), _MSG_DEFAULTS.get(type_name, {}), tuple(slots))
        with self._lock:
            self._plans[type_name] = plan
        return plan

    def _default(self, desc: tuple[Any, Any]) -> Any:
        kind, rest = desc
        if kind == Nodetype.BASE:
            return "" if rest[0] in _STRINGS else _DTYPES[rest[0]](0).item()
        if kind == Nodetype.NAME:
            return self.make(rest)
        element, size = rest
        if element[0] == Nodetype.BASE and element[1][0] in _DTYPES:
            return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_DTYPES[element[1][0]])
        return [self._default(element) for _ in range(size if kind == Nodetype.ARRAY else 0)]

    def _value(self, desc: tuple[Any, Any], value: Any) -> Any:
        kind, rest = desc
        if kind == Nodetype.NAME and isinstance(value, Mapping):
            return self.make(rest, **value)
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            element, size = rest
            if kind == Nodetype.ARRAY and len(value) != size:
                raise ValueError(f"a fixed array of {size} takes {size} values, not {len(value)}")
            if element[0] == Nodetype.BASE and element[1][0] in _DTYPES:
                return np.asarray(value, dtype=_DTYPES[element[1][0]])
            return [self._value(element, v) for v in value]
        return value


@functools.cache
def jazzy() -> MessageTypes:
    """The process's shared Jazzy type store (building one takes ~50 ms)."""
    return MessageTypes()
