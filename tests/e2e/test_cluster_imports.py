"""A mission that imports runs on a cluster as it validates and dry-runs (users audit 12, D1): `missionctl run`
sends the imported files' texts with the mission, read beside it, and the controller compiles those, never a file
of its own disk (the daemons here run from the repository's root, the mission lives in the test's folder: the
controller used to look for `lib/common.mission` in its own working directory and refuse the run). Real daemons on
loopback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cluster_support import instances_only_hosts, serving_cluster

from dsl import compile_text
from dsl.catalog import Catalog

MAIN = 'import "lib/common.mission"\n\nmission Main {\n    Settle\n}\n'
COMMON = "behavior Settle {\n    Wait(duration: 1s) as Pause\n}\n"


def test_a_mission_that_imports_runs_on_the_cluster(tmp_path: Path) -> None:
    (tmp_path / "missions" / "lib").mkdir(parents=True)
    (tmp_path / "missions" / "lib" / "common.mission").write_text(COMMON)
    main = tmp_path / "missions" / "main.mission"
    main.write_text(MAIN)
    with serving_cluster(tmp_path, ["controller", "w1"], instances_only_hosts) as cluster:
        done = cluster.missionctl("run", str(main), "--config", str(cluster.hosts_file), "--json")
        assert done.returncode == 0, (done.stdout[-2000:], done.stderr[-2000:], cluster.log("controller")[-3000:])
        report = json.loads(done.stdout)
        assert report["outcome"] == "success"
        assert any(t["path"].endswith("Settle/Pause") for t in report["timeline"])  # the imported behavior ran
        (tmp_path / "missions" / "lib" / "common.mission").unlink()
        refused = cluster.missionctl("run", str(main), "--config", str(cluster.hosts_file))
        assert refused.returncode == 2  # refused by the client, naming the file it could not read beside it
        assert "lib/common.mission" in refused.stdout + refused.stderr


def test_the_controller_compiles_only_what_it_was_sent(tmp_path: Path, catalog: Catalog,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """A file of the same name on the compiling side's disk is never read: the sent text wins, a missing one is a
    located error."""
    (tmp_path / "missions" / "lib").mkdir(parents=True)
    (tmp_path / "missions" / "lib" / "common.mission").write_text("behavior Settle {\n    Nope(x: 1)\n}\n")
    monkeypatch.chdir(tmp_path)  # where a disk read would find the wrong file
    sent = compile_text(MAIN, catalog, "missions/main.mission", imports={"missions/lib/common.mission": COMMON})
    assert sent.ok, [d.message for d in sent.diagnostics]
    missing = compile_text(MAIN, catalog, "missions/main.mission", imports={})
    assert not missing.ok
    (d,) = [d for d in missing.diagnostics if d.code == "io"]
    assert d.message == "cannot read imported file missions/lib/common.mission: it was not sent with the mission"
    assert (d.span.file, d.span.line) == ("missions/main.mission", 1)


def test_a_file_imported_under_two_names_is_sent_under_both(tmp_path: Path, catalog: Catalog,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Reverify audit 14, D1: `sub/b.mission` and `../app/sub/b.mission` (from another folder) are one file; the client
    read it once, sent it under the first name, and the controller refused the second as not sent."""
    from dsl.errors import Reporter
    from dsl.loader import import_aliases, imported_texts, load_file

    (tmp_path / "app" / "sub").mkdir(parents=True)
    (tmp_path / "lib").mkdir()
    main = 'import "../lib/a.mission"\nimport "sub/b.mission"\nmission ImpMain {\n    start -> A1\n    A1 -> B1\n}\n'
    (tmp_path / "app" / "main.mission").write_text(main)
    (tmp_path / "lib" / "a.mission").write_text('import "../app/sub/b.mission"\nbehavior A1 { Wait(duration: 1s) }\n')
    (tmp_path / "app" / "sub" / "b.mission").write_text("behavior B1 { Wait(duration: 1s) }\n")
    monkeypatch.chdir(tmp_path / "app")
    program = load_file("main.mission", Reporter())
    sent, aliases = imported_texts(program), import_aliases(program)
    assert set(sent) | set(aliases) == {"../lib/a.mission", "sub/b.mission", "../lib/../app/sub/b.mission"}
    monkeypatch.chdir(tmp_path / "lib")  # the controller's side: nowhere near the files
    compiled = compile_text(main, catalog, "main.mission", imports=sent, aliases=aliases)
    assert compiled.ok, [d.message for d in compiled.diagnostics]
