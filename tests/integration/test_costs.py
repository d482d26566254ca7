"""The compiler's cost grows linearly with its input, whatever the input's shape (issue #18).

Cost is counted, not timed: the Python lines the compiler executes (a `sys.settrace` counter), which a quadratic
loop, even one inside a comprehension, multiplies by the input's growth. Each shape is compiled at n and 4n: four
times the input may cost at most `LINEAR` times the work (4 and some slack for what does not grow). A shape that
took quadratic time before (a body of many children: every child copied its siblings' data) is among them. The
measured slope in seconds per byte is in `docs/design.md`; `bench/compile.py --slope` prints it.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable

import pytest

from dsl import compile_text
from dsl.catalog import Catalog
from tests.conftest import lines_executed

#: Four times the input may cost at most this many times the work.
LINEAR = 4.6


def chain(n: int) -> str:
    """States in sequence: `s0 -> s1 -> ...` (one body of many children and transitions)."""
    lines = ["mission Chain {", "    start -> s0"]
    for i in range(n):
        lines += [f"    Wait(duration: 1s) as s{i}", f"    s{i} -> s{i + 1}"]
    return "\n".join([*lines, f"    Wait(duration: 1s) as s{n}", "}"]) + "\n"


def concurrent(n: int) -> str:
    """One parallel block of many children reading and writing shared data."""
    kids = "\n".join(f"        DetectDoor(min_width: 0.7) as d{i}" for i in range(n))
    return ("mission Wide {\n    needs ranger: Ranger\n    shared visited: DoorLog\n    shared map: OccupancyMap\n"
            f"    parallel all {{\n{kids}\n    }}\n}}\n")


def behaviors(n: int) -> str:
    """Many behaviors, each used once, each with parameters, variables and guarded transitions."""
    out = ["mission Many {", "    parallel all {", *(f"        B{i}(limit: {i})" for i in range(n)), "    }", "}"]
    for i in range(n):
        out += [f"behavior B{i}(limit: int = 1) {{", "    var tries: int = 0", "    Wait(duration: 1s) as w",
                "    w -> done [tries < limit] / set tries = tries + 1", "    w -> fail after 2min", "}"]
    return "\n".join(out) + "\n"


def expression(n: int) -> str:
    """One long guard."""
    terms = " and ".join(f"x > {i}" for i in range(n))
    return f"mission Expr {{\n    var x: int = 0\n    Wait(duration: 1s) as w\n    w -> done [{terms}]\n}}\n"


def plan(n: int) -> str:
    """A plan of many steps in order."""
    steps = " < ".join(f"w{i}" for i in range(n))
    waits = "\n".join(f"    Wait(duration: 1s) as w{i}" for i in range(n))
    return f"mission Plan {{\n{waits}\n    plan {{ {steps} }}\n}}\n"


def errors(n: int) -> str:
    """Many lines in error (the recovery and the number of errors shown are bounded)."""
    return "mission Bad {\n" + "    Wait(duration: ) ) as\n" * n + "}\n"


def garbage(n: int) -> str:
    """Punctuation on one line (it once cost 1.7-17 ms a character)."""
    return "mission G {\n" + "}{)(->;[" * n + "\n}\n"


def string(n: int) -> str:
    """One long string with interpolations (a string once cost 370 bytes of memory a byte)."""
    return 'mission S {\n    Wait(duration: 1s) as w\n    w -> done / log "' + "ab{w}" * n + '"\n}\n'


SHAPES: dict[str, tuple[Callable[[int], str], int]] = {
    "chain": (chain, 150), "concurrent": (concurrent, 60), "behaviors": (behaviors, 40),
    "expression": (expression, 80), "plan": (plan, 60), "errors": (errors, 200), "garbage": (garbage, 400),
    "string": (string, 400),
}


def work(text: str, catalog: Catalog) -> int:
    """The Python lines executed to compile `text`."""
    return lines_executed(lambda: compile_text(text, catalog, "cost.mission"))


@pytest.fixture(scope="module", autouse=True)
def warm(catalog: Catalog) -> None:
    """Build the parser once, so neither size pays for it."""
    compile_text(chain(2), catalog, "warm.mission")


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_four_times_the_input_costs_at_most_four_times_the_work(shape: str, catalog: Catalog) -> None:
    make, n = SHAPES[shape]
    small, large = make(n), make(4 * n)
    ratio = work(large, catalog) / work(small, catalog)
    assert ratio <= LINEAR, f"{shape}: 4x the input ({len(small)} -> {len(large)} bytes) cost {ratio:.1f}x the work"


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_memory_grows_in_proportion_to_the_input(shape: str, catalog: Catalog) -> None:
    make, n = SHAPES[shape]
    text = make(16 * n)
    tracemalloc.start()
    try:
        compile_text(text, catalog, "cost.mission")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2_000_000 + 400 * len(text), f"{shape}: {peak / len(text):.0f} bytes of memory per byte"
