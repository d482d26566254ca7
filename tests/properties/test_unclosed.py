"""The block a missing `}` error names (dsl/unclosed.py): pure text scanning, checked on generated nestings."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from dsl.unclosed import unclosed_block

# A block tree: each node is a list of children (a leaf is an empty list), written as indented lines.
trees = st.recursive(st.just([]), lambda kids: st.lists(kids, min_size=1, max_size=3), max_leaves=12)


def write(tree: list[object], depth: int = 0, out: list[str] | None = None) -> list[str]:
    out = [] if out is None else out
    for child in tree:
        pad = "  " * depth
        if child:
            out.append(f"{pad}parallel all {{  # {{ in a comment")
            write(child, depth + 1, out)  # type: ignore[arg-type]
            out.append(pad + "}")
        else:
            out.append(f'{pad}Observe -> done / log "{{not a block}}"')
    return out


@given(trees)
def test_balanced_text_has_no_unclosed_block(tree: list[object]) -> None:
    lines = ["mission M {", *write(tree, 1), "}"]
    assert unclosed_block("\n".join(lines), len(lines) + 1) is None


@given(trees, st.data())
def test_a_removed_closing_brace_is_named_at_its_own_block(tree: list[object], data: st.DataObject) -> None:
    lines = ["mission M {", *write(tree, 1), "}"]
    closers = [i for i, line in enumerate(lines) if line.strip() == "}"]
    gone = data.draw(st.sampled_from(closers))
    # its opener: the nearest line above, as indented, that opens a block
    indent = len(lines[gone]) - len(lines[gone].lstrip())
    opener = max(i for i in range(gone) if lines[i].split("#")[0].rstrip().endswith("{")
                 and len(lines[i]) - len(lines[i].lstrip()) == indent)
    text = "\n".join(lines[:gone] + lines[gone + 1:])
    found = unclosed_block(text, len(lines))
    assert found is not None and found.line == opener + 1


def test_lines_are_counted_as_the_lexer_counts_them() -> None:
    """Only \\n ends a line (a vertical tab or form feed does not): the block is named on the lexer's line."""
    found = unclosed_block("\x0bA {\n  B\n", 4)
    assert found is not None and (found.line, found.column) == (1, 4)
