"""Throughput and grant latency of the RCM core with 100, 1,000 and 10,000 waiting requests.

Run with `python bench/rcm.py` (never collected by pytest). Eight exclusive cameras are held and
N requests of mixed priorities wait for "any Camera". Measured, with the queue kept at N:

- enqueue: a new request for a camera that has to wait;
- churn: a holder releases its camera (the head waiter is granted in the same call) and asks
  again at the back of the queue: the grant latency is the duration of that release call;
- free unit: a request for a distinct free unit (granted at once) while N requests wait.

The goal is 10,000 requests/s; the cost per call should not grow with N beyond ~log N.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import ParamSpec, TypeVar

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drd.rcm import Granted, NeedRequest, Request, ResourceManager, Unit  # noqa: E402

CAMERAS = 8
CAMERA = (NeedRequest("camera", "Camera"),)
SAMPLES = 5_000
P = ParamSpec("P")
T = TypeVar("T")


def timed(samples: list[float], call: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """Call, append its duration in microseconds to `samples`, return its result."""
    start = time.perf_counter_ns()
    result = call(*args, **kwargs)
    samples.append((time.perf_counter_ns() - start) / 1_000)
    return result


def setup(waiting: int) -> ResourceManager:
    rm = ResourceManager(lease=1e9, default_slice=1e9)
    for index in range(CAMERAS):
        rm.add_unit(Unit(f"cam{index}", "Camera"), 0.0)
        rm.request(Request(f"holder{index}", 1, CAMERA), 0.0)
    for index in range(waiting):
        rm.request(Request(f"waiter{index}", 1 + index % 3, CAMERA), 0.0)
    return rm


def summary(name: str, waiting: int, samples: list[float]) -> str:
    ordered = sorted(samples)
    p99 = ordered[int(len(ordered) * 0.99) - 1]
    rate = len(samples) / (sum(samples) / 1e6)
    median = statistics.median(ordered)
    return f"{waiting:>7,} waiting  {name:<24} {rate:>8,.0f}/s  median {median:6.1f} µs  p99 {p99:7.1f} µs"


def bench(waiting: int) -> list[str]:
    rm = setup(waiting)
    now = 1.0
    enqueue: list[float] = []
    for index in range(SAMPLES):
        timed(enqueue, rm.request, Request(f"extra{index}", 3, CAMERA), now)
    for index in range(SAMPLES):
        rm.cancel(f"extra{index}", now)

    grant: list[float] = []
    requests: list[float] = []
    for index in range(SAMPLES):
        now += 0.001
        holder = rm.holders(f"cam{index % CAMERAS}")[0]
        decisions = timed(grant, rm.release, holder, now)
        assert any(isinstance(d, Granted) for d in decisions)
        timed(requests, rm.request, Request(holder, 1 + index % 3, CAMERA), now)
    assert len(rm.queue()) == waiting

    free: list[float] = []
    for index in range(SAMPLES // 5):
        rm.add_unit(Unit(f"beacon{index}", f"Beacon{index}"), now)
    for index in range(SAMPLES // 5):
        request = Request(f"b{index}", 2, (NeedRequest("beacon", f"Beacon{index}"),))
        assert isinstance(timed(free, rm.request, request, now)[0], Granted)
    return [
        summary("enqueue (request waits)", waiting, enqueue),
        summary("churn: request", waiting, requests),
        summary("churn: release + grant", waiting, grant),
        summary("free unit: request", waiting, free),
    ]


def main() -> None:
    argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0]).parse_args()  # --help; no options
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"RCM core: {CAMERAS} exclusive cameras, {SAMPLES:,} samples per line")
    print(f"Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load average {load}")
    for waiting in (100, 1_000, 10_000):
        start = time.perf_counter()
        for line in bench(waiting):
            print(line)
        print(f"{'':>16}(scenario took {time.perf_counter() - start:.1f} s including setup)")


if __name__ == "__main__":
    main()
