"""docs/hosts.md lists the parsed configuration's dataclasses with their fields, as drd.hosts defines them (docs
audit 6: `Placement` had no `affinity` there, and four others had lost fields)."""

from __future__ import annotations

import dataclasses
import re

from drd import hosts
from tests.conftest import ROOT


def test_the_dataclasses_hosts_md_lists_have_exactly_those_fields() -> None:
    text = " ".join((ROOT / "docs" / "hosts.md").read_text(encoding="utf-8").split())
    listed = dict(re.findall(r"`(Cluster|Host|Device|Robot|Security|Placement)\(([^)`]*)\)`", text))
    assert sorted(listed) == ["Cluster", "Device", "Host", "Placement", "Robot", "Security"]
    for name, fields in listed.items():
        assert [f.strip() for f in fields.split(",")] == [f.name for f in dataclasses.fields(getattr(hosts, name))]
