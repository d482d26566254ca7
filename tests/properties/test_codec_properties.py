"""Property test of the codec's promise (`drd.bus.messages`): a sender cannot emit what a receiver would refuse.

A message is a msgspec Struct, which does not check its fields when it is built: any Python value can sit in any
field. Whatever it holds, `encode` either refuses it (MalformedMessage, with a reason about the body) or writes
bytes that `decode` accepts, and the message decoded from them encodes again.
"""

from __future__ import annotations

from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from drd.bus import Message, message
from drd.bus.messages import MalformedMessage, decode, encode


@message("test.codec-props.leaf")
class Leaf(Message):
    name: str
    value: float | None = None


@message("test.codec-props.tree")
class Tree(Message):
    op: str
    count: int = 0
    ratio: float = 0.0
    flag: bool = False
    params: dict[str, Any] | None = None
    rank: list[int] | None = None
    scale: tuple[float, ...] = ()
    leaves: list[Leaf] | None = None
    best: Leaf | None = None
    free: Any = None


@message("test.codec-props.point")
class Point(Message):
    x: float
    y: float = 0.0


@message("test.codec-props.plain")
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
