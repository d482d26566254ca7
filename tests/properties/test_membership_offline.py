"""Property: whatever the order of the view's news (down, up, a lease run out) and the mission loop's suspicions
(a call that did not answer, then a report), the manager fed the membership's actions holds a host's resources
exactly while the membership says so, and they are offline exactly while the host is down or suspected."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from drd.daemon.controller import Action, Membership

HOSTS = ("r1", "r2")
EVENTS = st.lists(st.tuples(st.sampled_from(["down", "up", "due", "silent", "heard"]), st.sampled_from(HOSTS)),
                  max_size=40)


def apply(actions: list[Action], present: set[str], offline: set[str]) -> None:
    """What the controller's shell does with them (`Controller._apply`), on sets."""
    for a in actions:
        if a.kind == "add":
            present.add(a.host)
        elif a.kind == "remove":
            present.discard(a.host)
            offline.discard(a.host)
        elif a.kind == "offline":
            offline.add(a.host)
        else:
            offline.discard(a.host)


@given(EVENTS)
def test_offline_exactly_while_down_or_suspected(events: list[tuple[str, str]]) -> None:
    m = Membership(1.0, {"controller", *HOSTS})
    present, offline = {"controller", *HOSTS}, set[str]()
    now = 0.0
    for kind, host in events:
        now += 0.4
        if kind == "down":
            got = m.down(host, now)
        elif kind == "up":
            got = m.up(host, now)
        elif kind == "due":
            got = m.due(now)
        else:
            got = m.silent(host) if kind == "silent" else m.heard(host)
        apply(got, present, offline)
        assert present == m.present
        assert offline == {h for h in m.present if h in m.removal or h in m.suspected}
