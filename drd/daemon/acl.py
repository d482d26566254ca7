"""Who may do what on a cluster's bus: zenoh's own access control, from `cluster.security.roles` (docs/security.md).

Every daemon enforces the same rules on the links clients open to it (zenoh's `access_control`):

- `daemon` (the daemons' own user, and the names listed under `daemon`): everything;
- `operator`: ask what it likes of the daemons but a Creator's or the simulator's own key (the controller's to
  call), so it runs, stops and tunes missions and reads everything; it sends nothing else: no publication (no
  load report, no announcement, no record), no liveliness token, no queryable, no reply;
- `observer`: as an operator, but it may not ask to run, stop, move or tune (`missions/run`, `missions/migrate`,
  `executive`, `host/*/tune`): it reads status, the Component Database, the manager's resources, and missions' records.

Why deny rules over `default_permission: allow` (and not allow rules over `deny`): zenoh's user/password
authentication is one-way, so the daemon that *opens* a link to another daemon does not learn the other's user:
under a default of deny it could send nothing. Links clients open are always authenticated where they arrive, so
the deny rules of their role apply there. Two things make deny rules complete: every user of the daemons'
password file must have a role (`check_roles`: a user matching no rule would be allowed everything), and the
services that change state answer only a query addressed to exactly their key (a `drd/<cluster>/**` query that
no deny rule names is refused by the service itself, `drd.bus.keys.is_concrete`). Pure: the configuration as data.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from drd.config import ConfigProblem
from drd.hosts import Cluster, Role, SecurityMode

#: What only daemons may ask, and what an observer may not ask either, under `drd/<cluster>/`.
DAEMONS_ONLY = ("host/*/creator", "sim")
OPERATORS_ONLY = ("missions/run", "missions/migrate", "executive", "host/*/tune")
#: Every kind of message zenoh's access control knows (what a named subject is allowed under a default of deny).
ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply", "liveliness_token",
                "declare_liveliness_subscriber", "liveliness_query"]
#: What a client never sends: it publishes, serves and answers nothing.
NEVER_FROM_CLIENTS = ["put", "delete", "declare_queryable", "reply", "liveliness_token"]
#: What only the acting controller (or a standby) serves and publishes, and what only the simulator's host serves,
#: under `drd/<cluster>/` (`security.per_host`).
CONTROLLERS_ONLY = ("missions/run", "missions/migrate", "executive", "executive/**", "rcm/**", "mission/**")
SIMULATORS_ONLY = ("sim", "world")


def access_control(cluster: Cluster) -> dict[str, Any] | None:
    """zenoh's `access_control` for the cluster's daemons, or None when no roles are configured (then every
    authenticated peer may do everything, as before roles existed)."""
    sec = cluster.security
    if not (sec.roles or sec.per_host) or sec.mode is SecurityMode.NONE:
        return None
    root = f"drd/{cluster.name}"
    field = "usernames" if sec.mode is SecurityMode.PASSWORD else "cert_common_names"
    rules = [
        {"id": "clients-send-nothing", "messages": NEVER_FROM_CLIENTS, "flows": ["ingress"], "permission": "deny",
         "key_exprs": ["**"]},
        {"id": "daemons-only", "messages": ["query"], "flows": ["ingress"], "permission": "deny",
         "key_exprs": [f"{root}/{k}" for k in DAEMONS_ONLY]},
        {"id": "operators-only", "messages": ["query"], "flows": ["ingress"], "permission": "deny",
         "key_exprs": [f"{root}/{k}" for k in OPERATORS_ONLY]},
    ]
    grants = {"operator": ["clients-send-nothing", "daemons-only"],
              "observer": ["clients-send-nothing", "daemons-only", "operators-only"]}
    roles = [role for role in grants if sec.roles.get(role)]
    subjects = [{"id": role, field: list(sec.roles[role])} for role in roles]
    policies = [{"id": f"{role}-policy", "rules": grants[role], "subjects": [role]} for role in roles]
    if sec.per_host:
        host_rules, host_subjects, host_policies = _per_host(cluster, root, field)
        rules, subjects, policies = rules + host_rules, subjects + host_subjects, policies + host_policies
    if sec.mode is SecurityMode.TLS and sec.roles:
        return _known_certificates_only(sec.roles.get("daemon", ()), rules, subjects, policies)
    if not policies:  # only daemons listed: nothing to restrict
        return None
    return {"enabled": True, "default_permission": "allow", "rules": rules, "subjects": subjects,
            "policies": policies}


def _known_certificates_only(daemons: Iterable[str], rules: list[dict[str, Any]], subjects: list[dict[str, Any]],
                             policies: list[dict[str, Any]]) -> dict[str, Any]:
    """With tls and roles: a certificate the CA signed for a name in no role may do nothing (security audit D2: it
    acted as a daemon, and stopped missions). TLS authenticates both ends of every link, so a default of deny
    leaves no daemon mute: each named subject (the daemons, each role, each host with `per_host`) is allowed
    everything but what its deny rules take away (zenoh: a matching deny wins over an allow)."""
    everything = {"id": "everything", "messages": ALL_MESSAGES, "flows": ["ingress", "egress"],
                  "permission": "allow", "key_exprs": ["**"]}
    subjects = [*subjects, {"id": "daemon", "cert_common_names": list(daemons)}] if daemons else subjects
    policies = [*policies, {"id": "daemon-policy", "rules": [], "subjects": ["daemon"]}] if daemons else policies
    return {"enabled": True, "default_permission": "deny", "rules": [*rules, everything], "subjects": subjects,
            "policies": [{**p, "rules": [*p["rules"], "everything"]} for p in policies]}


def _per_host(cluster: Cluster, root: str, field: str) -> tuple[list[dict[str, Any]], list[dict[str, Any]],
                                                                 list[dict[str, Any]]]:
    """`security.per_host`: each daemon (its user, or its certificate's common name, `field`: its host's name)
    speaks for its own host only. It publishes, serves,
    answers and declares tokens under no other host's keys (`host/<other>`, `instance/<other>`); a host that is no
    controller serves and publishes none of the controller's keys and calls no Creator; a host that is not the
    simulator's serves neither of its keys; a host that is no controller asks none of the operators' services
    either (run, stop, move or tune a mission: security audit D3). So a daemon's credentials cannot fake another
    host's load, liveliness or announcement, answer for it, command a Creator, or stop a mission. Where the rules
    apply: with tls on every link (mutual); with a password on every link the daemon opened (that authentication is
    one-way), so with routers on every link."""
    sending = ["put", "delete", "declare_queryable", "reply", "liveliness_token"]
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for host in cluster.hosts:
        others = [h.name for h in cluster.hosts if h.name != host.name]
        ids = []
        if others:
            keys = [k for o in others for k in (f"{root}/host/{o}", f"{root}/host/{o}/**", f"{root}/instance/{o}/**")]
            rules.append({"id": f"not-for-others-{host.name}", "messages": sending, "flows": ["ingress"],
                          "permission": "deny", "key_exprs": keys})
            ids.append(f"not-for-others-{host.name}")
        if Role.CONTROLLER not in host.roles:  # nor does it run, stop, move or tune missions: an operator's to ask
            ids += ["not-a-controller", "no-creator-calls", "operators-only"]
        if Role.SIMULATOR not in host.roles:
            ids.append("not-the-simulator")
        subjects.append({"id": f"host-{host.name}", field: [host.name]})
        policies.append({"id": f"host-{host.name}-policy", "rules": ids, "subjects": [f"host-{host.name}"]})
    rules += [
        {"id": "not-a-controller", "messages": ["put", "declare_queryable", "reply"], "flows": ["ingress"],
         "permission": "deny", "key_exprs": [f"{root}/{k}" for k in CONTROLLERS_ONLY]},
        {"id": "no-creator-calls", "messages": ["query"], "flows": ["ingress"], "permission": "deny",
         "key_exprs": [f"{root}/host/*/creator"]},
        {"id": "not-the-simulator", "messages": ["declare_queryable", "reply"], "flows": ["ingress"],
         "permission": "deny", "key_exprs": [f"{root}/{k}" for k in SIMULATORS_ONLY]},
    ]
    return rules, subjects, policies


def check_roles(cluster: Cluster, users: Iterable[str]) -> list[ConfigProblem]:
    """Every user of the daemons' password file has a role (see the module); problems name the file and key."""
    sec = cluster.security
    if not (sec.roles or sec.per_host) or sec.mode is not SecurityMode.PASSWORD:
        return []
    hosts = {h.name for h in cluster.hosts} if sec.per_host else set()
    return [ConfigProblem(cluster.source, "cluster.security.roles",
                          f"user {u} of {sec.password_file} has no role: give it one (operator, observer) or remove"
                          " its line (a user with no role would be allowed everything)")
            for u in users if sec.role_of(u) is None and u not in hosts]
