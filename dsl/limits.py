"""What one compilation may create or cost: the bounds a user could need to raise, in one place (issue #18).

`instances` bounds a multiplicity, written (`Wait[5000]` is a located error above it) or evaluated when it starts
(the interpreter fails it before any instance exists); `compile_seconds` bounds a compilation a controller does for
a client. Both come from hosts.yaml's `cluster.limits` where a cluster is known (`missionctl run`, `dry-run`,
`validate --config`) and are the defaults below elsewhere. The other bounds are fixed, because no mission a person
writes comes near them: file size 1 MiB (`dsl.loader`, also the bus's largest message), numbers of 18 digits or
1e15, durations of a year, expressions 100 deep, behaviors 64 deep (`dsl.parser`, `dsl.checker`).
"""

from __future__ import annotations

from dataclasses import dataclass

#: The default most instances a multiplicity may create: each is a statechart and components.
DEFAULT_INSTANCES = 1000
#: The default most seconds a controller compiles a submitted mission (a 1 MB one takes about 3 s on 2 cores).
DEFAULT_COMPILE_SECONDS = 10.0


@dataclass(frozen=True, slots=True)
class Limits:
    """The configurable bounds of a compilation and of the statechart it builds."""

    instances: int = DEFAULT_INSTANCES
    compile_seconds: float = DEFAULT_COMPILE_SECONDS


DEFAULT = Limits()
