"""A small etcd v3 client over etcd's own HTTP JSON gateway (`/v3/kv/range`, `/v3/kv/txn`, `/v3/lease/...`), with
the standard library only (issue #16: the replicated store of the controllers).

Why not a Python etcd package: the `etcd3` packages are unmaintained and pin old grpc and protobuf releases that
clash with what drd's other dependencies need; the gateway is part of every etcd server (3.4: prefix `/v3/`), speaks
JSON (int64 fields as strings, keys and values base64) and needs nothing but `urllib`. Every request is a POST of one
JSON object; a member that does not answer within `timeout` is skipped for the next one, so a dead member costs one
timeout, and the member that answered last is asked first next time.
"""

from __future__ import annotations

import base64
import json
import threading
import urllib.error
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from drd.errors import BusFailure

#: gRPC codes of a member that cannot serve now (deadline exceeded, unavailable: no raft leader): ask another.
RETRY_CODES = frozenset({4, 14})


class EtcdError(BusFailure):
    """etcd answered with an error (`code` is its gRPC code: 5 is "not found"), or no member answered."""

    def __init__(self, message: str, code: int = 0) -> None:
        super().__init__(message)
        self.code = code


class EtcdUnavailable(EtcdError):
    """No member of the etcd cluster answered within the timeout."""


def b64(data: str | bytes) -> str:
    return base64.b64encode(data.encode() if isinstance(data, str) else data).decode("ascii")


def prefix_end(prefix: str) -> str:
    """The `range_end` that makes a range cover every key starting with `prefix` (its last byte plus one)."""
    raw = bytearray(prefix.encode())
    raw[-1] += 1
    return b64(bytes(raw))


@dataclass(frozen=True, slots=True)
class KeyValue:
    key: str
    value: bytes
    create_revision: int
    mod_revision: int
    lease: int

    @staticmethod
    def of(data: dict[str, Any]) -> KeyValue:
        return KeyValue(base64.b64decode(data.get("key", "")).decode(), base64.b64decode(data.get("value", "")),
                        int(data.get("create_revision", 0)), int(data.get("mod_revision", 0)),
                        int(data.get("lease", 0)))


# -- the operations and comparisons of a transaction (as the gateway's JSON has them) ---------------------------------

def put(key: str, value: str | bytes, lease: int = 0) -> dict[str, Any]:
    body: dict[str, Any] = {"key": b64(key), "value": b64(value)}
    if lease:
        body["lease"] = str(lease)
    return {"request_put": body}


def delete(key: str, prefix: bool = False) -> dict[str, Any]:
    body = {"key": b64(key)} | ({"range_end": prefix_end(key)} if prefix else {})
    return {"request_delete_range": body}


def get(key: str) -> dict[str, Any]:
    return {"request_range": {"key": b64(key)}}


def created_at(key: str, revision: int) -> dict[str, Any]:
    """The comparison "`key` was created at `revision`" (0: it does not exist)."""
    return {"key": b64(key), "target": "CREATE", "result": "EQUAL", "create_revision": str(revision)}


class Etcd:
    """Requests to an etcd cluster through any of its members (`endpoints`: client URLs). Thread-safe."""

    def __init__(self, endpoints: Sequence[str], timeout: float = 1.0) -> None:
        if not endpoints:
            raise ValueError("no etcd endpoint")
        self.endpoints = [e.rstrip("/") for e in endpoints]
        self.timeout = timeout
        self._first = 0
        self._lock = threading.Lock()

    def post(self, path: str, body: dict[str, Any], timeout: float | None = None) -> dict[str, Any]:
        """One gateway request (`path` like `/v3/kv/range`), tried on each member in turn; its JSON answer."""
        data = json.dumps(body).encode()
        with self._lock:
            order = self.endpoints[self._first:] + self.endpoints[:self._first]
        tried: list[str] = []
        for i, endpoint in enumerate(order):
            request = urllib.request.Request(endpoint + path, data=data, method="POST",
                                             headers={"Content-Type": "application/json"})
            try:
                with urllib.request.urlopen(request, timeout=timeout or self.timeout) as reply:  # noqa: S310 (http)
                    answer: dict[str, Any] = json.loads(reply.read() or b"{}")
            except urllib.error.HTTPError as e:  # etcd's own refusal: the same from every member
                try:
                    err = json.loads(e.read() or b"{}")
                except ValueError:
                    err = {}
                message, code = str(err.get("message") or err.get("error") or e), int(err.get("code") or 0)
                if code in RETRY_CODES:  # this member has no leader or timed out: another one may do
                    tried.append(f"{endpoint}: {message}")
                    continue
                raise EtcdError(f"etcd {endpoint}{path}: {message}", code) from None
            except (OSError, ValueError) as e:  # not listening, timed out, cut off, not JSON: the next member
                tried.append(f"{endpoint}: {getattr(e, 'reason', e)}")
                continue
            if "error" in answer and isinstance(answer.get("code"), int):
                raise EtcdError(f"etcd {endpoint}{path}: {answer.get('message') or answer['error']}", answer["code"])
            with self._lock:
                self._first = (self._first + i) % len(self.endpoints)
            return answer
        raise EtcdUnavailable("no etcd member answered: " + "; ".join(tried))

    # -- keys ----------------------------------------------------------------------------------------------------------

    def get(self, key: str) -> KeyValue | None:
        kvs = self.post("/v3/kv/range", {"key": b64(key)}).get("kvs") or []
        return KeyValue.of(kvs[0]) if kvs else None

    def prefix(self, prefix: str) -> list[KeyValue]:
        """Every key under `prefix`, in key order."""
        answer = self.post("/v3/kv/range", {"key": b64(prefix), "range_end": prefix_end(prefix)})
        return [KeyValue.of(kv) for kv in answer.get("kvs") or []]

    def txn(self, compare: list[dict[str, Any]], success: list[dict[str, Any]],
            failure: list[dict[str, Any]] | None = None) -> tuple[bool, int, list[dict[str, Any]]]:
        """(whether every comparison held, the store's revision after it, the responses of the branch taken)."""
        answer = self.post("/v3/kv/txn", {"compare": compare, "success": success, "failure": failure or []})
        return (bool(answer.get("succeeded")), int(answer.get("header", {}).get("revision", 0)),
                list(answer.get("responses") or []))

    # -- leases --------------------------------------------------------------------------------------------------------

    def grant(self, ttl: int) -> tuple[int, int]:
        """A new lease: (its id, its TTL in seconds as etcd granted it: at least etcd's minimum)."""
        answer = self.post("/v3/lease/grant", {"TTL": str(ttl)})
        return int(answer["ID"]), int(answer.get("TTL", ttl))

    def keepalive(self, lease: int) -> int:
        """Renew `lease`; its TTL again, or 0 when etcd no longer has it (it expired or was revoked)."""
        answer = self.post("/v3/lease/keepalive", {"ID": str(lease)})
        return int((answer.get("result") or {}).get("TTL", 0))

    def revoke(self, lease: int) -> None:
        """Drop `lease` and every key attached to it now (a clean stop: no wait for its expiry)."""
        try:
            self.post("/v3/lease/revoke", {"ID": str(lease)})
        except EtcdError as e:
            if e.code != 5:  # not found: already gone
                raise
