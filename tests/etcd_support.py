"""A real etcd cluster on loopback for the failover tests (issue #16): `etcd` processes of the distribution's package
(Debian `etcd-server`, installed by `.ci/run`), each with its own data directory under the test's folder and free
ports, killed by pid afterwards. Where `etcd` is not installed the tests using it skip, saying why.

    with etcd_cluster(tmp_path, 3) as etcd:
        etcd.urls   # ["http://127.0.0.1:PORT", ...]
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from drd.etcd import Etcd, EtcdError
from tests.net_support import free_ports

ETCD = shutil.which("etcd")
SKIP = ("etcd is not installed (the Debian package etcd-server; .ci/run installs it): the standby-controller"
        " tests need a real etcd cluster")
START_TIMEOUT = 30.0




def need_etcd() -> None:
    if ETCD is None:
        pytest.skip(SKIP)


class EtcdCluster:
    """`n` etcd members on loopback, started together (one raft cluster)."""

    def __init__(self, folder: Path, n: int = 3) -> None:
        need_etcd()
        assert ETCD is not None
        self.folder = folder
        ports = free_ports(2 * n)
        self.names = [f"e{i}" for i in range(n)]
        self.urls = [f"http://127.0.0.1:{ports[2 * i]}" for i in range(n)]
        peers = [f"http://127.0.0.1:{ports[2 * i + 1]}" for i in range(n)]
        initial = ",".join(f"{name}={peer}" for name, peer in zip(self.names, peers, strict=True))
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        token = f"drd-test-{os.getpid()}-{ports[0]}"
        for name, url, peer in zip(self.names, self.urls, peers, strict=True):
            log = (folder / f"{name}.log").open("ab")
            cmd = [ETCD, "--name", name, "--data-dir", str(folder / f"{name}.etcd"),
                   "--listen-client-urls", url, "--advertise-client-urls", url,
                   "--listen-peer-urls", peer, "--initial-advertise-peer-urls", peer,
                   "--initial-cluster", initial, "--initial-cluster-token", token,
                   "--initial-cluster-state", "new", "--log-level", "warn"]
            with log:
                self.procs[name] = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                                                    env={**os.environ, "ETCD_UNSUPPORTED_ARCH": ""})

    def wait_ready(self) -> None:
        """Every member answers a read (the raft cluster has a leader)."""
        deadline = time.monotonic() + START_TIMEOUT
        for url in self.urls:
            client = Etcd([url], timeout=1.0)
            while True:
                try:
                    client.get("drd-test-ready")
                    break
                except EtcdError as e:
                    for name, proc in self.procs.items():
                        if proc.poll() is not None:
                            pytest.fail(f"etcd {name} exited with {proc.returncode}: "
                                        f"{(self.folder / f'{name}.log').read_text(errors='replace')[-2000:]}")
                    if time.monotonic() > deadline:
                        pytest.fail(f"etcd at {url} did not answer within {START_TIMEOUT:g} s: {e}")
                    time.sleep(0.1)

    def close(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                try:
                    os.kill(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            proc.wait(timeout=10)


@contextmanager
def etcd_cluster(folder: Path, n: int = 3) -> Iterator[EtcdCluster]:
    folder.mkdir(parents=True, exist_ok=True)
    cluster = EtcdCluster(folder, n)
    try:
        cluster.wait_ready()
        yield cluster
    finally:
        cluster.close()
