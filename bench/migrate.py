"""Migration benchmark: how long `missionctl migrate` takes the controller (issue #15).

Run `python bench/migrate.py [--moves 10] [--json]` (never by pytest). Real processes on loopback: controller,
ranger1 and spare (the repository's hosts.yaml, `spare` a second worker), a mission holding one `Wait(600s)` at
`--speed 1`; the Wait is moved back and forth between the two workers `--moves` times through the controller's
`missions/migrate` key (a `drd.daemon.migrate.Migrate` request, as `missionctl migrate` sends it, without the
command's own start-up). Each move stops the instance on one host (its snapshot comes back), starts it on the
other from that snapshot, with the missions' lock held: the mission loop misses the cycles it takes. Printed:
each move's round trip (median, max), and the snapshot's size. Goal: a move within 2 control cycles' worth of
wall time plus one start (a first start on a host may load the component's module): median <= 100 ms.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' cluster fixtures
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "e2e"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ... which import each other as `tests.*`

from cluster_support import MISSIONCTL, eventually, running, serving_cluster  # noqa: E402
from test_cluster_run import NAMES, corridor_hosts  # noqa: E402

from drd.daemon.migrate import Migrate, Migrated, migrate_key  # noqa: E402

GOAL = 0.100  # seconds, median move


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moves", type=int, default=10)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench_migrate_"))
    with serving_cluster(folder, NAMES, corridor_hosts) as cluster:
        mission = folder / "hold.mission"
        mission.write_text("mission Hold {\n    Wait(duration: 600s) as Hold\n}\n")
        cmd = [*MISSIONCTL, "run", str(mission), "--config", str(cluster.hosts_file), "--speed", "1", "--json"]
        with running(cmd):
            started = re.compile(r"mission (Hold-\d+) started")
            eventually(lambda: started.search(cluster.log("controller")) is not None, "the mission", 60)
            placed = re.findall(r"placement: Wait on (\w+)", cluster.log("controller"))[-1]
            client = cluster.client(timeout=10.0)
            times, sizes, host = [], [], placed
            try:
                for _ in range(args.moves):
                    host = "spare" if host == "ranger1" else "ranger1"
                    t0 = time.perf_counter()
                    reply = client.bus.call(migrate_key(cluster.name), Migrate("Hold/Hold", host), timeout=20.0)
                    times.append(time.perf_counter() - t0)
                    assert isinstance(reply, Migrated), reply
                    sizes.append(len(json.dumps(reply.state)))
                    time.sleep(0.5)
            finally:
                client.close()
    result = {"moves": len(times), "median_ms": round(statistics.median(times) * 1000, 1),
              "max_ms": round(max(times) * 1000, 1), "snapshot_bytes": max(sizes),
              "goal_ms": GOAL * 1000, "ok": statistics.median(times) <= GOAL}
    print(json.dumps(result) if args.json else
          f"{result['moves']} moves of a Wait between ranger1 and spare: median {result['median_ms']} ms, max"
          f" {result['max_ms']} ms; its snapshot {result['snapshot_bytes']} bytes"
          f" ({'within' if result['ok'] else 'over'} the goal of {GOAL * 1000:g} ms)")


if __name__ == "__main__":
    main()
