"""Key expressions: zenoh's syntax and intersection rule, checked the same way for both buses.

LocalBus matches with :func:`intersects`; ZenohBus lets zenoh match. Both refuse, through
:func:`check_key_expr`, what the other could not handle, so a dry-run refuses what a cluster would.
"""

from __future__ import annotations

from functools import lru_cache


def check_key_expr(key: str, *, concrete: bool = False) -> str:
    """Refuse a key expression zenoh would refuse (or that LocalBus cannot match), with why.

    Supported: chunks separated by ``/``, ``*`` (exactly one chunk) and ``**`` (any number of
    chunks) as whole chunks. Not supported: ``$*`` sub-chunk wildcards and ``@`` verbatim chunks.
    """
    if not isinstance(key, str):
        raise ValueError(f"key expression must be a non-empty string, not {key!r}")
    return _check_key_expr(key, concrete)


@lru_cache(maxsize=4096)  # a process uses few distinct keys, over and over
def _check_key_expr(key: str, concrete: bool) -> str:
    if not key:
        raise ValueError(f"key expression must be a non-empty string, not {key!r}")
    chunks = key.split("/")
    for index, chunk in enumerate(chunks):
        if not chunk:
            raise ValueError(f"key expression {key!r}: empty chunk or leading/trailing '/'")
        if any(c in chunk for c in "#?$") or chunk.startswith("@"):
            raise ValueError(f"key expression {key!r}: '#', '?', '$' and a leading '@' are not allowed")
        if "*" in chunk and chunk not in ("*", "**"):
            raise ValueError(f"key expression {key!r}: '*' must be a whole chunk ('*' or '**')")
        if concrete and "*" in chunk:
            raise ValueError(f"key {key!r} must be concrete (no wildcards)")
        if chunk == "**" and index + 1 < len(chunks) and chunks[index + 1] in ("*", "**"):
            raise ValueError(f"key expression {key!r}: write '*/**' for '**/*' and '**' for '**/**' (canon form)")
    return key


def intersects(a: str, b: str) -> bool:
    """True when some concrete key matches both expressions (zenoh's intersection rule)."""
    return _intersects(tuple(a.split("/")), tuple(b.split("/")))


@lru_cache(maxsize=4096)
def _intersects(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    if not a or not b:
        return all(c == "**" for c in a + b)
    if a[0] == "**":
        return _intersects(a[1:], b) or _intersects(a, b[1:])
    if b[0] == "**":
        return _intersects(a, b[1:]) or _intersects(a[1:], b)
    if a[0] == b[0] or a[0] == "*" or b[0] == "*":
        return _intersects(a[1:], b[1:])
    return False


def is_concrete(key: str) -> bool:
    return "*" not in key


def join_key(*chunks: str) -> str:
    """A key from names (host, component, instance...): refuses a name that would change its shape.

    ``join_key("drd", cluster, "host", host, "load")``; a name holding '/', a wildcard or a
    forbidden character raises ValueError instead of silently addressing something else.
    """
    for chunk in chunks:
        if not isinstance(chunk, str) or not chunk or "/" in chunk or "*" in chunk:
            raise ValueError(f"key chunk {chunk!r} must be a non-empty name without '/' or '*'")
    return check_key_expr("/".join(chunks))



def valid_key(key: str) -> bool:
    try:
        check_key_expr(key)
    except ValueError:
        return False
    return True
