"""Rough edges of the clean-stop path and the CLI's messages (re-verification R4): the controller's log line for
a mission kept for the next start, the progress line on a pipe while the controller is away, what a lost Ctrl-C
leads to, and `--render` naming the path it cannot write. Pure."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from drd.cli.cluster import ProgressGate, unconfirmed_stop
from drd.cli.missionctl import app
from drd.daemon.missions import ending_said


def test_a_mission_kept_by_a_clean_stop_is_logged_as_suspended_not_ended_none() -> None:
    assert ending_said(None, "", kept=True) == "suspended for the next start"
    assert ending_said("failure", "world corridor started again", kept=False) == \
        "ended failure (world corridor started again)"
    assert ending_said(None, "", kept=False) == "ended stopped", "journaled as stopped: said so"


def test_on_a_pipe_an_unchanged_progress_line_is_written_once_then_every_repeat() -> None:
    """While the controller was away, a pipe got the same `sim 28.1 s active …` line once a second (13 of them)."""
    gate = ProgressGate(terminal=False, repeat=30.0)
    same = "sim    28.1 s  active LocateDarkCorner"
    written = [t for t in range(60) if gate.due(same, float(t))]
    assert written == [0, 30], written
    assert gate.due("sim    28.2 s  active LocateDarkCorner", 31.0), "a line that changed is written"
    terminal = ProgressGate(terminal=True)
    assert all(terminal.due(same, float(t)) for t in range(5)), "a terminal gets each one, as before"


def test_a_lost_ctrl_c_says_the_mission_resumes_and_how_to_stop_it_for_good() -> None:
    said = unconfirmed_stop("Corridor-42", "no reply on 'drd/c/executive'", away=True)
    assert said.startswith("mission Corridor-42: could not confirm the stop (no reply on 'drd/c/executive')")
    assert "the stop is lost" in said and "resumes the mission" in said and "nobody attached" in said
    assert "`missionctl stop Corridor-42`" in said
    assert "if the controller is away" in unconfirmed_stop("Corridor-42", "timeout", away=False)


def test_render_to_a_file_of_no_picture_format_names_the_path() -> None:
    """`--render /dev/full` said `cannot draw full`: the stem, not the file."""
    mission = Path(__file__).parents[2] / "missions" / "corridor_surveillance.mission"
    result = CliRunner().invoke(app, ["dry-run", str(mission), "--render", "/dev/full"])
    assert result.exit_code == 2
    assert result.stderr.startswith("error: --render /dev/full: cannot draw it"), result.stderr
    assert ".png" in result.stderr


def test_text_from_the_wire_reaches_the_terminal_inert_and_rich_styles_it_still() -> None:
    """Wire audit 25, D2: an event's name or a peer's reason with escape sequences cleared the operator's screen and
    painted over the report (`ESC[2J`), or set the clipboard (OSC 52); rich's `Text` strips only a few controls."""
    import io

    from drd.cli.common import InertConsole

    screen = io.StringIO()
    console = InertConsole(file=screen, force_terminal=True, color_system="standard", highlight=False,
                           soft_wrap=True)
    console.out("error: ", style="bold red", end="")
    console.out("door\x1b[2J\x1b[H ALL CLEAR \x1b]52;c;cm0=\x1b\\ \x9b1m\x07")
    shown = screen.getvalue()
    assert "\x1b[2J" not in shown and "\x1b]52" not in shown and "\x9b" not in shown and "\x07" not in shown, shown
    assert "door\\x1b[2J\\x1b[H ALL CLEAR \\x1b]52;c;cm0=\\x1b\\ \\x9b1m" in shown, shown  # BEL: rich drops it
    assert "\x1b[1;31merror: " in shown  # its own style is still drawn
