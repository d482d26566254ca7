"""The shortcuts that make `missionctl status` and a bus call cheaper give what the long ways give.

- `load_endpoints` (no component catalog) reads the same cluster, security and endpoints as `load_hosts`;
- `print_json` writes to a pipe exactly what rich's `print_json` wrote there;
- `fast_command` (the hot commands without typer's parameter building) passes the values typer passes,
  and leaves everything else (help, errors, unusual spellings) to typer;
- the cached message encoders write the bytes the envelope's encoding gave, and decode builds the same
  messages as `__init__` (its `__post_init__` included).

No timing here: bench/cluster.py and bench/bus.py measure.
"""

from __future__ import annotations

import dataclasses
import functools
import io
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import msgspec
import pytest
import typer
from rich.console import Console  # noqa: TID251 - the reference: what rich's print_json wrote

from drd.bus import LoadReport, MalformedMessage, Message, Ping, Pong, decode, encode, message
from drd.bus.messages import _dumps
from drd.cli import cluster
from drd.cli.common import print_json
from drd.daemon.security import transport
from drd.hosts import HostsError, load_endpoints, load_hosts
from dsl.catalog import Catalog

ROOT = Path(__file__).resolve().parents[2]


# --- hosts.yaml without the catalog ------------------------------------------------------------------


def _same_access(path: Path, catalog: Catalog) -> None:
    full, light = load_hosts(path, catalog), load_endpoints(path)
    assert (light.name, light.security, light.lease, light.placement, light.source) == (
        full.name, full.security, full.lease, full.placement, full.source)
    assert [(h.name, h.endpoint, h.roles, h.cores) for h in light.hosts] == [
        (h.name, h.endpoint, h.roles, h.cores) for h in full.hosts]
    assert light.controller.name == full.controller.name
    assert all(not h.devices and not h.robots for h in light.hosts)
    if not full.security.files or all(Path(f).is_file() for f in full.security.files.values()):
        assert transport(light) == transport(full)


@pytest.mark.parametrize("name", ["hosts.yaml", "hosts.two_rangers.yaml"])
def test_light_reader_gives_the_repository_files_endpoints_and_security(name: str, catalog: Catalog) -> None:
    _same_access(ROOT / name, catalog)


def test_light_reader_gives_the_same_password_security(tmp_path: Path, catalog: Catalog) -> None:
    (tmp_path / "secrets").mkdir()
    (tmp_path / "secrets" / "users.txt").write_text("drd:s3cret\n", encoding="utf-8")
    text = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
    secured = "security: {mode: password, user: drd, password_file: secrets/users.txt}"
    text = text.replace("security: {mode: none}", secured)
    assert secured in text
    path = tmp_path / "hosts.yaml"
    path.write_text(text, encoding="utf-8")
    _same_access(path, catalog)
    assert transport(load_endpoints(path)).options["transport/auth/usrpwd/password"] == "s3cret"


def test_light_reader_skips_the_hardware_but_not_the_rest(tmp_path: Path, catalog: Catalog) -> None:
    text = (ROOT / "hosts.yaml").read_text(encoding="utf-8")
    broken_hardware = tmp_path / "hardware.yaml"
    broken_hardware.write_text(text.replace("type: Camera", "type: Kamera", 1), encoding="utf-8")
    assert "Kamera" in broken_hardware.read_text(encoding="utf-8")
    with pytest.raises(HostsError, match="Kamera"):
        load_hosts(broken_hardware, catalog)
    assert load_endpoints(broken_hardware).name == load_hosts(ROOT / "hosts.yaml", catalog).name
    bad_endpoint = tmp_path / "endpoint.yaml"
    bad_endpoint.write_text(text.replace("tcp/127.0.0.1:7448", "tcp/127.0.0.1:99999", 1), encoding="utf-8")
    with pytest.raises(HostsError) as full:
        load_hosts(bad_endpoint, catalog)
    with pytest.raises(HostsError) as light:
        load_endpoints(bad_endpoint)
    assert [str(p) for p in light.value.problems] == [str(p) for p in full.value.problems]


# --- JSON output -----------------------------------------------------------------------------------------


DATA: Any = {"cluster": "corridor", "at": 1795332883.125, "hosts": [{"name": "rånger1", "state": "up", "cpu": 12.5,
             "since": None, "roles": ["worker"], "note": "tab\there \"quoted\" \\ and \u2028 and 😀"}],
             "empty": {}, "none": [], "nested": {"a": [1, 2.0, True, False, None]}, "big": 10**20}


@pytest.mark.parametrize("data", [DATA, [], {}, "text", 3, [DATA, DATA]])
def test_print_json_to_a_pipe_is_what_rich_printed(data: Any, capsys: pytest.CaptureFixture[str]) -> None:
    print_json(data)
    printed = capsys.readouterr().out
    sink = io.StringIO()
    Console(file=sink, highlight=False, soft_wrap=True).print_json(json.dumps(data))  # `out` as it was
    assert printed == sink.getvalue()
    assert json.loads(printed) == data


def test_print_json_uses_default_like_json_dumps(capsys: pytest.CaptureFixture[str]) -> None:
    print_json({"path": Path("a/b")}, default=str)
    assert json.loads(capsys.readouterr().out) == {"path": "a/b"}


# --- the fast path of the hot commands ---------------------------------------------------------------


def _recording_app(name: str) -> tuple[typer.Typer, dict[str, Any]]:
    """A typer app whose command `name` has the real command's signature and records what typer passes."""
    seen: dict[str, Any] = {}
    real = getattr(cluster, name)

    @functools.wraps(real)
    def recorder(**kwargs: Any) -> int:
        seen.update(kwargs)
        return 0

    app = typer.Typer(add_completion=False)
    app.command(name)(recorder)
    app.command("other")(lambda: 0)  # two commands, as missionctl has: the name is then required
    return app, seen


@pytest.mark.parametrize("argv", [
    ["status"],
    ["status", "--json", "--config", "x.yaml", "--timeout", "0.5"],
    ["status", "-c", "x.yaml", "--connect", "tcp/a:1", "--connect", "tcp/b:2", "--events", "5", "-w",
     "--interval", "0.25"],
    ["status", "--events", "0", "--timeout", "0.05", "--interval=2"],
    ["hosts", "--timeout=3", "--json"],
    ["components", "--json", "--connect=tcp/127.0.0.1:7447"],
    ["resources", "--config=a b.yaml"],
])
def test_fast_path_passes_what_typer_passes(argv: list[str]) -> None:
    app, seen = _recording_app(argv[0])
    call = cluster.fast_command(app, argv)
    assert isinstance(call, functools.partial)
    assert app(argv, prog_name="missionctl", standalone_mode=False) == 0
    assert call.keywords == seen
    assert {k: type(v) for k, v in call.keywords.items()} == {k: type(v) for k, v in seen.items()}


@pytest.mark.parametrize("argv", [
    [], ["status", "--help"], ["status", "--timeout", "0.01"], ["status", "--timeout", "1e-1"],
    ["status", "--timeout", ".5"], ["status", "--json", "--json"], ["status", "--events", "-1"],
    ["status", "--events", "07"], ["status", "--config"], ["status", "extra"], ["status", "--no-json"],
    ["status", "-wc", "x.yaml"], ["status", "--config", "x", "--config", "y"], ["status", "--json=yes"],
    ["status", "--"], ["status", "--timeout", ""], ["query", "Camera"], ["validate", "x.mission"], ["--help"],
])
def test_fast_path_leaves_the_rest_to_typer(argv: list[str]) -> None:
    from drd.cli.missionctl import app

    assert cluster.fast_command(app, argv) is None


def test_fast_path_declines_a_command_typer_would_treat_specially() -> None:
    app, _ = _recording_app("status")
    app.registered_commands[0].context_settings = {"auto_envvar_prefix": "MISSIONCTL"}
    assert cluster.fast_command(app, ["status"]) is None
    other, _ = _recording_app("status")
    other.callback()(lambda: None)
    assert cluster.fast_command(other, ["status"]) is None

    def with_envvar(timeout: float = typer.Option(2.0, "--timeout", envvar="TIMEOUT")) -> int:
        return 0

    third = typer.Typer()
    third.command("status")(with_envvar)
    assert cluster.fast_command(third, ["status"]) is None


def test_missionctl_status_runs_without_pydantic_and_fails_as_before(tmp_path: Path) -> None:
    """The real entry point takes the fast path (no typer parameter building), with the usual error."""
    code = ("import atexit, sys\n"
            "atexit.register(lambda: print('pydantic loaded' if 'pydantic' in sys.modules else 'no pydantic'))\n"
            "sys.argv = ['missionctl', 'status', '--config', sys.argv[1], '--timeout', '0.2']\n"
            "from drd.cli.missionctl import main\nmain()\n")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "missing.yaml")], capture_output=True, text=True,
                       timeout=60, cwd=ROOT, check=False)
    assert r.returncode == 2 and "missing.yaml: no such file" in r.stderr
    assert r.stdout.strip() == "no pydantic"


def test_usage_errors_show_the_usage_not_a_class_name() -> None:
    code = ("import sys; sys.argv = ['missionctl', 'status', '--timeout', '0.01']\n"
            "from drd.cli.missionctl import main\nmain()")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT, check=False)
    assert r.returncode == 2
    assert "Usage: missionctl status" in r.stderr and "--timeout" in r.stderr and "BadParameter" not in r.stderr


# --- the bus's cached codecs ---------------------------------------------------------------------------


@message("test.speed.inner", 1)
class _Inner(Message):
    name: str
    at: float


@message("test.speed.outer", 1)
class _Outer(Message):
    inner: _Inner
    items: list[_Inner]
    table: dict[str, int]
    maybe: _Inner | None = None
    anything: Any = None


@message("test.speed.checked", 1)
class _Checked(Message):
    value: int

    def __post_init__(self) -> None:
        msgspec.structs.force_setattr(self, "value", abs(self.value))  # a frozen Struct's own way


def _envelope_bytes(msg: Message) -> bytes:
    """The wire bytes as encode wrote them before its per-class cache: the whole envelope, encoded at once."""
    cls = type(msg)
    return _dumps({"v": cls.VERSION, "type": cls.TYPE, "body": msg})


@pytest.mark.parametrize("msg", [
    Ping(3, 1.5), Pong(7, "sérver ✓"), LoadReport("h", 1.0, 2.5, 0.25, 3, 12.0),
    _Outer(_Inner("a", 1.0), [_Inner("b", 2.0), _Inner("c", 3.0)], {"x": 1}, None, {"free": [1, "two"]}),
    _Outer(_Inner("a", 1.0), [], {}, _Inner("d", 4.0), None), _Checked(-4),
])
def test_cached_encoder_writes_the_envelope_bytes_and_decode_builds_the_same_message(msg: Message) -> None:
    data = encode(msg)
    assert data == _envelope_bytes(msg)
    back = decode(data)
    assert back == msg and type(back) is type(msg)
    assert dataclasses.asdict(back) == dataclasses.asdict(msg)  # type: ignore[call-overload]
    assert decode(bytearray(data)) == msg and decode(memoryview(data)) == msg


def test_decode_runs_post_init_and_builds_frozen_messages() -> None:
    assert decode(b'{"v":1,"type":"test.speed.checked","body":{"value":-5}}') == _Checked(5)
    ping = decode(encode(Ping(1, 2.0)))
    assert isinstance(ping, Ping)
    with pytest.raises(AttributeError):  # a frozen Struct's refusal (a dataclass's FrozenInstanceError is one too)
        ping.nonce = 3  # type: ignore[misc]


def test_decode_still_names_what_is_wrong() -> None:
    with pytest.raises(MalformedMessage, match="unknown message type 'nope'"):
        decode(b'{"v":1,"type":"nope","body":{}}')
    with pytest.raises(MalformedMessage, match=r"unsupported version 2 of 'drd.ping' \(supported: \[1\]\)"):
        decode(b'{"v":2,"type":"drd.ping","body":{}}')
    with pytest.raises(MalformedMessage, match="body.nonce: expected int, got string"):
        decode(b'{"v":1,"type":"drd.ping","body":{"nonce":"1","sent_at":0.0}}')
    with pytest.raises(MalformedMessage, match="payload is str, not bytes"):
        decode("{}")  # type: ignore[arg-type]
    with pytest.raises(MalformedMessage, match="is not a registered message type"):
        encode(Message())
