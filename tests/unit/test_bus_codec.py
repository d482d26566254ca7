"""The msgspec codec's own rules (drd.bus.messages, drd.bus.schema), beside the contract's malformed-input table.

- every field is on the wire, defaulted or not, and no other: msgspec alone would fill a default and ignore an
  unknown field;
- a non-finite float is refused where null is allowed too (it would be written as null and read back as None);
- what msgspec cannot decode, and what orjson would not write, is refused when the class is defined;
- decode builds only the registered classes, runs their ``__post_init__``, and turns its refusal into a reason;
- encode's reason names the field even where the bytes could not show it, and no key that is not a string
  goes out as one.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import pytest

from drd.bus import Message, message
from drd.bus.messages import MalformedMessage, decode, encode
from drd.bus.schema import wire_struct


@message("test.codec.point")
class Point(Message):
    x: float
    y: float = 0.0


@message("test.codec.reading")
class Reading(Message):
    value: float | None = None
    values: list[float | None] | None = None
    at: Point | None = None


@message("test.codec.tagged")
class Tagged(Message):
    tags: dict[str, str]
    free: Any = None


@message("test.codec.checked")
class Checked(Message):
    count: int

    def __post_init__(self) -> None:
        if self.count < 0:
            raise ValueError(f"count must not be negative, got {self.count}")


def env(body: object, type_name: str) -> bytes:
    return json.dumps({"v": 1, "type": type_name, "body": body}).encode()


def test_a_defaulted_field_must_still_be_sent() -> None:
    with pytest.raises(MalformedMessage) as info:
        decode(env({"x": 1.0}, "test.codec.point"))
    assert info.value.reason == "body: missing field 'y' of test.codec.point"
    assert decode(env({"x": 1, "y": 2}, "test.codec.point")) == Point(1.0, 2.0)


def test_a_nested_unknown_field_is_refused_with_its_path() -> None:
    with pytest.raises(MalformedMessage) as info:
        decode(env({"value": None, "values": None, "at": {"x": 1.0, "y": 2.0, "z": 3.0}}, "test.codec.reading"))
    assert info.value.reason == "body.at: expected Point | null, got object"  # an optional field: the union is named


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_a_non_finite_float_is_refused_where_null_is_allowed(bad: float) -> None:
    with pytest.raises(MalformedMessage, match=r"^body\.value: expected float \| null, got float$"):
        encode(Reading(bad))
    with pytest.raises(MalformedMessage, match=r"^body\.values: expected list\[float \| null\] \| null, got list$"):
        encode(Reading(values=[1.0, bad]))
    with pytest.raises(MalformedMessage, match=r"^body\.at: expected Point \| null, got Point$"):
        encode(Reading(at=Point(bad)))
    with pytest.raises(MalformedMessage, match=r"^body\.x: .* is not a finite float$"):
        encode(Point(bad))
    assert decode(encode(Reading(None, [None, 2.5], Point(1, 2)))) == Reading(None, [None, 2.5], Point(1.0, 2.0))


def test_an_int_where_a_float_is_expected_arrives_as_a_float() -> None:
    back = decode(encode(Point(1, 2)))
    assert back == Point(1.0, 2.0) and type(back.x) is float  # type: ignore[attr-defined]


def test_what_the_codec_cannot_carry_is_refused_at_definition() -> None:
    with pytest.raises(TypeError, match="unsupported annotation.*array-like"):

        @message("test.codec.two-lists")
        class TwoLists(Message):
            items: list[int] | tuple[str, ...]

    with pytest.raises(TypeError, match="unsupported annotation.*dict-like"):

        @message("test.codec.two-objects")
        class TwoObjects(Message):
            at: Point | dict[str, Any]

    with pytest.raises(TypeError, match="cannot start with '_'"):

        @message("test.codec.private")
        class Private(Message):
            _secret: str


def test_decode_runs_post_init_and_turns_its_refusal_into_a_reason() -> None:
    assert decode(encode(Checked(2))) == Checked(2)
    with pytest.raises(MalformedMessage, match="count must not be negative, got -1"):
        decode(env({"count": -1}, "test.codec.checked"))


def test_decode_builds_the_registered_class_and_nothing_else() -> None:
    msg = decode(env({"value": 1.5, "values": [None], "at": {"x": 0.5, "y": 1}}, "test.codec.reading"))
    assert type(msg) is Reading and type(msg.at) is Point  # type: ignore[attr-defined]
    assert dataclasses.replace(msg, value=2.0) == Reading(2.0, [None], Point(0.5, 1.0))  # type: ignore[type-var]
    assert wire_struct(Reading) is not Reading  # the wire struct checks; the dataclass is what callers get


def test_a_stray_attribute_never_reaches_the_wire_unseen() -> None:
    for msg in (Point(1.0), Tagged({"a": "b"})):  # written by msgspec, and by orjson
        with pytest.raises((TypeError, AttributeError)):
            object.__setattr__(msg, "z", 3.0)  # a message (a Struct) has its fields and no other attribute
        assert decode(encode(msg)) == msg and b'"z"' not in encode(msg)


def test_a_key_that_is_not_a_string_is_refused_even_inside_any() -> None:
    with pytest.raises(MalformedMessage, match=r"^body\.tags: keys must be str, got int$"):
        encode(Tagged({1: "one"}))  # type: ignore[dict-item]
    with pytest.raises(MalformedMessage, match=r"^body: "):
        encode(Tagged({"a": "b"}, {"deep": [{2: "two"}]}))


@message("test.codec.versioned", 1)
class VersionedV1(Message):
    name: str


@message("test.codec.versioned", 2)
class VersionedV2(Message):
    name: str
    count: int = 0


@message("test.codec.nested")
class Nested(Message):
    points: list[Point]
    tags: list[str] = []


def test_the_wire_bytes_are_the_envelope_with_every_field_in_order() -> None:
    assert encode(Point(1.0, 0.5)) == b'{"v":1,"type":"test.codec.point","body":{"x":1.0,"y":0.5}}'  # msgspec writes
    assert encode(Tagged({"a": "b"})) == b'{"v":1,"type":"test.codec.tagged","body":{"tags":{"a":"b"},"free":null}}'
    assert encode(Nested([Point(2.0)])) == (
        b'{"v":1,"type":"test.codec.nested","body":{"points":[{"x":2.0,"y":0.0}],"tags":[]}}')


def test_a_defaulted_field_of_a_nested_message_must_be_sent_too() -> None:
    with pytest.raises(MalformedMessage) as info:
        decode(env({"points": [{"x": 1.0, "y": 2.0}, {"x": 1.0}], "tags": []}, "test.codec.nested"))
    assert info.value.reason == "body.points[1]: missing field 'y' of test.codec.point"
    with pytest.raises(MalformedMessage, match=r"^body: missing field 'tags' of test.codec.nested$"):
        decode(env({"points": []}, "test.codec.nested"))


def test_built_in_code_a_message_takes_its_defaults_each_a_fresh_one() -> None:
    a, b = Nested([]), Nested([])
    assert a.tags == [] and a.tags is not b.tags and Point(1.0).y == 0.0
    assert decode(encode(a)) == a


def test_each_version_of_a_type_decodes_into_its_own_class() -> None:
    assert decode(env({"name": "a"}, "test.codec.versioned")) == VersionedV1("a")
    v2 = json.dumps({"v": 2, "type": "test.codec.versioned", "body": {"name": "a", "count": 3}}).encode()
    assert decode(v2) == VersionedV2("a", 3) and decode(encode(VersionedV2("b"))) == VersionedV2("b")
    with pytest.raises(MalformedMessage, match=r"^body: missing field 'count' of test.codec.versioned$"):
        decode(json.dumps({"v": 2, "type": "test.codec.versioned", "body": {"name": "a"}}).encode())


def test_a_message_keeps_the_dataclasses_protocol() -> None:
    reading = Reading(1.5, [None], Point(0.5))
    assert [f.name for f in dataclasses.fields(reading)] == ["value", "values", "at"]
    assert dataclasses.asdict(reading) == {"value": 1.5, "values": [None], "at": {"x": 0.5, "y": 0.0}}
    assert dataclasses.replace(reading, value=None) == Reading(None, [None], Point(0.5))
    assert hash(Point(1.0)) == hash(Point(1.0)) and Point(1.0) != Checked(1)
    with pytest.raises(AttributeError):
        reading.value = 2.0  # type: ignore[misc]
