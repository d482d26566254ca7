"""What a move does with a component's state when the state cannot go along (placement audit 24, #1, #2, #4), on
real daemons on loopback (a controller and two bare workers; the user's own components, killed by pid).

- A snapshot over 64 KiB cannot be taken along: `migrate` said "moved ... afresh (its component keeps no state)",
  exit 0, and the component started again from nothing. Now it is refused and the instance goes on where it was.
- A `restore` that raises on the new host: the command printed only the exception, and the instance was then
  stepped half-built (the mission failed with an AttributeError from `step`). Now its state fails with the
  exception, as a start that raises does.
- A `movable: false` component whose host is lost: `migrate` refuses it, but it was placed again elsewhere and
  given its snapshot. Now it starts there afresh (its state stays behind, as its manifest says).

Each component writes what it did to a file of its own, read from outside the cluster."""

from __future__ import annotations

import json
import signal
from collections.abc import Iterator
from typing import Any

import pytest
from cluster_support import DaemonCluster, eventually, instances_only_hosts, serving_cluster, user_kit

NAMES = ["controller", "w1", "w2"]
KIT = '''import json
import os

from drd.runtime.component import Component, Status


class Tally(Component):
    """Counts its steps; writes each start (fresh, restored or told its state is gone) to $TALLY_OUT/<name>."""

    restored = None
    told = False

    def restore(self, state):
        self.restored, self.told = state, True

    def start(self):
        self.count = int(self.restored["count"]) if self.restored else 0
        what = "restored" if self.restored else "afresh" if self.told else "fresh"
        with open(os.path.join(os.environ["TALLY_OUT"], type(self).__name__), "a") as f:
            f.write(json.dumps({"start": what, "count": self.count, "pid": os.getpid()}) + "\\n")

    def step(self, now):
        self.count += 1
        return Status.RUNNING

    def snapshot(self):
        return {"count": self.count}


class Hoard(Tally):
    def snapshot(self):
        return {"count": self.count, "pad": "x" * 70000}


class Brittle(Tally):
    def restore(self, state):
        raise RuntimeError("Brittle cannot restore")


class Keeper(Tally):
    pass
'''
MANIFEST = """name: {name}
kind: behavior
description: A counter, for the migration tests.
entry_point: tallykit:{name}
process: container
movable: {movable}
"""


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaemonCluster]:
    folder = tmp_path_factory.mktemp("migrate_state")
    with pytest.MonkeyPatch.context() as mp:
        user_kit(folder, mp, "tallykit", KIT, {n: MANIFEST.format(name=n, movable=str(n != "Keeper").lower())
                                               for n in ("Hoard", "Brittle", "Keeper")})
        (folder / "out").mkdir()
        mp.setenv("TALLY_OUT", str(folder / "out"))
        with serving_cluster(folder, NAMES, instances_only_hosts) as c:
            yield c


def starts(c: DaemonCluster, name: str) -> list[dict[str, Any]]:
    path = c.folder / "out" / name
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def run(c: DaemonCluster, name: str) -> str:
    """Mission `Run<name>` running `name` (detached): its id, once its component started on a worker."""
    mission = c.folder / f"{name}.mission"
    mission.write_text(f"mission Run{name} {{\n    {name}\n}}\n")
    r = c.missionctl("run", str(mission), "--config", str(c.hosts_file), "--detach", timeout=60)
    assert r.returncode == 0, (r.stdout, r.stderr, c.tails("controller"))
    mid = r.stdout.strip()
    eventually(lambda: starts(c, name) and where(c, mid), f"{name} to start and its host to announce it", 30,
               explain=lambda: c.tails("controller"))
    return mid


def where(c: DaemonCluster, mid: str) -> str | None:
    r = c.missionctl("components", "--config", str(c.hosts_file), "--json", timeout=30)
    assert r.returncode == 0, r.stderr[-2000:]
    return next((i["host"] for i in json.loads(r.stdout)["instances"] if i["mission"] == mid), None)


def mission(c: DaemonCluster, mid: str) -> dict[str, Any]:
    r = c.missionctl("status", "--config", str(c.hosts_file), "--json", timeout=30)
    assert r.returncode == 0, r.stderr[-2000:]
    return next(m for m in json.loads(r.stdout)["missions"] if m["id"] == mid)


def migrate(c: DaemonCluster, instance: str, host: str) -> tuple[int, str]:
    r = c.missionctl("migrate", instance, "--to", host, "--config", str(c.hosts_file), "--json", timeout=60)
    return r.returncode, r.stderr


def other(host: str | None) -> str:
    return "w2" if host == "w1" else "w1"


def test_a_snapshot_too_large_to_take_along_is_refused_and_the_instance_goes_on_where_it_was(
        cluster: DaemonCluster) -> None:
    mid = run(cluster, "Hoard")
    try:
        host = where(cluster, mid)
        code, err = migrate(cluster, f"{mid}/RunHoard/Hoard", other(host))
        assert code == 2 and "cannot move with its state" in err and "over 65536 bytes" in err, err
        assert where(cluster, mid) == host and mission(cluster, mid)["outcome"] is None
        assert [s["start"] for s in starts(cluster, "Hoard")] == ["fresh"]  # never started again from nothing
    finally:
        cluster.missionctl("stop", mid, "--config", str(cluster.hosts_file), timeout=60)


def test_a_restore_that_raises_on_the_new_host_fails_the_state_with_its_exception(cluster: DaemonCluster) -> None:
    mid = run(cluster, "Brittle")
    code, err = migrate(cluster, f"{mid}/RunBrittle/Brittle", other(where(cluster, mid)))
    assert code == 2 and "Brittle cannot restore" in err and "its state fails" in err, err
    eventually(lambda: mission(cluster, mid)["outcome"] == "failure", "the mission to fail", 30)
    reason = mission(cluster, mid)["reason"]
    assert "Brittle cannot restore" in reason and "AttributeError" not in reason, reason


def test_a_component_that_may_not_move_starts_afresh_when_its_host_is_lost(cluster: DaemonCluster) -> None:
    mid = run(cluster, "Keeper")
    host = where(cluster, mid)
    assert host in ("w1", "w2")
    try:
        eventually(lambda: mission(cluster, mid).get("time", 0) > 2.0, "a few steps counted", 30)
        cluster.procs[host].send_signal(signal.SIGKILL)
        cluster.procs[host].wait(timeout=10)
        eventually(lambda: len(starts(cluster, "Keeper")) == 2, "Keeper to start again elsewhere", 30,
                   explain=lambda: cluster.tails("controller"))
        assert [s["start"] for s in starts(cluster, "Keeper")] == ["fresh", "afresh"]  # not given its snapshot
        assert where(cluster, mid) == other(host) and mission(cluster, mid)["outcome"] is None
    finally:
        cluster.missionctl("stop", mid, "--config", str(cluster.hosts_file), timeout=60)
        cluster.start(host)
        cluster.wait_up()
