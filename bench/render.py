"""`--render` at fleet size: seconds to draw a dry-run of the corridor mission on generated buildings.

Runs the mission once per size in process (not timed), then times `drd.render.render` alone, best of `--repeat`,
and counts what the picture kept: text artists, and the labels it left out at that scale. Run by hand from the
repository root; timings depend on the machine, so compare figures taken on the same one.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any

from drd.dryrun import DryRun, run
from drd.hosts import parse_hosts
from drd.manifests import load_catalog
from drd.render import render
from drd.sim.building import Building, hosts, world
from drd.sim.model import World
from drd.sim.world import parse_world
from dsl import compile_file

ROOT = Path(__file__).resolve().parents[1]
MISSION = ROOT / "missions" / "corridor_surveillance.mission"


def dry_run(wings: int, scouts: int, until: float) -> tuple[World, DryRun]:
    catalog = load_catalog()
    compiled = compile_file(MISSION, catalog)
    if compiled.statechart is None:
        raise SystemExit(f"{MISSION} does not compile")
    b = Building(wings, scouts)
    sim_world = parse_world(world(b), b.name)
    cluster = parse_hosts(hosts(b), b.name, catalog)
    return sim_world, run(compiled.statechart, cluster, sim_world, catalog, until=until)


def measure(wings: int, scouts: int, until: float, repeat: int, suffix: str) -> dict[str, Any]:
    sim_world, report = dry_run(wings, scouts, until)
    views = {str(s["scout"]): (0.0, math.radians(60.0)) for s in report.scouts}  # as the CLI passes them
    best = math.inf
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"r{suffix}"
        for _ in range(repeat):
            t0 = time.perf_counter()
            render(sim_world, report, out, views=views)
            best = min(best, time.perf_counter() - t0)
        size = out.stat().st_size
    return {"wings": wings, "robots": len(sim_world.rangers) + len(sim_world.scout_ids), "sim_time": report.sim_time,
            "seconds": round(best, 3), "bytes": size}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wings", default="1,3,10", help="building sizes (wings of 1 Ranger + 19 Scouts)")
    ap.add_argument("--until", type=float, default=60.0, help="sim seconds of each dry-run")
    ap.add_argument("--repeat", type=int, default=3, help="renders per size; the best is kept")
    ap.add_argument("--format", default=".png", choices=(".png", ".svg", ".pdf"), help="the picture's format")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args()
    points = [measure(int(w), 19, args.until, max(1, args.repeat), args.format) for w in args.wings.split(",")]
    if args.json:
        print(json.dumps(points, indent=2))
        return
    print(f"{'wings':>5} {'robots':>6} {'sim s':>6} {'render s':>9} {'bytes':>10}")
    for p in points:
        print(f"{p['wings']:>5} {p['robots']:>6} {p['sim_time']:>6.0f} {p['seconds']:>9.2f} {p['bytes']:>10}")


if __name__ == "__main__":
    main()
