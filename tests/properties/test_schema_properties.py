"""Property tests of the message schema (`drd.bus.schema`): the compiled converters against a plain reading of
the annotations.

The converters take shortcuts on the hot path (an optional field's None skips its converter, ``dict[str, Any]``
and ``list[Any]`` are checked without being copied); a reference checker written as the schema reads says
which JSON bodies fit, and `decode` must accept exactly those, build what they say, and refuse the others
with a MalformedMessage.
"""

from __future__ import annotations

import json
import types
import typing
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.bus import Message, message
from drd.bus.messages import MalformedMessage, decode, encode
from drd.bus.schema import SCHEMAS


@message("test.schema.leaf")
class Leaf(Message):
    name: str
    value: float | None = None


@message("test.schema.tree")
class Tree(Message):
    op: str
    count: int = 0
    ratio: float = 0.0
    flag: bool = False
    params: dict[str, Any] | None = None
    epochs: dict[str, int | None] | None = None
    rank: list[int] | None = None
    events: list[list[Any]] | None = None
    logs: list[str] | None = None
    mixed: int | str | None = None
    scale: tuple[float, ...] = ()
    leaves: list[Leaf] | None = None
    best: Leaf | None = None
    free: Any = None


def fits(v: Any, tp: Any) -> bool:
    """Does the decoded JSON value `v` fit annotation `tp`? The schema as its docstring states it."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return True
    if tp is float:
        return type(v) in (float, int)
    if tp in (str, int, bool, type(None)):
        return type(v) is tp
    if origin in (typing.Union, types.UnionType):
        return any(fits(v, a) for a in args)
    if origin in (list, tuple):
        return type(v) is list and all(fits(x, args[0]) for x in v)
    if origin is dict:
        return type(v) is dict and all(fits(x, args[1]) for x in v.values())
    fields = dict(SCHEMAS[tp])
    return type(v) is dict and v.keys() == fields.keys() and all(fits(v[k], fields[k]) for k in fields)


def built(v: Any, tp: Any) -> Any:
    """What `decode` must build from a fitting `v`: ints become floats where a float is expected, lists
    become tuples for tuple annotations, objects become message instances."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or v is None:
        return v
    if tp is float:
        return float(v)
    if origin in (typing.Union, types.UnionType):
        return built(v, next(a for a in args if fits(v, a)))
    if origin in (list, tuple):
        items = [built(x, args[0]) for x in v]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        return {k: built(x, args[1]) for k, x in v.items()}
    if tp in SCHEMAS:
        return tp(**{k: built(v[k], a) for k, a in SCHEMAS[tp]})
    return v


json_scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**31), 2**31),
                         st.floats(allow_nan=False, allow_infinity=False, width=32), st.text(max_size=4))
json_values = st.recursive(json_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=3), inner, max_size=3)), max_leaves=8)


def valid(tp: Any) -> st.SearchStrategy[Any]:
    """JSON values that fit `tp` (mixed with arbitrary ones by the callers, to reach both sides)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return json_values
    if tp is float:
        return st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=32), st.integers(-100, 100))
    if tp in (str, int, bool, type(None)):
        return {str: st.text(max_size=4), int: st.integers(-100, 100), bool: st.booleans(),
                type(None): st.none()}[tp]
    if origin in (typing.Union, types.UnionType):
        return st.one_of(*(valid(a) for a in args))
    if origin in (list, tuple):
        return st.lists(valid(args[0]), max_size=3)
    if origin is dict:
        return st.dictionaries(st.text(max_size=3), valid(args[1]), max_size=3)
    return bodies(tp)


def bodies(cls: type, wild: float = 0.0) -> st.SearchStrategy[dict[str, Any]]:
    """Bodies of `cls`: each field valid or (with `wild`) any JSON value, sometimes a field missing or extra."""
    def field(tp: Any) -> st.SearchStrategy[Any]:
        return st.one_of(valid(tp), json_values) if wild else valid(tp)

    fixed = st.fixed_dictionaries({name: field(tp) for name, tp in SCHEMAS[cls]})
    if not wild:
        return fixed
    return st.one_of(fixed, fixed.flatmap(lambda d: st.sampled_from(sorted(d)).map(
        lambda k: {n: x for n, x in d.items() if n != k})), fixed.map(lambda d: {**d, "unknown": 1}))


def envelope(body: Any) -> bytes:
    return json.dumps({"v": 1, "type": "test.schema.tree", "body": body}).encode()


@settings(max_examples=300, deadline=None)
@given(bodies(Tree, wild=0.3))
def test_decode_accepts_exactly_the_bodies_that_fit_and_builds_what_they_say(body: dict[str, Any]) -> None:
    data = envelope(body)
    if fits(body, Tree):
        msg = decode(data)
        assert msg == built(body, Tree)
        assert decode(encode(msg)) == msg
    else:
        try:
            decode(data)
        except MalformedMessage as e:
            assert e.reason.startswith("body")
        else:
            raise AssertionError(f"accepted a body that does not fit: {body!r}")


@settings(max_examples=200, deadline=None)
@given(bodies(Tree))
def test_encode_of_a_decoded_message_gives_the_same_json_back(body: dict[str, Any]) -> None:
    msg = decode(envelope(body))
    again = json.loads(encode(msg))["body"]
    assert fits(again, Tree) and decode(envelope(again)) == msg


def test_encode_refuses_a_non_string_key_in_a_free_dict_and_names_the_field() -> None:
    try:
        encode(Tree("x", params={1: "one"}))  # type: ignore[dict-item]
    except MalformedMessage as e:
        assert e.reason == "body.params: expected dict[str, Any] | null, got dict", e.reason
    else:
        raise AssertionError("a dict with an int key was encoded")
    try:
        encode(Tree("x", free={1: "one"}))  # free is Any: the JSON encoder is what refuses
    except MalformedMessage as e:
        assert e.reason.startswith("body:"), e.reason
    else:
        raise AssertionError("a dict with an int key was encoded")


# --- a sender cannot emit what a receiver would refuse -------------------------------------------------
# A message is a msgspec Struct, which does not check its fields when it is built: any Python value can sit in any
# field. Whatever it holds, `encode` either refuses it (MalformedMessage, with a reason about the body) or writes
# bytes that `decode` accepts, and the message decoded from them encodes again.


@message("test.schema.point")
class Point(Message):
    x: float
    y: float = 0.0


@message("test.schema.plain")
class Plain(Message):  # no dict, no Any, no null: written by msgspec alone, with no check in Python first
    count: int
    ratio: float
    names: list[str]
    at: Point


scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.text(max_size=3),
                    st.binary(max_size=3))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=3), st.lists(inner, max_size=3).map(tuple), st.frozensets(st.integers(), max_size=2),
    st.dictionaries(st.one_of(st.text(max_size=2), st.integers()), inner, max_size=2),
    st.builds(Leaf, st.one_of(st.text(max_size=2), inner), st.one_of(st.floats(), inner)),
    st.builds(Point, st.one_of(st.floats(), inner), st.one_of(st.floats(), inner))), max_leaves=6)


def emitted_is_accepted(msg: Message) -> None:
    try:
        data = encode(msg)
    except MalformedMessage as e:
        assert e.reason.startswith("body"), e.reason
        return
    back = decode(data)  # raises if a receiver would refuse what was sent
    assert type(back) is type(msg) and decode(encode(back)) == back


@settings(max_examples=400, deadline=None)
@given(st.fixed_dictionaries(dict.fromkeys(Tree.__struct_fields__, values)))
def test_whatever_a_tree_holds_encode_refuses_it_or_a_receiver_accepts_it(fields: dict[str, Any]) -> None:
    emitted_is_accepted(Tree(**fields))


@settings(max_examples=300, deadline=None)
@given(st.fixed_dictionaries(dict.fromkeys(Plain.__struct_fields__, values)))
def test_whatever_a_plain_message_holds_encode_refuses_it_or_a_receiver_accepts_it(fields: dict[str, Any]) -> None:
    emitted_is_accepted(Plain(**fields))
