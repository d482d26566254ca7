"""The Distributed Robotics Daemon (`drd start`): one per host. See docs/daemon.md.

Pure cores, tested without a network: `view.ClusterView` (the Component Database's view of the
cluster), `controller.Membership` (when a host's resources join and leave the manager), `logs.RateLimit`.
The shell: `daemon.Daemon` (services on a bus), `controller.Controller` (the RCM and the Mission
Executive on the controller host), `client.ClusterClient` (what `missionctl` uses), `runfiles` (pidfiles).
"""

from __future__ import annotations

from drd.cluster.keys import ClusterKeys
from drd.daemon.view import Change, ClusterView, HostState

__all__ = ["Change", "ClusterKeys", "ClusterView", "HostState"]
