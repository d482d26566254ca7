"""The Resource Controller Manager's pure core: resources, requests and grant decisions.

`ResourceManager` decides who holds which Resource Controllers (RCs) and Aggregate Resource
Controllers (ARCs): all-or-nothing by priority, round-robin slices among equals, capacity on
sharable units, leases, fencing epochs and wait-for-cycle resolution. It does no I/O and reads no
clock: the executive and the daemon call it with `now` and act on the decision records it returns.
"""

from __future__ import annotations

from drd.rcm.manager import ResourceManager
from drd.rcm.model import (
    Aggregate,
    Candidate,
    Deadlock,
    Decision,
    Granted,
    NeedRequest,
    Released,
    ReleaseReason,
    Renewed,
    Request,
    Reserved,
    Revoked,
    Unit,
    Unsatisfiable,
    Waiting,
    Where,
    units_of,
)

__all__ = [
    "Aggregate",
    "Candidate",
    "Deadlock",
    "Decision",
    "Granted",
    "NeedRequest",
    "Released",
    "ReleaseReason",
    "Renewed",
    "Request",
    "Reserved",
    "ResourceManager",
    "Revoked",
    "Unit",
    "Unsatisfiable",
    "Waiting",
    "Where",
    "units_of",
]
