"""`drd start --detach` imports a user's components as a foreground `drd start` and a dry-run do: from PYTHONPATH,
not from the working directory first (reverify audit 7, D-e). The detached daemon is started again with
`python -m`, which puts the working directory first on the import path, so a copy of the user's package there
shadowed the one PYTHONPATH names: the dry-run ran one and the cluster another. Here the working directory holds
a broken `pathkit.py` and PYTHONPATH a good one; the mission on a detached cluster must run the good one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from cluster_support import corridor_hosts, running_cluster

from tests.conftest import ROOT

GOOD = "from components.behaviors.wait import Wait\n\n\nclass Pause(Wait):\n    pass\n"
BROKEN = 'raise ImportError("the copy in the working directory was imported")\n'
#: `drd` and `missionctl` as their console scripts run: without the working directory on the import path
DRD = [sys.executable, "-P", "-m", "drd.cli.drd"]
MISSIONCTL = [sys.executable, "-P", "-c", "from drd.cli.missionctl import main; main()"]
MANIFEST = """name: Pause
kind: behavior
description: Wait, from the user's package.
entry_point: pathkit:Pause
params:
  duration: {type: duration, default: 1s, min: 0s, max: 1h, description: how long.}
"""


def test_a_detached_daemon_imports_from_pythonpath_not_from_its_working_directory(tmp_path: Path) -> None:
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "pathkit.py").write_text(GOOD)
    (tmp_path / "pathkit.py").write_text(BROKEN)  # the working directory's copy
    (tmp_path / "comps" / "Pause").mkdir(parents=True)
    (tmp_path / "comps" / "Pause" / "manifest.yaml").write_text(MANIFEST)
    (tmp_path / "pause.mission").write_text("mission Pausing {\n    Pause(duration: 1s)\n}\n")
    env = {**os.environ, "DRD_COMPONENTS": str(tmp_path / "comps"),
           "PYTHONPATH": os.pathsep.join([str(tmp_path / "lib"), str(ROOT)])}
    with running_cluster(tmp_path, ["controller", "ranger1"]) as c:
        c.hosts_file.write_text(corridor_hosts(c))
        config = ["--config", str(c.hosts_file), "--run-dir", str(c.run_dir)]
        try:
            for name in c.names:
                r = subprocess.run([*DRD, "start", "--host", name, *config, "--detach"], cwd=tmp_path, env=env,
                                   capture_output=True, text=True, timeout=60, check=False)
                assert r.returncode == 0, (r.stdout, r.stderr)
            c.wait_up()
            r = subprocess.run([*MISSIONCTL, "run", str(tmp_path / "pause.mission"), "--config", str(c.hosts_file),
                                "--json"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
                               check=False)
            report = json.loads(r.stdout) if r.stdout.strip().startswith("{") else {}
            assert r.returncode == 0 and report.get("outcome") == "success", (r.stdout[-2000:], r.stderr[-2000:])
        finally:
            subprocess.run([*DRD, "stop", "--all", "--cluster", c.name, "--run-dir", str(c.run_dir)], cwd=tmp_path,
                           env=env, capture_output=True, timeout=60, check=False)
