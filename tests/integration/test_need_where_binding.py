"""A behavior's `needs x: T where ...` under an ancestor that holds a robot with a T part (audit item 2).

The robot's part serves the need when the `where` holds of it on entry: the mission runs (it used to ask the manager
for the camera it held itself, a deadlock broken at run time). A `where` the part does not satisfy still asks the
manager: a behavior may want another robot's camera. Real executive, manager, drivers and simulator (the dry-run).
"""

from __future__ import annotations

from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.sim.world import load_world
from dsl import compile_text
from dsl.catalog import Catalog
from dsl.export import need_label
from tests.conftest import ROOT

SELFCAM = """mission SelfCam {{
    needs rover: Ranger
    Peek
}}
behavior Peek {{
    needs lens: Camera{where}
    {step}
}}
"""


def _dry_run(catalog: Catalog, where: str, step: str = "Observe(duration: 2s)") -> DryRun:
    chart = compile_text(SELFCAM.format(where=where, step=step), catalog, "selfcam.mission").raise_for_errors()
    assert chart is not None
    return run(chart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml"),
               catalog, until=60.0)


def test_a_need_without_where_uses_the_ancestors_camera(catalog: Catalog) -> None:
    report = _dry_run(catalog, "")
    assert report.outcome == "success", report.reason
    assert [h["path"] for h in report.holds()] == ["SelfCam"]


def test_a_where_that_holds_of_the_ancestors_camera_reuses_it_without_deadlock(catalog: Catalog) -> None:
    report = _dry_run(catalog, ' where lens.id == "ranger1.camera"')
    assert report.outcome == "success", report.reason
    assert [h["path"] for h in report.holds()] == ["SelfCam"]  # Peek asked the manager for nothing
    assert report.sim_time >= 2.0


def test_a_where_for_another_robots_camera_asks_the_manager(catalog: Catalog) -> None:
    report = _dry_run(catalog, ' where lens.id == "ranger1.scout1.camera"')
    assert report.outcome == "success", report.reason
    held = {h["path"]: h["resources"] for h in report.holds()}
    assert held == {"SelfCam": {"rover": "ranger1"}, "SelfCam/Peek": {"lens": "ranger1.scout1.camera"}}


def test_a_preallocated_step_does_not_reserve_what_the_ancestor_serves(catalog: Catalog) -> None:
    """The audit's first m4_fence draft: a `preallocate` reserved the camera the mission held, a deadlock too."""
    mission = """mission Ahead {
    needs rover: Ranger
    Wait(duration: 1s) as pause
    start -> pause
    pause -> Peek preallocate
}
behavior Peek {
    needs lens: Camera where lens.id == "ranger1.camera"
    Observe(duration: 2s)
}
"""
    chart = compile_text(mission, catalog, "ahead.mission").raise_for_errors()
    assert chart is not None
    report = run(chart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml"),
                 catalog, until=60.0)
    assert report.outcome == "success", report.reason
    assert [h["path"] for h in report.holds()] == ["Ahead"]


def test_the_plan_shows_which_part_may_serve_the_need(catalog: Catalog) -> None:
    chart = compile_text(SELFCAM.format(where=' where lens.id == "ranger1.camera"', step="Observe(duration: 2s)"),
                         catalog).raise_for_errors()
    assert chart is not None
    lens = chart.states["SelfCam/Peek"].needs[0]
    assert lens.requested and lens.reuse == (("SelfCam", "rover", "camera"),)
    assert need_label(lens) == ('lens: Camera where lens.id == "ranger1.camera"'
                                " ← rover.camera if it qualifies, else asked")
