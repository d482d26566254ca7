"""Failures injected into a dry-run at a sim time: `kill ranger1 at 90s`, `lose scout3 at 2min`.

Pure: parsing and checking against the cluster and the world; `drd.dryrun` applies them. What each does:

- `kill HOST`: the host's daemon dies. The components bound to its devices die with it (their states fail, as
  calls to a dead host do on a cluster), its resources go offline and leave the manager one lease later unless it
  restarts (grants freed then, the behaviors still holding them fail or degrade as the language says), and the
  robots it drives stop where they are, in the world.
- `lose ROBOT`: one robot is gone (a Scout falls down the stairs): its resources leave the manager, the
  instance that held it fails, the rest of the mission goes on.
- `join HOST`: the host's daemon starts late: until then the manager does not know its resources (its robots
  stand idle in the world); when it joins they are added, and a running multiplicity below its max grows.
- `restart HOST`: the daemon of a host killed earlier starts again. The controller resumes its missions from its
  journal (as `drd start` does on a cluster: `drd.runtime.snapshot`); any other host joins back.
- `block DOOR`: an open door is obstructed (as solid as closed, and not openable).
- `close DOOR` / `open DOOR`: a door changes state.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable
from dataclasses import dataclass
from enum import StrEnum

from drd.errors import MissionInputError
from dsl.ast import parse_duration
from dsl.errors import did_you_mean


class Action(StrEnum):
    KILL = "kill"
    JOIN = "join"
    RESTART = "restart"
    LOSE = "lose"
    BLOCK = "block"
    CLOSE = "close"
    OPEN = "open"


#: What each action applies to, for messages.
TARGET = {Action.KILL: "host", Action.JOIN: "host", Action.RESTART: "host", Action.LOSE: "robot",
          Action.BLOCK: "door", Action.CLOSE: "door", Action.OPEN: "door"}

_FORM = re.compile(r"^\s*(?P<action>\w+)\s+(?P<target>[\w.\-]+)\s+at\s+(?P<at>\S+)\s*$")
USAGE = "write ACTION TARGET at TIME, e.g. 'kill ranger1 at 90s', 'lose scout3 at 2min', 'block door_n3 at 60s'"


class InjectionError(MissionInputError, ValueError):
    """An injection that cannot be understood or names nothing that exists; the message says which and why."""


@dataclass(frozen=True, slots=True, order=True)
class Injection:
    at: float
    action: Action
    target: str

    def __str__(self) -> str:
        return f"{self.action.value} {self.target} at {self.at:g}s"


def parse(text: str, *, hosts: set[str], robots: set[str], doors: set[str]) -> Injection:
    """One `--inject` value, checked against what exists (`hosts` from hosts.yaml, the world's robots and doors)."""
    m = _FORM.match(text)
    if m is None:
        spaced = re.search(r"\bat\s+(\d+(?:\.\d+)?)\s+(ms|s|min|h)\s*$", text)
        why = f": a time has no space before its unit (write {spaced[1]}{spaced[2]})" if spaced else ""
        raise InjectionError(f"cannot read injection {text!r}{why}: {USAGE}")
    word = m["action"].lower()
    try:
        action = Action(word)
    except ValueError:
        names = [a.value for a in Action]
        raise InjectionError(f"unknown injection {word!r} in {text!r}: use one of {', '.join(names)}"
                             f"{_suggest(word, names)}") from None
    at = parse_duration(m["at"])
    if at is None:
        raise InjectionError(f"bad time {m['at']!r} in {text!r}: write a duration such as 90s, 2min or 1.5h")
    known = {"host": hosts, "robot": robots, "door": doors}[TARGET[action]]
    if m["target"] not in known:
        raise InjectionError(f"no {TARGET[action]} {m['target']!r} to {word} in {text!r}{_suggest(m['target'], known)}"
                             f": known {TARGET[action]}s are {_some(known)}")
    return Injection(at, action, m["target"])


def parse_all(texts: list[str], *, hosts: set[str], robots: set[str], doors: set[str],
              until: float | None = None) -> list[Injection]:
    """Every `--inject`, in time order; all problems reported together. One after `until` (the run's sim time
    limit) is refused: it could never happen, and a run that silently left it out would mislead."""
    out, problems = [], []
    for t in texts:
        try:
            inj = parse(t, hosts=hosts, robots=robots, doors=doors)
        except InjectionError as e:
            problems.append(str(e))
            continue
        if until is not None and inj.at > until:
            problems.append(f"injection {t!r} comes after the run ends (--until {until:g} s):"
                            " it would never happen")
        out.append(inj)
    out.sort()
    problems += _restarts_follow_kills(out)
    if problems:
        raise InjectionError("\n".join(problems))
    return out


def _restarts_follow_kills(injections: list[Injection]) -> list[str]:
    """A `restart HOST` needs that host killed before it (and not restarted since)."""
    problems, down = [], set()
    for i in injections:
        if i.action is Action.KILL:
            down.add(i.target)
        elif i.action is Action.RESTART:
            if i.target not in down:
                problems.append(f"{i}: {i.target} is not down then: write 'kill {i.target} at ...' before it")
            down.discard(i.target)
    return problems


#: Names a refusal lists at most: at fleet size, every robot of a building on one line was 10 kB (scale audit 11).
SHOWN_NAMES = 12


def _some(names: Collection[str]) -> str:
    """The first `SHOWN_NAMES` of `names` (sorted), and how many more there are."""
    shown = sorted(names)
    if len(shown) <= SHOWN_NAMES:
        return ", ".join(shown) or "none"
    return f"{', '.join(shown[:SHOWN_NAMES])} and {len(shown) - SHOWN_NAMES} more"


def _suggest(name: str, candidates: Iterable[str]) -> str:
    hint = did_you_mean(name, candidates)
    return f" ({hint})" if hint else ""
