"""The scan geometry on arrays gives the floats the plain per-beam loops gave, bit for bit (hypothesis).

`components.behaviors.scan` does its per-beam arithmetic on numpy arrays; the loops below are the definitions it
replaced (as they were), run on random corridor-like scans (walls at random distances and angles, door gaps,
misses, noise, an end wall) and on scans of anything at all. Equal means `==` on the very floats: a wall fit, the
clearance ahead and the end-wall test, with and without a memo, with and without an expected distance.
"""

from __future__ import annotations

import bisect
import math

from hypothesis import given, settings
from hypothesis import strategies as st

from components.behaviors.scan import (
    SECTORS,
    SPREAD,
    SUPPORT,
    ScanMemo,
    Wall,
    clearance_ahead,
    fit_wall,
    surface_across,
)
from drd.hw.interfaces import Scan

FAR = 8.0
N = 181


# -- the plain definitions -----------------------------------------------------------------------------------------


def plain_fit(scan: Scan, side: int, expect: float | None) -> Wall | None:
    lo, hi = SECTORS[1 if side > 0 else -1]
    b, far = scan.beams(), scan.max_range
    i0, i1 = b.span(lo, hi)
    beams = zip(scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1], strict=True)
    pts = [(r * c, y) for r, c, s in beams if r < far and (y := (r * s if side > 0 else -(r * s))) > 0.05]
    abeam = sorted([y for x, y in pts if abs(x) <= 2 * y])
    support = [y for y, z in zip(abeam, abeam[SUPPORT - 1:], strict=False) if z - y < SPREAD]
    xs, ys = [x for x, _ in pts], [y for _, y in pts]
    if not support:
        return None
    if expect is None:
        d0 = support[0]
    else:
        j = bisect.bisect_left(support, expect)
        d0 = support[j - 1] if j == len(support) or (j > 0 and expect - support[j - 1] <= support[j] - expect) \
            else support[j]
    inl = [i for i, y in enumerate(ys) if -0.25 < y - d0 < 0.25]
    m = c = 0.0
    for gate in (None, 0.1):
        if gate is not None:
            inl = [i for i, (x, y) in enumerate(zip(xs, ys, strict=True)) if -gate < y - (m * x + c) < gate]
        n = len(inl)
        if n < 5:
            return None
        ix, iy = [xs[i] for i in inl], [ys[i] for i in inl]
        mx, my = sum(ix) / n, sum(iy) / n
        dxs = [x - mx for x in ix]
        sxx = sum([dx * dx for dx in dxs])
        if sxx < 1e-6:
            return None
        m = sum([dx * (y - my) for dx, y in zip(dxs, iy, strict=True)]) / sxx
        c = my - m * mx
    a = math.atan(m)
    return Wall(c * math.cos(a), side * a, n, max(ix) - min(ix))


def plain_ahead(scan: Scan) -> list[tuple[float, float, float]]:
    b = scan.beams()
    i0, i1 = bisect.bisect_right(b.angles, -math.pi / 2), bisect.bisect_left(b.angles, math.pi / 2)
    return list(zip(scan.ranges[i0:i1], b.cos[i0:i1], b.sin[i0:i1], strict=True))


def plain_clearance(scan: Scan, half_width: float) -> float:
    far = scan.max_range
    return min([r * c for r, c, s in plain_ahead(scan) if r < far and -half_width < r * s < half_width], default=far)


def plain_wall_across(scan: Scan, within: float) -> bool:
    if plain_clearance(scan, 0.35) >= within:
        return False
    far, depth = scan.max_range, within + 0.25
    # the hits in the lane, in beam order, split into surfaces where consecutive hits are over 0.25 m apart
    kept = [(r * c, r * s) for r, c, s in plain_ahead(scan) if r < far and 0 < r * c < depth and -0.9 < r * s < 0.9]
    surfaces: list[list[float]] = []
    for k, (x, y) in enumerate(kept):
        if k == 0 or math.hypot(x - kept[k - 1][0], y - kept[k - 1][1]) > 0.25:
            surfaces.append([])
        surfaces[-1].append(y)
    return any(max(ys) - min(ys) >= 1.0 for ys in surfaces)


# -- scans ---------------------------------------------------------------------------------------------------------


@st.composite
def corridor_scans(draw: st.DrawFn) -> Scan:
    """A robot in a corridor: two walls (distances, a common tilt), door gaps, an end wall maybe, noise, misses."""
    left, right = draw(st.floats(0.3, 2.5)), draw(st.floats(0.3, 2.5))
    tilt = draw(st.floats(-0.4, 0.4))
    end = draw(st.one_of(st.none(), st.floats(0.3, 7.0)))
    gaps = draw(st.lists(st.tuples(st.integers(0, N - 1), st.integers(1, 12), st.floats(0.5, 9.0)), max_size=4))
    noise = draw(st.lists(st.floats(-0.03, 0.03), min_size=N, max_size=N))
    step = math.pi / (N - 1)
    ranges = []
    for i in range(N):
        a = -math.pi / 2 + i * step - tilt
        s, c = math.sin(a), math.cos(a)
        r = FAR
        if s > 1e-9:
            r = min(r, left / s)
        if s < -1e-9:
            r = min(r, right / -s)
        if end is not None and c > 1e-9:
            r = min(r, end / c)
        ranges.append(r)
    for start, width, far in gaps:
        for k in range(start, min(N, start + width)):
            ranges[k] = far
    out = tuple(FAR if r >= FAR else max(0.0, r + e) for r, e in zip(ranges, noise, strict=True))
    return Scan(out, -math.pi / 2, step, FAR)


any_scans = st.lists(st.one_of(st.just(FAR), st.floats(0.0, FAR)), min_size=N, max_size=N).map(
    lambda rs: Scan(tuple(rs), -math.pi / 2, math.pi / (N - 1), FAR))
expects = st.one_of(st.none(), st.floats(0.0, 3.0))


@settings(max_examples=300, deadline=None)
@given(st.one_of(corridor_scans(), any_scans), expects, expects, st.floats(0.5, 1.5))
def test_the_array_geometry_is_the_plain_geometry(scan: Scan, left: float | None, right: float | None,
                                                  within: float) -> None:
    memo = ScanMemo()
    for side, expect in ((1, left), (-1, right), (1, None), (-1, None)):
        want = plain_fit(scan, side, expect)
        assert fit_wall(scan, side, expect) == want
        assert fit_wall(scan, side, expect, memo) == want
        assert fit_wall(scan, side, expect, memo) == want  # from the memo
    for half in (0.35, 0.2):
        assert clearance_ahead(scan, half) == plain_clearance(scan, half)
        assert clearance_ahead(scan, half, memo) == plain_clearance(scan, half)
        assert type(clearance_ahead(scan, half, memo)) is float
    assert surface_across(scan, within) is plain_wall_across(scan, within)
    assert surface_across(scan, within, memo) is plain_wall_across(scan, within)
