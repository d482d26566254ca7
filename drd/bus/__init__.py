"""The drd bus: one interface for all inter-process communication (see docs/bus.md).

``LocalBus`` (in-process, deterministic) is importable from here; ``ZenohBus`` lives in
``drd.bus.zenoh_bus`` so that importing the interface never requires eclipse-zenoh.
"""

from __future__ import annotations

from .base import (
    DEFAULT_TIMEOUT,
    Bus,
    BusClosed,
    BusError,
    BusStats,
    BusTimeout,
    BusWrapper,
    Handler,
    Query,
    Queryable,
    RemoteError,
    Reply,
    Sample,
    Subscription,
    Token,
    typed_handler,
)
from .keys import check_key_expr, intersects, join_key
from .local import LocalBus, LocalNetwork
from .messages import ErrorReply, LoadReport, MalformedMessage, Message, Ping, Pong, decode, encode, message

__all__ = [
    "DEFAULT_TIMEOUT",
    "Bus",
    "BusClosed",
    "BusWrapper",
    "BusError",
    "BusStats",
    "BusTimeout",
    "ErrorReply",
    "Handler",
    "LoadReport",
    "LocalBus",
    "LocalNetwork",
    "MalformedMessage",
    "Message",
    "Ping",
    "Pong",
    "Query",
    "Queryable",
    "RemoteError",
    "Reply",
    "Sample",
    "Subscription",
    "Token",
    "typed_handler",
    "check_key_expr",
    "decode",
    "encode",
    "intersects",
    "join_key",
    "message",
]
