"""From `cluster.security` in hosts.yaml to zenoh's transport configuration; never a silent plaintext.

- `none`: nothing; an open cluster (a laptop, an isolated test network). Endpoints as written.
- `password`: zenoh user/password authentication (`transport/auth/usrpwd`). A peer that does not
  present a user and password listed in `password_file` is refused, and so are we by it. Links are
  authenticated, not encrypted. A client presents `$DRD_USER` (default: the daemons' `user`); with
  `security.roles`, the daemons enforce what each role may do (`drd.daemon.acl`).
- `tls`: mutual TLS (`transport/link/tls`, `enable_mtls`); both sides present a certificate signed
  by `ca`. `tcp/H:P` endpoints become `tls/H:P`, and only `tls` links are allowed.

`password_file` is zenoh's dictionary format, one `user:password` per line (the password is
everything after the first colon; blank lines are allowed): it lists who may join, and the line
of `security.user` is what this process presents. Every problem with a file (missing, unreadable,
badly formed, no line for the user) raises `SecurityError` naming the file and the key: a daemon
with security configured never starts without it.
"""

from __future__ import annotations

import binascii
import ipaddress
import os
import re
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drd.config import ConfigError, ConfigProblem
from drd.daemon.acl import access_control, check_roles
from drd.hosts import Cluster, Role, Security, SecurityMode, check_files

#: The user a client presents itself as in password mode (`missionctl` on an operator's machine).
USER_ENV = "DRD_USER"


class SecurityError(ConfigError):
    """The security settings cannot be applied: each problem names the file and its key."""


@dataclass(frozen=True, slots=True)
class Transport:
    """How one process joins the cluster's bus: endpoints by host, and zenoh options."""

    mode: SecurityMode
    endpoints: Mapping[str, str]
    options: Mapping[str, Any] = field(default_factory=dict)
    routers: tuple[str, ...] = ()  # the hosts with the role router (none: every daemon meets every other)
    #: the name the daemons' access control knows this session by: its user (password) or its certificate's
    #: common name (tls); "" in mode none
    identity: str = ""

    def others(self, me: str) -> dict[str, str]:
        """Whom the daemon of `me` meets, in order: every other host, or with routers the other routers only.
        A client of the routers connects to the first it reaches, so each client's list starts at a router of its
        own (by a hash of its name: the same on every start), and the clients spread over the routers."""
        found = {h: e for h, e in self.endpoints.items() if h != me and (not self.routers or h in self.routers)}
        if not self.routers or me in self.routers or not found:
            return found
        names = list(found)
        first = zlib.crc32(me.encode()) % len(names)
        return {h: found[h] for h in names[first:] + names[:first]}

    def dials(self, me: str) -> dict[str, str]:
        """What the daemon of `me` keeps a link to by dialing it: among peers (or among routers), only those listed
        before `me` in the hosts file; the others dial `me`. A client of the routers dials them all (`others`).

        One dialer per pair, because two peers that dial each other share a transport of two links, and when the
        links expire one by one (a frozen or partitioned host coming back), zenoh can merge the redial into the
        stale transport and never send one side's declarations again: the host reports its load and is never up
        (zenoh issue #2806, seen here in 1 of 29 SIGSTOPs; docs/design.md "One dialer per pair")."""
        found = self.others(me)
        if self.zenoh_mode(me) == "client":
            return found
        names = list(self.endpoints)
        before = set(names[:names.index(me)]) if me in names else set()
        return {h: e for h, e in found.items() if h in before}

    def zenoh_mode(self, me: str) -> str:
        """The zenoh mode of `me`'s session: a peer among peers, a router, or a client of the routers."""
        if not self.routers:
            return "peer"
        return "router" if me in self.routers else "client"

    def listens(self, me: str) -> bool:
        """Whether `me`'s daemon listens on its endpoint (a client of the routers does not)."""
        return self.zenoh_mode(me) != "client"

    def entry_points(self) -> list[str]:
        """Where a client (missionctl) connects: the routers, else every daemon."""
        return [e for h, e in self.endpoints.items() if not self.routers or h in self.routers]

    def client_mode(self) -> str:
        """The zenoh mode of a client's session (missionctl): with routers, a zenoh `client` of them, as the daemons
        are, linked to one router at a time (the next one when it fails), so a request reaches each daemon once; a
        peer linked to two routers got every query once through each, and the controller ran each mission twice
        (docs/design.md "One router at a time for missionctl"). Without routers, a peer linked to every daemon:
        peers do not forward to each other, so there too a query arrives once."""
        return "client" if self.routers else "peer"


def transport(cluster: Cluster, user: str | None = None, *, daemon: bool = False,
              host: str | None = None) -> Transport:
    """The cluster's endpoints and zenoh options for its security mode. `user`: who a client presents itself as
    (password mode; default: `$DRD_USER`, else the daemons' user); `daemon`: a daemon's, which enforces the
    roles of `security.roles` (`drd.daemon.acl`); `host`: that daemon's host, its user with `security.per_host`.

    Raises:
        SecurityError: a file is missing, unreadable or badly formed, or an endpoint cannot carry TLS.
    """
    sec = cluster.security
    problems = list(check_files(cluster))
    if problems:
        raise SecurityError(problems)
    endpoints = {h.name: h.endpoint for h in cluster.hosts}
    routers = tuple(h.name for h in cluster.hosts if Role.ROUTER in h.roles)
    acl = access_control(cluster) if daemon else None
    if sec.mode is SecurityMode.NONE:
        exposed = sorted(h for h, e in endpoints.items() if not is_loopback(e))
        if daemon and exposed and not sec.open:
            raise SecurityError([ConfigProblem(cluster.source, "cluster.security", (
                f"mode none on a network: {', '.join(exposed)} {'listens' if len(exposed) == 1 else 'listen'} beyond"
                " this machine, where anyone who reaches"
                " them could run missions and drive robots; use mode password or tls, or say `open: true` if that"
                " is what you want"))])
        return Transport(sec.mode, endpoints, routers=routers)
    if sec.mode is SecurityMode.PASSWORD:
        assert sec.user is not None and sec.password_file is not None  # parse_hosts requires both
        who = _user(sec, user, host if daemon else None, daemon)
        password = read_password(cluster.source, sec.password_file, who)
        unknown = check_roles(cluster, dictionary_users(sec.password_file)) if daemon else []
        if unknown:
            raise SecurityError(unknown)
        return Transport(sec.mode, endpoints, routers=routers, identity=who, options={
            "transport/auth/usrpwd/user": who,
            "transport/auth/usrpwd/password": password,
            "transport/auth/usrpwd/dictionary_file": sec.password_file,
            **({"access_control": acl} if acl else {}),
        })
    return _tls_transport(cluster, routers, acl, host if daemon else None)


def _tls_transport(cluster: Cluster, routers: tuple[str, ...], acl: dict[str, Any] | None,
                   daemon_host: str | None) -> Transport:
    """`transport` in mode tls: `tls/` endpoints, the PEM files checked, the certificate's name known (and, for the
    daemon of `daemon_host`, checked against the access control)."""
    sec = cluster.security
    assert sec.ca is not None and sec.cert is not None and sec.key is not None  # parse_hosts requires all three
    problems, tls = [], {}
    for name, endpoint in ((h.name, h.endpoint) for h in cluster.hosts):
        proto, _, address = endpoint.partition("/")
        if proto != "tcp":
            problems.append(ConfigProblem(cluster.source, f"hosts.{name}.endpoint",
                                          f"security mode tls needs a tcp endpoint (it becomes tls/...),"
                                          f" got {endpoint}"))
        tls[name] = f"tls/{address}"
    problems += [p for key, wanted in TLS_PEM.items() if (p := check_pem(cluster.source, key, getattr(sec, key),
                                                                          wanted)) is not None]
    if problems:
        raise SecurityError(problems)
    name = certificate_name(cluster.source, sec.cert)
    if daemon_host is not None:
        _check_daemon_name(cluster, daemon_host, name)
    return Transport(sec.mode, tls, routers=routers, identity=name, options={
        **({"access_control": acl} if acl else {}),
        "transport/link/protocols": ["tls"],
        "transport/link/tls/root_ca_certificate": sec.ca,
        "transport/link/tls/listen_certificate": sec.cert,
        "transport/link/tls/listen_private_key": sec.key,
        "transport/link/tls/connect_certificate": sec.cert,
        "transport/link/tls/connect_private_key": sec.key,
        "transport/link/tls/enable_mtls": True,
    })


def certificate_name(source: str, path: str) -> str:
    """The common name of the certificate in `path`: what the daemons' access control knows a tls peer by (zenoh's
    `cert_common_names`), so `missionctl` can refuse at once what its role does not allow (the daemons drop such
    a request without a reply) and a daemon can say at start that the others will not hear it.

    Raises:
        SecurityError: the file holds no certificate `cryptography` can read, or one with no common name.
    """
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    where = "cluster.security.cert"
    try:
        cert = x509.load_pem_x509_certificate(Path(path).read_bytes())
    except (OSError, ValueError) as e:
        raise SecurityError([ConfigProblem(source, where, f"{path}: not a readable certificate ({e})")]) from None
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not names:
        raise SecurityError([ConfigProblem(source, where, (
            f"{path}: the certificate has no common name (CN); with tls the daemons know a peer by it"))])
    return str(names[0].value)


def _check_daemon_name(cluster: Cluster, host: str, name: str) -> None:
    """With roles or `per_host`, a daemon's certificate must carry a name its peers' access control allows: one
    listed under `roles.daemon`, or with `per_host` its host's name. Otherwise every peer would drop what it sends
    (default deny) and it would start, alone, with no error anywhere."""
    sec = cluster.security
    allowed = [*sec.roles.get("daemon", ()), *([host] if sec.per_host else [])]
    if not (sec.roles or sec.per_host) or name in allowed:
        return
    wanted = " or ".join(filter(None, [f"its host's name, {host} (per_host)" if sec.per_host else "",
                                       "a name listed under cluster.security.roles.daemon"]))
    raise SecurityError([ConfigProblem(cluster.source, "cluster.security.cert", (
        f"{sec.cert}: the certificate's common name is {name}, but host {host}'s must be {wanted}: the other daemons"
        " would refuse everything it sends"))])


def _user(sec: Security, user: str | None, host: str | None, daemon: bool) -> str:
    """Who a session presents itself as: a daemon its host (`per_host`) or the daemons' user; a client `user`,
    else `$DRD_USER`, else the daemons' user."""
    assert sec.user is not None  # mode password requires it
    if daemon:
        return host if sec.per_host and host else sec.user
    return user or os.environ.get(USER_ENV) or sec.user


#: The PEM blocks zenoh looks for in each TLS file (rustls_pemfile): certificates, or an unencrypted key.
TLS_PEM: Mapping[str, tuple[str, ...]] = {
    "ca": ("CERTIFICATE",),
    "cert": ("CERTIFICATE",),
    "key": ("PRIVATE KEY", "RSA PRIVATE KEY", "EC PRIVATE KEY"),
}
_PEM = re.compile(r"-----BEGIN ([A-Z0-9 ]+)-----([A-Za-z0-9+/=\s]*?)-----END \1-----")


def check_pem(source: str, key: str, path: str, wanted: Sequence[str]) -> ConfigProblem | None:
    """Why the file at `path` has no well-formed PEM block labelled one of `wanted`, or None.

    zenoh reads the TLS files only when the session opens, and its errors name neither the file nor
    the key ("peer sent no certificates" for a certificate file without a certificate).
    """
    where = f"cluster.security.{key}"
    try:
        text = Path(path).read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as e:
        return ConfigProblem(source, where, f"{path}: not a PEM file ({e})")
    labels = []
    for label, body in _PEM.findall(text):
        try:
            binascii.a2b_base64("".join(body.split()), strict_mode=True)
        except binascii.Error:
            return ConfigProblem(source, where, f"{path}: the {label} block is not valid base64")
        if label in wanted:
            return None
        labels.append(label)
    if "ENCRYPTED PRIVATE KEY" in labels:
        return ConfigProblem(source, where, f"{path}: the key is encrypted; zenoh needs an unencrypted key")
    found = f"found only {', '.join(dict.fromkeys(labels))}" if labels else "found none"
    return ConfigProblem(source, where, f"{path}: expected a PEM {' or '.join(wanted)} block, {found}")


def read_password(source: str, path: str, user: str) -> str:
    """The password of `user` in a zenoh dictionary file (`user:password` lines).

    Raises:
        SecurityError: the file cannot be read, has a line without `:`, or has no line for `user`.
    """
    key = "cluster.security.password_file"
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise SecurityError([ConfigProblem(source, key, f"cannot read {path}: {e}")]) from e
    found = None
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        name, colon, password = line.partition(":")
        if not colon or not name:
            raise SecurityError([ConfigProblem(source, key, f"{path}:{number}: expected user:password")])
        if name == user and found is None:
            found = password
    if found is None:
        raise SecurityError([ConfigProblem(source, key, f"{path}: no line {user}:PASSWORD for user {user!r}")])
    if not found:
        raise SecurityError([ConfigProblem(source, key, f"{path}: the password of user {user!r} is empty")])
    return found


def is_loopback(endpoint: str) -> bool:
    """Whether an endpoint (`tcp/HOST:PORT`) listens on this machine only."""
    host = endpoint.partition("/")[2].rpartition(":")[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a DNS name: it may be anywhere
        return False


def dictionary_users(path: str) -> list[str]:
    """The users of a zenoh dictionary file (already read by `read_password`, so well formed)."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    return list(dict.fromkeys(line.partition(":")[0] for line in lines if line.strip()))


def describe(mode: SecurityMode, endpoints: Sequence[str]) -> str:
    """One line for the logs: how this process talks to the others."""
    what = {SecurityMode.NONE: "no authentication (open cluster)",
            SecurityMode.PASSWORD: "user/password authentication",
            SecurityMode.TLS: "mutual TLS"}[mode]
    return f"{what}; listening on {', '.join(endpoints) or 'nothing'}"
