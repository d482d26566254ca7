"""Which controller's term a worker takes (drd.cluster.terms): only the live controller's, once a call of it was
accepted; a forged or unknown term is refused and changes nothing (bus audit, defect 1)."""

from __future__ import annotations

from drd.cluster.terms import REFUSED_FOR, TermFence, Terms


class Witness:
    """The live controller's term as a test sets it, and how often it was asked."""

    def __init__(self, live: float | None, why: str = "") -> None:
        self.current, self.why, self.asked = live, why, 0

    def __call__(self) -> tuple[float | None, str]:
        self.asked += 1
        return self.current, self.why


def fence(live: float | None, why: str = "") -> tuple[TermFence, Witness, list[float]]:
    witness, now = Witness(live, why), [100.0]
    return TermFence("ranger1", witness, clock=lambda: now[0]), witness, now


def test_a_term_greater_than_the_live_controllers_is_refused_and_changes_nothing() -> None:
    f, witness, _ = fence(7.0)
    why = f.admit(9.9e15)
    assert "term 9900000000000000 is no controller's: the live controller's term is 7" in why
    f.adopt(9.9e15)  # even if a caller got through, an unvouched term is never adopted
    assert f.term == 0.0
    assert f.admit(7.0) == "" and witness.asked == 2
    f.adopt(7.0)
    assert f.term == 7.0 and f.admit(7.0) == "" and witness.asked == 2  # the adopted term asks nobody


def test_a_term_is_adopted_only_after_the_call_was_accepted() -> None:
    f, _, _ = fence(7.0)
    assert f.admit(7.0) == ""
    assert f.term == 0.0  # admitted, not adopted: the Creator's checks come first
    f.adopt(7.0)
    assert f.term == 7.0


def test_an_older_controller_is_refused_once_a_newer_one_was_adopted() -> None:
    f, witness, _ = fence(7.0)
    f.admit(7.0)
    f.adopt(7.0)
    witness.current = 12.0  # a new election
    assert f.admit(12.0) == ""
    f.adopt(12.0)
    assert "refuses a call from an older controller (term 7; the controller of term 12 acts now)" in f.admit(7.0)


def test_a_term_between_the_adopted_and_the_live_one_is_refused() -> None:
    f, witness, _ = fence(7.0)
    f.admit(7.0)
    f.adopt(7.0)
    witness.current = 12.0
    assert "term 9 is older than the live controller's, 12" in f.admit(9.0)
    assert f.term == 7.0


def test_an_unchecked_term_is_refused_and_the_witness_asked_again_later() -> None:
    f, witness, now = fence(None, "etcd did not answer")
    assert "cannot check its term 7 (etcd did not answer)" in f.admit(7.0)
    assert "cannot check" in f.admit(7.0) and witness.asked == 1  # a refusal of that term is remembered a moment
    witness.current = 7.0
    now[0] += REFUSED_FOR
    assert f.admit(7.0) == "" and witness.asked == 2


def test_a_flood_of_one_forged_term_asks_the_witness_once_and_a_real_new_term_at_once() -> None:
    f, witness, _ = fence(7.0)
    for _ in range(50):
        assert f.admit(9.9e15)
    assert witness.asked == 1
    witness.current = 8.0  # a real controller shows up meanwhile: its term is asked, not the memo's
    assert f.admit(8.0) == "" and witness.asked == 2


def test_the_rule_forgets_refusals_beyond_its_memory() -> None:
    rule = Terms()
    for t in range(200):
        rule.answered(1000.0 + t, (7.0, ""), 0.0)
    assert len(rule.refused) <= 64


def test_without_a_witness_the_callers_word_is_taken_as_before() -> None:
    f = TermFence("ranger1", None)
    assert f.admit(5.0) == ""
    f.adopt(5.0)
    assert f.term == 5.0 and "older controller" in f.admit(4.0)


def test_the_controllers_status_vouches_only_when_every_answer_agrees_and_is_not_in_the_future() -> None:
    """An open cluster lets any peer answer on the controller's status key (the re-verification audit forged
    `started=9.9e15` there, then sent one accepted call): a term is taken only from answers that all agree, and a
    start time more than a clock skew ahead of ours is nobody's."""
    from types import SimpleNamespace

    from drd.cluster.terms import CLOCK_SKEW, started_term

    real = SimpleNamespace(host="controller", started=1000.0)
    forged = SimpleNamespace(host="controller", started=9.9e15)
    assert started_term("controller", [real], 1005.0) == (1000.0, "")
    assert started_term("controller", [real, SimpleNamespace(host="ranger1", started=5.0)], 1005.0) == (1000.0, "")
    term, why = started_term("controller", [real, forged], 1005.0)
    assert term is None and "2 different terms answer as the controller controller's status" in why
    term, why = started_term("controller", [forged], 1005.0)  # the forger alone (the controller down meanwhile)
    assert term is None and "in the future" in why
    assert started_term("controller", [SimpleNamespace(host="controller", started=1005.0 + CLOCK_SKEW)], 1005.0)[0]
    assert started_term("controller", [], 1005.0)[0] is None
