"""The worker pipe protocol (`drd.cluster.pipe`): every record survives encode/decode, and what a worker could
forge (an unknown tag, a wrong number of fields, a field of a wrong type, a pickled object) is refused by the
plain decoder the Creator reads workers with, before anything is built or run."""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import pytest

from drd.cluster.pipe import (
    AttrRead,
    Call,
    CallReply,
    Command,
    DeviceCall,
    Done,
    Drop,
    Message,
    Ok,
    ProtocolError,
    Raise,
    Ready,
    Run,
    Setup,
    decode,
    encode,
    reading_key,
    reading_request,
)

SETUP = Setup("tests.test_workers:Probe", {"drive": "ranger1.drive"}, {"drive": ["odometry", "set_velocity"]},
              {"drive": ["set_velocity"]})
AHEAD = {("dev", "drive", "odometry", (), ()): (1.0, 2.0, 0.5), ("attr", "camera", "fov", (), ()): 1.2}
CALLS = (Call("M/A", "start", 0.0, "", None, None, {"x": 1}, {"mode": "drive"}, SETUP, None, [{"began": 2.5}]),
         Call("M/B", "step", 1.5, "", {"log": ["M/A"]}, {"log": "7"}, None, None, None, AHEAD),
         Call("M/C", "terminate", 2, "success", None, None, None, None, None, None))
REPLIES = (CallReply("running", {"pid": 12}, [["Seen", {"at": 1.0}]], ["a line"], {"log": ["M/A", "M/B"]},
                     [["r1", "k", 3]], "", False, [("attr", "camera", "fov", (), ())]),
           CallReply(error="ValueError: no", setup_failed=True),
           CallReply("running", snapshot=[{"began": 2.5, "steps": 40}]), CallReply("success", snapshot=[None]))

#: Every message a worker sends the Creator: the Creator reads them with the plain decoder.
FROM_WORKER: list[Message] = [
    Ready(4242),
    DeviceCall("M/A", "drive", "odometry"),
    DeviceCall("M/A", "drive", "scan", (1, "two", None), {"fast": True}),
    AttrRead("M/A", "camera", "fov"),
    Command("M/A", "drive", "set_velocity", (0.5, 0.1), {}),
    Done(REPLIES),
    Done(()),
]
#: Every message the Creator sends a worker but `Raise` (plain data too).
FROM_CREATOR: list[Message] = [
    Run(CALLS, {"7": ["M/A"]}),
    Run((), {}),
    Drop(("M/A", "M/B")),
    Ok((1.0, 2.0, 0.5)),
    Ok(None, changed=True),
]


@pytest.mark.parametrize("msg", FROM_WORKER + FROM_CREATOR, ids=lambda m: type(m).__name__)
def test_every_plain_record_round_trips_through_the_plain_decoder(msg: Message) -> None:
    data = encode(msg)
    assert decode(data) == msg
    assert decode(data, trusted=True) == msg


@pytest.mark.parametrize("changed", [False, True])
def test_raise_round_trips_on_the_trusted_path_only(changed: bool) -> None:
    data = encode(Raise(LookupError("no device for need 'arm'"), changed))
    got = decode(data, trusted=True)
    assert isinstance(got, Raise) and got.changed is changed
    assert type(got.error) is LookupError and got.error.args == ("no device for need 'arm'",)
    with pytest.raises(pickle.UnpicklingError, match="builtins.LookupError"):
        decode(data)  # an exception is an object: a worker could never make the Creator build one


def test_the_wire_is_plain_data_a_tagged_tuple() -> None:
    wire = pickle.loads(encode(Run(CALLS[:1], {})))
    assert wire[0] == "run" and isinstance(wire[1][0], tuple) and isinstance(wire[1][0][8], tuple)
    assert pickle.loads(encode(Ok(3, True))) == ("ok", 3, True)


def _forged(*wire: Any) -> bytes:
    return pickle.dumps(wire, pickle.HIGHEST_PROTOCOL)


def test_an_unknown_tag_is_refused_by_name() -> None:
    with pytest.raises(ProtocolError, match="unknown tag 'exec'"):
        decode(_forged("exec", "rm -rf /"))


@pytest.mark.parametrize("data", [pickle.dumps(["ready", 1]), pickle.dumps("ready"), pickle.dumps(()),
                                  pickle.dumps((1, 2)), pickle.dumps(None)], ids=repr)
def test_what_is_not_a_tagged_tuple_is_refused(data: bytes) -> None:
    with pytest.raises(ProtocolError, match="not a message"):
        decode(data)


@pytest.mark.parametrize("wire", [
    ("ready",),
    ("ready", 1, 2),
    ("dev", "M/A", "drive", "odometry"),  # the old protocol allowed a short `dev`: no more
    ("attr", "M/A", "camera", "fov", (), {}),
    ("done",),
    ("done", [("running", None, [], [], None, [], "", False)]),  # a reply short of a field
], ids=repr)
def test_a_wrong_number_of_fields_is_refused(wire: tuple[Any, ...]) -> None:
    with pytest.raises(ProtocolError, match=rf"'{wire[0]}'.* takes \d+ fields"):
        decode(_forged(*wire))


@pytest.mark.parametrize("wire", [
    ("ready", "4242"),
    ("dev", "M/A", 3, "odometry", (), {}),
    ("dev", "M/A", "drive", "odometry", (), [("fast", True)]),
    ("attr", ["M/A"], "camera", "fov"),
    ("cmd", "M/A", "drive", "set_velocity", 0.5, {}),
    ("drop", ["M/A", 7]),
    ("done", "replies"),
    ("done", [("running", "outputs", [], [], None, [], "", False, [], None, False)]),
    ("done", [("running", None, [], [], None, [], "", False, [], "a snapshot not in a list", False)]),
    ("done", [("running", None, [], [], None, [], "", False, [], None, "raised, not a bool")]),
    ("ok", 1, "changed"),
], ids=repr)
def test_a_field_of_a_wrong_type_is_refused(wire: tuple[Any, ...]) -> None:
    with pytest.raises(ProtocolError, match=rf"'{wire[0]}'.* must be"):
        decode(_forged(*wire))


class Gadget:
    def __init__(self) -> None:
        self.x = 1


class Shell:
    """Unpickles to `os.system(command)`: what a worker could send to run code in the Creator."""

    def __init__(self, command: str) -> None:
        self.command = command

    def __reduce__(self) -> tuple[Any, ...]:
        return (os.system, (self.command,))


def test_a_pickled_object_from_a_worker_is_refused_before_it_is_built(tmp_path: Path) -> None:
    with pytest.raises(pickle.UnpicklingError, match="Gadget"):
        decode(_forged("ok", Gadget(), False))
    with pytest.raises(pickle.UnpicklingError, match="Gadget"):
        decode(encode(Done((CallReply(outputs={"x": Gadget()}),))))  # deep inside a well-formed message too
    marker = tmp_path / "ran"
    forged = _forged("dev", "M/A", "drive", "odometry", (Shell(f"touch {marker}"),), {})
    with pytest.raises(pickle.UnpicklingError, match="system"):
        decode(forged)
    assert not marker.exists(), "the plain decoder ran a command a worker sent"


def test_a_reading_key_names_the_same_request_on_both_ends() -> None:
    call = DeviceCall("M/A", "ranges", "scan", (1,), {"fast": True})
    key = reading_key(call)
    assert key is not None and reading_request("M/A", key) == call
    attr = AttrRead("M/A", "camera", "fov")
    key = reading_key(attr)
    assert key is not None and reading_request("M/A", key) == attr
    assert reading_key(DeviceCall("M/A", "ranges", "scan", ([1],), {})) is None  # not hashable: always asked
