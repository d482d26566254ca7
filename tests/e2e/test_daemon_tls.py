"""Mutual TLS between real daemons on loopback (`cluster.security.mode: tls`).

A throwaway PKI is made in the test's folder: the cluster's CA signs one certificate per host
(subjectAltName IP:127.0.0.1 and DNS:localhost, because zenoh checks the endpoint's name on
connect) and one for the operator's `missionctl`; another CA signs the certificate of an intruder.
Every host has its own folder, as every machine would: the same hosts.yaml, and its own files at
the paths it names (`tls/ca.pem`, `tls/host.pem`, `tls/host.key`, relative to the hosts file).

- controller and ranger1 (the cluster's CA) see each other up, and `missionctl --config` works;
- ranger2, whose certificate and CA are another PKI's, exchanges nothing with them: each side stays
  `never seen` by the other and names the other in its log as refusing its credentials, while
  ranger2 itself works with a client of its own PKI (so its certificates are good, just foreign);
- a client that trusts the cluster's CA gets nothing when it presents no certificate, or one signed
  by another CA (the listener enforces mTLS), and neither does a plaintext tcp client.

The certificates come from the `cryptography` package when it is importable, else from the
`openssl` CLI (`DRD_TEST_PKI=openssl` forces it); without either the tests are skipped. Every
process is ours and killed by pid at the end (`cluster_support`); every wait is bounded.
"""

from __future__ import annotations

import datetime
import importlib.util
import ipaddress
import json
import os
import shutil
import subprocess
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from drd.daemon.client import ClusterClient, NoDaemon
from drd.daemon.peers import REFUSED
from drd.daemon.security import transport
from drd.hosts import load_hosts
from dsl.catalog import Catalog
from tests.cluster_support import DaemonCluster, eventually, running_cluster

zenoh = pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

NAMES = ["controller", "ranger1", "ranger2"]
MEMBERS = NAMES[:2]  # certificates of the cluster's CA; ranger2's come from another CA
SECURITY = "{mode: tls, ca: tls/ca.pem, cert: tls/host.pem, key: tls/host.key}"
OPENSSL = shutil.which("openssl") or "/usr/bin/openssl"


# --- a throwaway PKI --------------------------------------------------------------------------------------


def pki_backend() -> str:
    """`cryptography` or `openssl`: what makes the test certificates; skips when there is neither."""
    wanted = os.environ.get("DRD_TEST_PKI")
    if wanted != "openssl" and importlib.util.find_spec("cryptography") is not None:
        return "cryptography"
    if os.access(OPENSSL, os.X_OK):
        return "openssl"
    pytest.skip("no way to make test certificates: the cryptography package is not importable and there is no"
                f" openssl CLI ({OPENSSL})")


class Authority:
    """A CA whose key and certificate live in `folder`; `issue` writes a host's three TLS files."""

    def __init__(self, folder: Path, name: str, backend: str) -> None:
        self.folder, self.name, self.backend = folder, name, backend
        folder.mkdir(parents=True)
        self.cert, self.key = folder / "ca.pem", folder / "ca.key"
        if backend == "cryptography":
            self._ca_cryptography()
        else:
            openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-days", "2",
                    "-keyout", str(self.key), "-out", str(self.cert), "-subj", f"/CN={name}",
                    "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign")

    def issue(self, dest: Path, common_name: str) -> None:
        """`dest/ca.pem` (this CA), `dest/host.pem` and `dest/host.key` for `common_name` on loopback."""
        dest.mkdir(parents=True)
        shutil.copy(self.cert, dest / "ca.pem")
        if self.backend == "cryptography":
            self._leaf_cryptography(dest, common_name)
            return
        csr = dest / "host.csr"
        openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-keyout",
                str(dest / "host.key"), "-out", str(csr), "-subj", f"/CN={common_name}")
        ext = dest / "host.ext"
        ext.write_text("subjectAltName = IP:127.0.0.1, DNS:localhost\nbasicConstraints = critical, CA:FALSE\n")
        openssl("x509", "-req", "-in", str(csr), "-CA", str(self.cert), "-CAkey", str(self.key), "-set_serial",
                str(int.from_bytes(os.urandom(8), "big")), "-days", "2", "-extfile", str(ext),
                "-out", str(dest / "host.pem"))
        csr.unlink()
        ext.unlink()

    # with `cryptography` (drd itself only reads a certificate's name with it: `certificate_name`)

    def _ca_cryptography(self) -> None:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID

        key = ec.generate_private_key(ec.SECP256R1())
        name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, self.name)])
        usage = x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False,
                              data_encipherment=False, key_agreement=False, key_cert_sign=True, crl_sign=True,
                              encipher_only=False, decipher_only=False)
        cert = (_builder(name, name, key.public_key())
                .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
                .add_extension(usage, critical=True)
                .sign(key, hashes.SHA256()))
        _write_pem(self.key, key)
        _write_pem(self.cert, cert)

    def _leaf_cryptography(self, dest: Path, common_name: str) -> None:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import NameOID

        ca_key = serialization.load_pem_private_key(self.key.read_bytes(), None)
        assert isinstance(ca_key, ec.EllipticCurvePrivateKey)
        issuer = x509.load_pem_x509_certificate(self.cert.read_bytes()).subject
        key = ec.generate_private_key(ec.SECP256R1())
        names = [x509.IPAddress(ipaddress.ip_address("127.0.0.1")), x509.DNSName("localhost")]
        cert = (_builder(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]), issuer, key.public_key())
                .add_extension(x509.SubjectAlternativeName(names), critical=False)
                .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                .sign(ca_key, hashes.SHA256()))
        _write_pem(dest / "host.key", key)
        _write_pem(dest / "host.pem", cert)


def _builder(subject: Any, issuer: Any, public_key: Any) -> Any:
    from cryptography import x509

    now = datetime.datetime.now(datetime.UTC)
    return (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer).public_key(public_key)
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(hours=1)).not_valid_after(now + datetime.timedelta(days=2)))


def _write_pem(path: Path, item: Any) -> None:
    from cryptography.hazmat.primitives import serialization

    if hasattr(item, "private_bytes"):
        data = item.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                  serialization.NoEncryption())
    else:
        data = item.public_bytes(serialization.Encoding.PEM)
    path.write_bytes(data)


def openssl(*args: str) -> None:
    r = subprocess.run([OPENSSL, *args], capture_output=True, text=True, timeout=30, check=False)
    assert r.returncode == 0, f"openssl {' '.join(args)} failed:\n{r.stderr}"


# --- the cluster ---------------------------------------------------------------------------------------------


class TlsCluster:
    """The daemons, each started from a folder of its own (`<host>/hosts.yaml`, `<host>/tls/`)."""

    def __init__(self, c: DaemonCluster, catalog: Catalog) -> None:
        self.c, self.catalog = c, catalog
        self.endpoints = {n: f"tls/127.0.0.1:{p}" for n, p in zip(NAMES, c.ports, strict=True)}

    def hosts_file(self, name: str) -> Path:
        return self.c.folder / name / "hosts.yaml"

    def options(self, hosts_file: Path) -> dict[str, Any]:
        """The zenoh options `missionctl --config hosts_file` would use."""
        return dict(transport(load_hosts(hosts_file, self.catalog)).options)

    def missionctl_json(self, *args: str, config: Path) -> dict[str, Any]:
        r = self.c.missionctl(*args, "--json", "--config", str(config), "--timeout", "5")
        assert r.returncode == 0, r.stderr
        data: dict[str, Any] = json.loads(r.stdout)
        return data

    def client_gets_nothing(self, endpoint: str, options: Mapping[str, Any], timeout: float = 0.5) -> bool:
        """No daemon within `timeout` (a client with the right certificate connects in milliseconds)."""
        try:
            client = ClusterClient.connect([endpoint], cluster=self.c.name, timeout=timeout, options=options)
        except NoDaemon:
            return True
        client.close()
        return False


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory, catalog: Catalog) -> Iterator[TlsCluster]:
    backend = pki_backend()
    folder = tmp_path_factory.mktemp("tls")
    ours = Authority(folder / "pki" / "cluster", "drd-test-cluster-ca", backend)
    foreign = Authority(folder / "pki" / "foreign", "drd-test-foreign-ca", backend)
    with running_cluster(folder, NAMES, security=SECURITY) as c:
        ours.issue(folder / "tls", "missionctl")  # the operator's, beside the main hosts.yaml
        for name in NAMES:
            (ours if name in MEMBERS else foreign).issue(folder / name / "tls", name)
            (folder / name / "hosts.yaml").write_text(c.hosts_file.read_text())
        for name in NAMES:
            c.start(name, hosts_file=folder / name / "hosts.yaml")
        c.wait_ready()
        yield TlsCluster(c, catalog)


def test_daemons_of_the_cluster_ca_see_each_other_up_and_missionctl_works(cluster: TlsCluster) -> None:
    c = cluster.c

    def states() -> dict[str, str]:
        return {h["name"]: h["state"] for h in cluster.missionctl_json("hosts", config=c.hosts_file)["hosts"]}

    eventually(lambda: states() == {"controller": "up", "ranger1": "up", "ranger2": "down"},
               "controller and ranger1 up (and ranger2 down) in `missionctl hosts`", 20, poll=0.2)
    hosts = {h["name"]: h for h in cluster.missionctl_json("hosts", config=c.hosts_file)["hosts"]}
    assert {n: h["endpoint"] for n, h in hosts.items()} == cluster.endpoints
    assert hosts["ranger1"]["reason"] == "joined" and hosts["ranger1"]["pid"] == c.pid("ranger1")
    assert hosts["ranger1"]["cpu"] is not None

    units = {u["id"] for u in cluster.missionctl_json("resources", config=c.hosts_file)["units"]}
    assert "ranger1.camera" in units and not any(u.startswith("ranger2.") for u in units)
    for name in MEMBERS:
        assert f"bus: mutual TLS; listening on {cluster.endpoints[name]}" in c.log(name)
        assert "Traceback" not in c.log(name)


def test_a_daemon_of_another_ca_exchanges_nothing_and_is_named_in_the_logs(cluster: TlsCluster) -> None:
    c = cluster.c
    refusals = [(me, peer) for me in NAMES for peer in NAMES if me != peer and (me == "ranger2") != (peer == "ranger2")]
    for me, peer in refusals:
        line = f"peer {peer} unreachable: {cluster.endpoints[peer]}: {REFUSED}"
        eventually(lambda me=me, line=line: line in c.log(me),  # type: ignore[misc]
                   f"{me} to name {peer} as refusing our credentials", 20, poll=0.1)

    status = cluster.missionctl_json("status", config=c.hosts_file)
    assert status["answered_by"] == "controller"
    assert status["daemon"]["unreachable"] == {"ranger2": f"{cluster.endpoints['ranger2']}: {REFUSED}"}
    ranger2 = next(h for h in status["hosts"] if h["name"] == "ranger2")
    assert (ranger2["state"], ranger2["reason"], ranger2["cpu"], ranger2["pid"]) == ("down", "never seen", None, None)
    assert not any(e["host"] == "ranger2" for e in status["events"])

    # the foreign PKI works in itself: ranger2 answers a client of its own CA, and has seen nobody
    mine = cluster.missionctl_json("hosts", config=cluster.hosts_file("ranger2"))
    assert mine["answered_by"] == "ranger2"
    assert {h["name"]: (h["state"], h["reason"]) for h in mine["hosts"]} == {
        "controller": ("down", "never seen"), "ranger1": ("down", "never seen"), "ranger2": ("up", "this host")}
    assert " up: " not in c.log("ranger2")


def test_a_client_without_a_certificate_of_the_cluster_ca_gets_nothing(cluster: TlsCluster) -> None:
    c, endpoint = cluster.c, cluster.endpoints["controller"]
    ours = cluster.options(c.hosts_file)
    assert not cluster.client_gets_nothing(endpoint, ours, 5.0), "the operator's certificate must get in"

    no_certificate = {k: v for k, v in ours.items() if "connect_" not in k and "enable_mtls" not in k}
    assert cluster.client_gets_nothing(endpoint, no_certificate), "a client without a certificate got in"
    foreign = cluster.options(cluster.hosts_file("ranger2"))
    foreign_cert = ours | {k: v for k, v in foreign.items() if "connect_" in k}  # trusts our CA, presents theirs
    assert cluster.client_gets_nothing(endpoint, foreign_cert), "a certificate of another CA got in"
    assert cluster.client_gets_nothing(endpoint.replace("tls/", "tcp/"), {}), "a plaintext client got in"

    r = c.missionctl("hosts", "--connect", endpoint.replace("tls/", "tcp/"), "--timeout", "0.5")
    assert r.returncode == 2 and "no drd daemon answered" in r.stderr


def test_a_malformed_key_refuses_to_start_naming_the_file(tmp_path: Path) -> None:
    Authority(tmp_path / "pki", "drd-test-ca", pki_backend()).issue(tmp_path / "tls", "controller")
    (tmp_path / "tls" / "host.key").write_text("not a key\n")
    c = DaemonCluster(tmp_path, ["controller", "ranger1"], security=SECURITY)
    try:
        r = c.drd("start", "--host", "controller", "--config", str(c.hosts_file), "--run-dir", str(tmp_path / "run"))
        assert r.returncode == 2
        assert not list((tmp_path / "run").rglob("*.pid"))
        assert f"cluster.security.key: {tmp_path / 'tls' / 'host.key'}" in r.stderr, r.stderr
        assert "will not start without it" in r.stderr and "Traceback" not in r.stderr
    finally:
        c.close()
