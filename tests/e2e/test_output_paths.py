"""Output files that would destroy an input or another output, and a picture cut short (cli audit 24, #1, #2, #8):
each was written over without a word, exit 0 (a `--trace` over the mission file, `replay --trace` over the
recording, `--trace` and `--record` into one file that was neither), a Ctrl-C while the picture was drawn left a
cut one (and cut the good one that was there), and `plan -o plan.jsn` wrote the text tree under a suffix it does
not know."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MISSIONCTL = [sys.executable, "-c", "from drd.cli.missionctl import main; main()"]
HOSTS = ROOT / "hosts.yaml"
MISSION = "mission Stroll {\n    needs r: Ranger\n    Calibrate(samples: 5)\n}\n"


def missionctl(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*MISSIONCTL, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "stroll.mission").write_text(MISSION)
    (tmp_path / "hosts.yaml").write_text(HOSTS.read_text())
    return tmp_path


@pytest.mark.parametrize(("args", "said"), [
    (["--trace", "stroll.mission"], "--trace stroll.mission: it is a mission file"),
    (["--record", "./hosts.yaml"], "--record hosts.yaml: it is the hosts file"),
    (["--trace", "run.out", "--record", "run.out"], "--record run.out: it is the --trace file"),
    (["--render", "../x/../{dir}/stroll.mission"], "it is a mission file"),
    (["--trace", "twin.mission"], "--trace twin.mission: it is a mission file"),
], ids=["trace-over-the-mission", "record-over-the-hosts-file", "trace-and-record-in-one", "a-path-around",
        "a-hard-link"])
def test_a_dry_run_refuses_an_output_over_an_input_or_another_output(work: Path, args: list[str],
                                                                     said: str) -> None:
    (work.parent / "x").mkdir(exist_ok=True)
    (work / "twin.mission").hardlink_to(work / "stroll.mission")
    args = [a.format(dir=work.name) for a in args]
    run = missionctl("dry-run", "stroll.mission", "--config", "hosts.yaml", *args, cwd=work)
    assert run.returncode == 2 and said in run.stderr, run.stderr[-2000:]
    assert run.stdout == ""  # refused before anything ran
    assert (work / "stroll.mission").read_text() == MISSION and (work / "hosts.yaml").read_text() == HOSTS.read_text()
    assert not (work / "run.out").exists()


LIB = "behavior Settle { Calibrate(samples: 5) }\n"


@pytest.mark.parametrize(("args", "said"), [
    (["dry-run", "main.mission", "--config", "hosts.yaml", "--trace", "lib/common.mission"],
     "--trace lib/common.mission: it is a file a mission imports"),
    (["dry-run", "main.mission", "--config", "hosts.yaml", "--world", "mine.yaml", "--render", "mine.yaml"],
     "--render mine.yaml: it is the world file"),
    (["plan", "main.mission", "-o", "lib/common.mission", "--format", "dot"],
     "-o lib/common.mission: it is a file the mission imports"),
    (["run", "main.mission", "--config", "hosts.yaml", "--record", "lib/common.mission"],  # before any connection
     "--record lib/common.mission: it is a file the mission imports"),
], ids=["dry-run-trace-over-an-import", "dry-run-picture-over-the-world", "plan-over-an-import", "run-over-an-import"])
def test_no_output_over_a_file_the_mission_imports_or_the_world(work: Path, args: list[str], said: str) -> None:
    """What a run reads besides the mission and the hosts file is an input too (review of cli audit 24, #7)."""
    (work / "lib").mkdir()
    (work / "lib" / "common.mission").write_text(LIB)
    (work / "main.mission").write_text('import "lib/common.mission"\n'
                                       'mission Main {\n    needs r: Ranger\n    Settle\n}\n')
    world = (ROOT / "worlds" / "corridor.yaml").read_text()
    (work / "mine.yaml").write_text(world)
    run = missionctl(*args, cwd=work)
    assert run.returncode == 2 and said in run.stderr, run.stderr[-2000:]
    assert (work / "lib" / "common.mission").read_text() == LIB and (work / "mine.yaml").read_text() == world
    if args[0] != "plan":
        assert run.stdout == ""  # refused before anything ran


def test_replay_refuses_to_write_its_trace_over_the_recording(work: Path) -> None:
    run = missionctl("dry-run", "stroll.mission", "--config", "hosts.yaml", "--record", "run.mcap", cwd=work)
    assert run.returncode == 0, run.stderr[-2000:]
    before = (work / "run.mcap").read_bytes()
    again = missionctl("replay", "run.mcap", "--trace", "run.mcap", cwd=work)
    assert again.returncode == 2 and "--trace run.mcap: it is the recording" in again.stderr, again.stderr
    assert (work / "run.mcap").read_bytes() == before
    assert missionctl("replay", "run.mcap", cwd=work).returncode == 0


def test_plan_refuses_its_own_mission_as_output_and_a_suffix_it_does_not_know(work: Path) -> None:
    over = missionctl("plan", "stroll.mission", "-o", "stroll.mission", cwd=work)
    assert over.returncode == 2 and "-o stroll.mission: it is the mission file" in over.stderr, over.stderr
    assert (work / "stroll.mission").read_text() == MISSION
    typo = missionctl("plan", "stroll.mission", "-o", "plan.jsn", cwd=work)
    assert typo.returncode == 2 and "-o plan.jsn: its suffix picks the format, and .jsn is not one" in typo.stderr
    assert not (work / "plan.jsn").exists()
    plain = missionctl("plan", "stroll.mission", "-o", "plan", cwd=work)  # no suffix: the text tree, as before
    assert plain.returncode == 0 and "Stroll" in (work / "plan").read_text()


def test_a_picture_cut_short_leaves_the_one_that_was_there_whole(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C arrives while matplotlib writes the file: what it wrote so far never reaches the picture's path."""
    from matplotlib.figure import Figure

    from drd.dryrun import DryRun
    from drd.render import render
    from drd.sim import load_world

    picture = tmp_path / "run.svg"
    picture.write_text("<svg>the last run's</svg>")

    def cut_short(self: Figure, fname: Path, **_: object) -> None:
        Path(fname).write_text("<svg><g>")  # half a picture, then the Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", cut_short)
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    with pytest.raises(KeyboardInterrupt):
        render(world, DryRun("M", None, "success", 1.0, 1.0), picture)
    assert picture.read_text() == "<svg>the last run's</svg>"
    assert [p.name for p in tmp_path.iterdir()] == ["run.svg"]  # nothing half-written left beside it


def test_a_ctrl_c_while_the_picture_is_drawn_keeps_the_report_and_says_the_picture_was_not_drawn(
        work: Path) -> None:
    """The Ctrl-C is raised where the picture is drawn (`drd.render.render`), in the real command."""
    code = ("import sys, drd.render\n"
            "def interrupted(*a, **k):\n    raise KeyboardInterrupt\n"
            "drd.render.render = interrupted\n"
            "from drd.cli.missionctl import main\nsys.argv[0] = 'missionctl'\nmain()\n")
    run = subprocess.run([sys.executable, "-c", code, "dry-run", "stroll.mission", "--config", "hosts.yaml",
                          "--render", "run.png"], cwd=work, capture_output=True, text=True, timeout=300, check=False)
    assert run.returncode == 2, (run.stdout[-1000:], run.stderr[-2000:])
    assert "mission Stroll" in run.stdout and "success" in run.stdout  # the report, as printed
    assert "--render run.png: not drawn: interrupted (Ctrl-C)" in run.stderr and "Traceback" not in run.stderr
    assert not (work / "run.png").exists()


def test_a_picture_drawn_again_keeps_its_mode_and_its_hard_links(tmp_path: Path) -> None:
    """Review of cli audit 24, #1: drawn beside and put in place, a picture got the umask's mode and lost its
    hard links' view of it; it keeps its mode, and a picture with hard links is written in place."""
    import os

    from drd.dryrun import DryRun
    from drd.render import render
    from drd.sim import load_world

    world = load_world(ROOT / "worlds" / "corridor.yaml")
    picture, twin = tmp_path / "run.svg", tmp_path / "twin.svg"
    picture.write_text("old")
    os.chmod(picture, 0o640)
    render(world, DryRun("M", None, "success", 1.0, 1.0), picture)
    assert picture.read_text().startswith("<?xml") and (picture.stat().st_mode & 0o777) == 0o640
    os.link(picture, twin)
    picture.write_text("old")
    render(world, DryRun("M", None, "success", 1.0, 1.0), picture)
    assert twin.read_text() == picture.read_text() and picture.read_text().startswith("<?xml")


def test_plan_takes_any_suffix_when_the_format_is_given(work: Path) -> None:
    """Review of cli audit 24, #8: `-f mermaid -o chart.md` was refused for its suffix, which picks nothing here."""
    r = missionctl("plan", "stroll.mission", "-f", "mermaid", "-o", "chart.md", cwd=work)
    assert r.returncode == 0 and (work / "chart.md").read_text().startswith(("stateDiagram", "---", "%%")), r.stderr
