"""A daemon's log file is bounded and survives an external logrotate (soak audit, defect 4: a plain file handler
grew forever, and after a logrotate without `copytruncate` it wrote to the moved file)."""

from __future__ import annotations

import logging
from pathlib import Path

from drd.daemon.logs import BACKUPS, MAX_BYTES, RotatingLog


def record(text: str) -> logging.LogRecord:
    return logging.LogRecord("drd.daemon", logging.INFO, __file__, 1, text, None, None)


def test_a_log_past_its_size_rolls_over_and_keeps_a_bounded_number_of_old_files(tmp_path: Path) -> None:
    path = tmp_path / "ranger1.log"
    handler = RotatingLog(path, max_bytes=1000, backups=2)
    try:
        for i in range(200):  # 200 lines of 30 bytes: 6 KB written through a 1 KB log
            handler.handle(record(f"line {i:04d} " + "x" * 19))
    finally:
        handler.close()
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["ranger1.log", "ranger1.log.1", "ranger1.log.2"]
    assert all((tmp_path / name).stat().st_size <= 1000 for name in files)
    assert path.read_text().splitlines()[-1].startswith("line 0199")  # the newest lines are in the log itself
    assert (tmp_path / "ranger1.log.1").read_text().splitlines()[-1] < path.read_text().splitlines()[0]


def test_a_log_moved_away_by_logrotate_is_reopened(tmp_path: Path) -> None:
    path = tmp_path / "ranger1.log"
    handler = RotatingLog(path)
    try:
        handler.handle(record("before"))
        path.rename(tmp_path / "ranger1.log-20260101")  # what logrotate does without copytruncate
        handler.handle(record("after"))
        assert path.read_text() == "after\n"
        path.unlink()  # and a log removed by hand
        handler.handle(record("again"))
    finally:
        handler.close()
    assert (tmp_path / "ranger1.log-20260101").read_text() == "before\n"
    assert path.read_text() == "again\n"


def test_the_default_bound_is_a_few_tens_of_megabytes() -> None:
    assert 1 << 20 <= MAX_BYTES and MAX_BYTES * (BACKUPS + 1) <= 100 << 20


def test_a_peers_text_cannot_start_a_line_of_the_log() -> None:
    """Wire audit 25, D5: a `stop` of the mission `M\\n2026-01-01 ... FORGED` wrote a whole forged line into the
    controller's log (`_reject` logs the reason, which names the mission); a traceback stays on its own lines."""
    import io
    import logging

    from drd.daemon.logs import OneLine

    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(OneLine("%(levelname)s %(name)s: %(message)s"))
    log = logging.getLogger("test.one_line")
    log.addHandler(handler)
    log.propagate = False
    try:
        log.warning("rejected a message on %s: %s", "drd/c/executive", "no mission M\n2026 WARNING FORGED\r\x1b[2J")
        try:
            raise ValueError("ours")
        except ValueError:
            log.exception("failed")
    finally:
        log.removeHandler(handler)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "WARNING test.one_line: rejected a message on drd/c/executive: no mission M\\n2026 WARNING " \
                       "FORGED\\r\\x1b[2J", lines
    assert lines[1] == "ERROR test.one_line: failed" and lines[2] == "Traceback (most recent call last):", lines
