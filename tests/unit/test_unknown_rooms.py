"""`dsl.rooms`: a room a mission names as text must be one of the world's (users audit 9, D6: a misspelled room in a
geofence was logged once as "cannot be measured" and then guarded nothing)."""

from __future__ import annotations

from dsl import compile_text
from dsl.catalog import Catalog
from dsl.rooms import unknown_rooms

MISSION = """mission Corral {
    needs rig: Ranger
    constraint pen: inside(rig, "n1", "hallway_nope")
    start -> Go
    FollowCorridor(speed: 0.3) as Go
    Go -> done [inside(rig, "s9")]
    Go -> done [inside(rig, name)]
    var name: str = "zz"
}
"""


def test_each_unknown_room_written_as_text_is_located_with_a_hint(catalog: Catalog) -> None:
    result = compile_text(MISSION, catalog, "corral.mission")
    assert result.statechart is not None, [d.message for d in result.diagnostics]
    found = unknown_rooms(result.statechart, {"n1", "s1", "s2"}, "corridor")
    assert [(d.message, d.span.line, d.span.column, d.hint) for d in found] == [
        ("no room named hallway_nope in world corridor", 3, 39, "its rooms: n1, s1, s2"),
        ("no room named s9 in world corridor", 6, 29, "did you mean s1?"),
    ]  # a name held in a variable is only known when the mission runs
    assert unknown_rooms(result.statechart, {"n1", "hallway_nope", "s9"}, "corridor") == []
