"""Replies in pages, so that no reply outgrows the transport (issue #16). Pure.

A bus message is at most `drd.bus.messages.MAX_SIZE` (1 MiB): 3,800 finished missions once made the status reply
bigger, and `status`, `stop` and `run` failed until a restart. A server that answers a list (the executive's
missions, a mission's records) fills a page up to `PAGE_BYTES` of items and `count` items, and says where the next
page starts (`next`, a cursor the client sends back as `after`); the client asks page after page and assembles.
The cursor is a number the items carry in the order served (a mission's start ordinal, a record's `seq`), not a
position: an item dropped or added between two pages shifts nothing.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TypeVar

from drd.bus.messages import MAX_SIZE

T = TypeVar("T")

#: Bytes of items in one page: half a bus message, so that the envelope, the reply's other fields and an item at
#: the edge always fit.
PAGE_BYTES = MAX_SIZE // 2
#: Items in a page when the client asks for no count (0), and the most it may ask for.
PAGE_COUNT = 200
MAX_PAGE_COUNT = 1000


def page_count(asked: int) -> int:
    """The items a page holds at most: what the client asked (`0`: the default), within 1..`MAX_PAGE_COUNT`."""
    return PAGE_COUNT if asked <= 0 else min(asked, MAX_PAGE_COUNT)


def fill(items: Iterable[tuple[int, T]], size: Callable[[T], int], count: int,
         budget: int = PAGE_BYTES) -> tuple[list[T], int]:
    """The first items of `items` ((cursor, item), in cursor order, computed lazily) that fit `count` and `budget`
    bytes (`size(item)`), at least one; and the cursor to ask the next page after (that of the last item taken),
    0 when none is left. An item alone over the budget is taken alone (it was sent on the bus by itself once)."""
    limit = page_count(count)
    taken: list[T] = []
    used = last = 0
    for cursor, item in items:
        cost = size(item) + 1  # and its comma
        if taken and (len(taken) >= limit or used + cost > budget):
            return taken, last
        taken.append(item)
        used += cost
        last = cursor
    return taken, 0


def by_position(items: Sequence[T], after: int, count: int, size: Callable[[T], int],
                budget: int = PAGE_BYTES) -> tuple[list[T], int]:
    """A page of a list served whole each time (a view): its items after position `after` (1-based), as `fill`
    takes them. Positions move when items come or go between two pages: a view's pages may miss or repeat one
    (the caller says what it does about it)."""
    return fill(((n, item) for n, item in enumerate(items, start=1) if n > after), size, count, budget)
