"""Several controllers, one acting (issue #16): the journal's two backends behind one interface (`drd.journal`:
SQLite and etcd) and the election (`drd.cluster.election`) against a real one-member etcd started here (skipped,
saying why, where `etcd` is absent). The election's pure rule and hosts.yaml's `cluster.store` are in
tests/unit/test_election.py; the three-member cluster and real daemons in tests/e2e/test_controller_failover.py."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from etcd_support import EtcdCluster, etcd_cluster, need_etcd

from drd.cluster.election import Election, leader_key
from drd.etcd import Etcd, EtcdUnavailable, created_at, delete, put
from drd.journal import EtcdJournal, Journal, JournalError, SqliteJournal, WorldState

# -- the journal's two backends ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def etcd(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EtcdCluster]:
    need_etcd()
    with etcd_cluster(tmp_path_factory.mktemp("etcd1"), 1) as e:
        yield e


_clusters = iter(range(10_000))


def lead(client: Etcd, cluster: str) -> int:
    """Make a leader key for `cluster` (no lease): its revision, the term a journal writes under."""
    ok, revision, _ = client.txn([created_at(leader_key(cluster), 0)], [put(leader_key(cluster), "test")])
    assert ok
    return revision


@pytest.fixture(params=["sqlite", "etcd"])
def backend(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Callable[[int], Journal]]:
    """A factory of journals of one backend, each new one reading what the others wrote (keep = its argument)."""
    if request.param == "sqlite":
        yield lambda keep: SqliteJournal(tmp_path / "journal.sqlite", keep=keep)
        return
    e: EtcdCluster = request.getfixturevalue("etcd")
    client = Etcd(e.urls)
    name = f"j{next(_clusters)}"
    term = lead(client, name)
    yield lambda keep: EtcdJournal(client, name, term, leader=leader_key(name), keep=keep)


def world(seq: int) -> WorldState:
    return WorldState("corridor", 3, 10.0, 12.5 + seq, seq, {"scout1": {"carrier": ""}})


def test_both_backends_keep_what_resuming_needs(backend: Callable[[int], Journal]) -> None:
    journal = backend(2)
    assert journal.running() == [] and journal.world() is None
    for i, mid in enumerate(["A-1", "B-2", "C-3", "D-4"]):
        journal.begin(mid, {"source": f"mission {mid} {{ }}", "speed": 20.0}, i + 1, 10.0 + i, 600.0)
        time.sleep(0.002)  # their start order is their order
    journal.save({"A-1": (12.5, {"path": "A", "children": []})}, world(7))
    journal.save({"B-2": (13.0, {"path": "B"})}, world(8))
    again = backend(2)  # another process (a restart, a standby) reads the same
    running = again.running()
    assert [j.id for j in running] == ["A-1", "B-2", "C-3", "D-4"]
    assert running[0].snapshot == {"path": "A", "children": []} and running[0].at == 12.5
    assert running[2].snapshot is None and running[2].at == running[2].base == 12.0
    assert running[1].request == {"source": "mission B-2 { }", "speed": 20.0} and running[1].priority == 2
    assert again.world() == WorldState("corridor", 3, 10.0, 20.5, 8, {"scout1": {"carrier": ""}},
                                       again.world().saved)  # type: ignore[union-attr]
    for mid in ["A-1", "B-2", "C-3"]:
        again.finish(mid, "success", "")
        time.sleep(0.002)
    assert [j.id for j in backend(2).running()] == ["D-4"]
    journal.close()
    again.close()


def test_an_etcd_journal_of_a_lost_election_writes_nothing(etcd: EtcdCluster) -> None:
    client = Etcd(etcd.urls)
    name = f"j{next(_clusters)}"
    old = lead(client, name)
    told: list[str] = []
    stale = EtcdJournal(client, name, old, leader=leader_key(name), on_fenced=told.append)
    stale.begin("M-1", {"source": "x"}, 1, 0.0, 60.0)
    client.txn([], [delete(leader_key(name))])
    new = lead(client, name)  # another controller won meanwhile
    assert new > old
    stale.save({"M-1": (5.0, {"path": "stale"})}, world(1))
    stale.finish("M-1", "failure", "the old controller says so")
    assert len(told) == 1 and "another one acts" in told[0] and stale.fenced
    current = EtcdJournal(client, name, new, leader=leader_key(name))
    [job] = current.running()
    assert job.id == "M-1" and job.snapshot is None  # nothing of the stale one's after it lost
    assert current.world() is None


def test_an_etcd_journal_of_another_version_is_refused(etcd: EtcdCluster) -> None:
    client = Etcd(etcd.urls)
    name = f"j{next(_clusters)}"
    client.txn([], [put(f"drd/{name}/journal/version", "99")])
    with pytest.raises(JournalError, match="journal version 99"):
        EtcdJournal(client, name, lead(client, name), leader=leader_key(name))


def test_no_etcd_member_answering_is_said_naming_them() -> None:
    with pytest.raises(EtcdUnavailable, match="no etcd member answered: http://127.0.0.1:9"):
        Etcd(["http://127.0.0.1:9"], timeout=0.5).get("x")


# -- the election against etcd -------------------------------------------------------------------------------------


def test_one_of_two_campaigns_wins_and_a_clean_stop_hands_over_to_the_other(etcd: EtcdCluster) -> None:
    name = f"e{next(_clusters)}"
    elected: list[tuple[str, int]] = []
    fenced: list[str] = []

    def campaign(host: str) -> Election:
        return Election(Etcd(etcd.urls), name, host, 2, on_elected=lambda t: elected.append((host, t)),
                        on_fenced=fenced.append, poll=0.05)

    first, second = campaign("c1"), campaign("c2")
    first.start()
    deadline = time.monotonic() + 10
    while not elected and time.monotonic() < deadline:
        time.sleep(0.02)
    second.start()
    time.sleep(0.5)
    assert [h for h, _ in elected] == ["c1"] and first.acting() and not second.acting()
    assert second.state.holder == "c1" and second.state.holder_term == elected[0][1]
    first.close(revoke=True)  # a clean stop: the standby takes over without waiting for the lease
    deadline = time.monotonic() + 10
    while len(elected) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert [h for h, _ in elected] == ["c1", "c2"] and elected[1][1] > elected[0][1]
    assert second.acting(elected[1][1]) and not second.acting(elected[0][1])
    assert fenced == []  # a clean stop is not a fencing
    second.close()
