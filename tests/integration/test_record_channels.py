"""What a recording holds besides the records (issue #13): the sensors as the drivers read them, launches and
landings, the behavior tree's active configuration at each change, and where everyone ended; read back with the
independent `mcap` reader (and Foxglove's protobuf decoder for its schemas), never with `drd.record`'s writer."""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import orjson
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from drd.dryrun import DryRun, run
from drd.hosts import load_hosts
from drd.record import Recorder, read, state_at
from drd.runtime import records as rec
from drd.sim.physics import Simulation
from drd.sim.world import load_world
from dsl import compile_file
from dsl.catalog import Catalog
from tests.conftest import ROOT, shared_examples
from tests.runtime_support import Timed


class Run:
    """One dry-run with a recording, and what its simulation's sensors gave the drivers (seen from the class, under
    the recorder's tap): `reads[kind]` lists (robot, sim time, args, result)."""

    def __init__(self, path: Path, report: DryRun, sim: Simulation, reads: dict[str, list[tuple[Any, ...]]]) -> None:
        self.path, self.report, self.sim, self.reads = path, report, sim, reads

    def messages(self) -> list[tuple[str, str, int, Any]]:
        """(topic, schema name, log time, decoded message) of every message, in file order."""
        factory, decoders, out = DecoderFactory(), {}, []
        with self.path.open("rb") as fh:
            for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
                assert schema is not None, channel.topic
                if channel.message_encoding == "json":
                    decoded = orjson.loads(message.data)
                else:
                    decoder = decoders.setdefault(schema.id, factory.decoder_for(channel.message_encoding, schema))
                    decoded = decoder(message.data)
                out.append((channel.topic, schema.name, message.log_time, decoded))
        return out


def recorded_run(tmp: Path, chart_file: Path, catalog: Catalog, monkeypatch: pytest.MonkeyPatch,
                 **options: Any) -> Run:
    reads: dict[str, list[tuple[Any, ...]]] = defaultdict(list)
    for name in ("ranges", "camera", "brightness"):
        original = getattr(Simulation, name)

        def spy(self: Simulation, robot: str, *args: Any, _original: Any = original, _name: str = name) -> Any:
            result = _original(self, robot, *args)
            reads[_name].append((robot, self.time, args, result))
            return result

        monkeypatch.setattr(Simulation, name, spy)
    chart = compile_file(chart_file, catalog).statechart
    assert chart is not None
    sims: list[Simulation] = []
    path = tmp / "run.mcap"
    report = run(chart, load_hosts(ROOT / "hosts.yaml", catalog), load_world(ROOT / "worlds" / "corridor.yaml"),
                 catalog, recorder=Recorder(path), progress=lambda sim, _ex: sims.append(sim), **options)
    return Run(path, report, sims[0], reads)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory: pytest.TempPathFactory, catalog: Catalog) -> Run:
    with pytest.MonkeyPatch.context() as monkeypatch:
        return recorded_run(tmp_path_factory.mktemp("corridor"), ROOT / "missions" / "corridor_surveillance.mission",
                            catalog, monkeypatch)


def test_the_channels_and_their_schemas(corridor: Run) -> None:
    assert corridor.report.outcome == "success"
    with corridor.path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.statistics is not None
    schema = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert schema == {
        "/drd/records": "drd.Record", "/drd/runs": "drd.Run", "/drd/active": "drd.Active",
        "/drd/camera": "drd.CameraFrame", "/drd/light": "drd.Brightness", "/drd/flights": "drd.Flight",
        "/drd/tf": "foxglove.FrameTransforms", "/drd/world": "foxglove.SceneUpdate",
        "/drd/trails": "foxglove.SceneUpdate", "/drd/seen": "foxglove.SceneUpdate", "/drd/log": "foxglove.Log",
        "/drd/scan/ranger1": "foxglove.LaserScan"}  # the only laser of hosts.yaml
    counts = Counter(topic for topic, *_ in corridor.messages())
    assert {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items() if n} == counts
    assert counts["/drd/records"] == len(corridor.report.records)
    assert counts["/drd/log"] == len(corridor.report.logs())
    assert counts["/drd/runs"] == 1  # and no cluster's channels (`/drd/hosts`...) in a dry-run


def test_message_times_are_sim_time_and_never_go_back_on_a_channel(corridor: Run) -> None:
    last: dict[str, int] = {}
    for topic, _schema, log_time, _msg in corridor.messages():
        assert log_time >= last.get(topic, 0), topic
        last[topic] = log_time
    assert max(last.values()) == round(corridor.report.sim_time * 1e9)


def test_scans_are_what_the_laser_gave_its_driver_once_per_cycle(corridor: Run) -> None:
    read: dict[tuple[str, int], tuple[Any, ...]] = {}
    for robot, at, args, result in corridor.reads["ranges"]:
        read.setdefault((robot, round(at * 1e9)), (args, result))
    scans = [(t, m) for topic, _s, t, m in corridor.messages() if topic == "/drd/scan/ranger1"]
    assert len(scans) == len(read)  # the laser was read in that many control cycles, once each
    for t, scan in scans:
        (beams, max_range, fov), ranges = read[("ranger1", t)]
        assert scan.frame_id == "ranger1" and scan.timestamp.ToNanoseconds() == t
        assert len(scan.ranges) == beams and scan.start_angle == pytest.approx(-fov / 2)
        assert scan.end_angle == pytest.approx(fov / 2)
        assert [max_range if math.isinf(d) else d for d in scan.ranges] == ranges  # nothing hit: +inf


def test_camera_frames_light_and_sightings_are_what_the_cameras_gave(corridor: Run) -> None:
    messages = corridor.messages()
    frames = [m for topic, _s, _t, m in messages if topic == "/drd/camera"]
    with_people = {(m["robot"], m["at"]): m["detections"] for m in frames if m["detections"]}
    seen = {(robot, at): [{"label": d.label, "bearing": d.bearing, "distance": d.distance, "light": d.light}
                          for d in result] for robot, at, _args, result in corridor.reads["camera"] if result}
    assert with_people == seen and len(seen) > 20  # every frame with someone in it, exactly
    sightings = [m for topic, _s, _t, m in messages if topic == "/drd/seen"]
    assert len(sightings) == len(seen)
    assert {e.frame_id for m in sightings for e in m.entities} <= {f"scout{i}" for i in range(1, 7)}
    light = [(m["robot"], m["at"], m["regions"]) for topic, _s, _t, m in messages if topic == "/drd/light"]
    assert light == [(robot, at, result) for robot, at, _args, result in corridor.reads["brightness"]]
    fovs = [e for topic, _s, _t, m in messages if topic == "/drd/world" for e in m.entities if e.id.startswith("fov/")]
    assert sorted(e.frame_id for e in fovs) == sorted({robot for robot, *_ in corridor.reads["camera"]})
    stamps = [(t, e.timestamp.seconds * 10**9 + e.timestamp.nanos) for topic, _s, t, m in messages
              if topic == "/drd/world" and t > 0 for e in m.entities]  # the scene's changes after the start
    assert stamps and all(t == stamp for t, stamp in stamps), "each entity stamped with its change's time"


def test_each_launch_and_its_landing(corridor: Run) -> None:
    flights = [m for topic, _s, _t, m in corridor.messages() if topic == "/drd/flights"]
    launches = [f for f in flights if f["kind"] == "launch"]
    assert sorted(f["robot"] for f in launches) == sorted(s["scout"] for s in corridor.report.scouts)
    landings = {(f["robot"], f["at"]): f["to"] for f in flights if f["kind"] == "landing"}
    jumps = [f for f in flights if f["kind"] == "jump"]
    assert len(landings) == len(launches) + len(jumps)
    assert all(landings[(f["robot"], f["lands_at"])] == f["to"] for f in launches + jumps)


def test_the_final_poses_are_the_dry_runs(corridor: Run) -> None:
    last: dict[str, tuple[str, float, float, float]] = {}
    for topic, _s, _t, m in corridor.messages():
        if topic == "/drd/tf":
            for tf in m.transforms:
                last[tf.child_frame_id] = (tf.parent_frame_id, tf.translation.x, tf.translation.y,
                                           2 * math.atan2(tf.rotation.z, tf.rotation.w))
    sim = corridor.sim
    for rid in sim.robots:
        pose = sim.pose(rid)
        parent, x, y, h = last[rid]
        assert parent == "world" and (x, y) == (pose.x, pose.y), rid
        assert math.cos(h - pose.heading) == pytest.approx(1.0), rid
    for iid, (x, y) in sim.intruders().items():
        assert last[f"intruder/{iid}"][1:3] == (x, y)
    scouts = {s["scout"]: (s["x"], s["y"]) for s in corridor.report.scouts}
    assert {k: (round(v[1], 2), round(v[2], 2)) for k, v in last.items() if k in scouts} == scouts


def test_every_frame_the_scene_locks_a_body_to_at_0_has_a_pose_at_0(corridor: Run) -> None:
    """Records audit 18, #3: the scene at 0 locks each intruder's body to `intruder/<id>`, whose first transform came
    at 0.1 s; a viewer then had a body on a frame that did not exist yet."""
    at0: set[str] = set()
    locked: set[str] = set()
    for topic, _s, log_time, m in corridor.messages():
        if topic == "/drd/tf" and log_time == 0:
            at0 |= {tf.child_frame_id for tf in m.transforms}
        elif topic == "/drd/world" and log_time == 0:
            locked |= {e.frame_id for e in m.entities if e.frame_locked}
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    assert {f"intruder/{i.id}" for i in world.intruders} <= locked
    assert locked <= at0, locked - at0
    poses = {iid: read(corridor.path).pose(f"intruder/{iid}", 0.0) for iid in (i.id for i in world.intruders)}
    assert poses == {i.id: (*i.position(0.0), 0.0) for i in world.intruders}


def test_a_scout_in_its_magazine_is_its_rangers_frame(corridor: Run) -> None:
    recording = read(corridor.path)
    launched = {s["scout"]: s["at"] for s in corridor.report.scouts}
    for scout, at in launched.items():
        assert recording.carried[scout][0] == (0.0, "ranger1")  # from the start (readers audit 16, D8)
        assert recording.pose(scout, at - 0.2) == recording.pose("ranger1", at - 0.2)  # carried there
        assert recording.tracks[scout][0][0] >= at - 1e-6  # its own track begins with its flight


def active_messages(r: Run) -> list[dict[str, Any]]:
    return [m for topic, _s, _t, m in r.messages() if topic == "/drd/active"]


#: The records that change the active configuration.
CHANGES = {"entered", "exited", "suspended", "resumed", "waiting", "granted", "released", "finished"}


def assert_active_is_state_at(r: Run) -> None:
    recording = read(r.path)
    messages = active_messages(r)
    changes = sorted({round(x.at, 9) for x in r.report.records if x.kind in CHANGES})
    assert [round(m["at"], 9) for m in messages] == changes  # one message at each instant it changed
    for m in messages:
        [expected] = state_at(recording, m["at"])["missions"]
        assert {k: m[k] for k in ("mission", "id", "outcome", "active", "holds", "waiting")} == expected, m["at"]


def test_the_active_configuration_at_each_change_is_what_replay_at_says(corridor: Run) -> None:
    assert_active_is_state_at(corridor)
    last = active_messages(corridor)[-1]
    assert last["outcome"] == "success" and last["active"] == [] and last["holds"] == {}


def test_the_active_configuration_shows_who_waits_and_who_is_suspended(tmp_path: Path, catalog: Catalog,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Fig. 8: three behaviors want one camera, two share it by slices, the third waits behind them."""
    shared = recorded_run(tmp_path, shared_examples() / "shared_camera.mission", catalog, monkeypatch,
                          registry={"Observe": Timed})
    assert shared.report.outcome == "success"
    assert_active_is_state_at(shared)
    states = Counter(a["state"] for m in active_messages(shared) for a in m["active"])
    assert states["waiting"] and states["suspended"] and states["running"]
    blocked = [w for m in active_messages(shared) for w in m["waiting"] if w["blocked_by"]]
    assert any(b["holds"] == {"cam": "ranger1.camera"} for w in blocked for b in w["blocked_by"])


def test_the_foxglove_layout_shows_channels_a_recording_has(corridor: Run) -> None:
    """docs/foxglove-layout.json: a 3D panel on the world, trails, sightings and scans (frames from `/drd/tf`),
    tables of the active states and holds, the records raw, the log lines."""
    import json

    layout = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    panels = layout["configById"]
    shown = {p["topicPath"].split(".")[0] for p in panels.values() if "topicPath" in p}
    shown |= {p["topicToRender"] for p in panels.values() if "topicToRender" in p}
    three_d = set(panels["3D!drd"]["topics"])
    topics = {topic for topic, *_ in corridor.messages()}
    assert shown <= topics and {"/drd/world", "/drd/trails", "/drd/seen", "/drd/scan/ranger1"} <= three_d
    assert all(t in topics or t.startswith("/drd/scan/") for t in three_d)  # another team's lasers too
    assert shown == {"/drd/active", "/drd/records", "/drd/log"}

    def leaves(node: object) -> set[str]:
        return {node} if isinstance(node, str) else leaves(node["first"]) | leaves(node["second"])  # type: ignore[index]

    assert leaves(layout["layout"]) == set(panels)


def test_a_recording_as_a_ros2_bag(corridor: Run, tmp_path: Path) -> None:
    """`replay --ros2-bag`: what `rosbags-convert` cannot do (it refuses an MCAP file whose profile is not ros2),
    read back with rosbags' own reader."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from drd.record import to_ros2_bag

    counts = to_ros2_bag(corridor.path, tmp_path / "bag")
    recorded = Counter(topic for topic, *_ in corridor.messages())
    assert counts == {"/tf": recorded["/drd/tf"], "/ranger1/scan": recorded["/drd/scan/ranger1"],
                      "/rosout": recorded["/drd/log"],
                      **{t: n for t, n in recorded.items() if t in ("/drd/records", "/drd/active", "/drd/camera",
                                                                     "/drd/light", "/drd/flights", "/drd/runs")}}
    store = get_typestore(Stores.ROS2_HUMBLE)
    scans = [m for topic, _s, _t, m in corridor.messages() if topic == "/drd/scan/ranger1"]
    with Reader(tmp_path / "bag") as bag:
        assert {c.topic: c.msgcount for c in bag.connections} == counts
        read = [store.deserialize_cdr(raw, c.msgtype) for c, _t, raw in bag.messages()
                if c.topic == "/ranger1/scan"]
    assert [list(m.ranges) for m in read] == [[numpy_float32(d) for d in s.ranges] for s in scans]
    assert read[0].header.frame_id == "ranger1" and read[0].angle_min == pytest.approx(scans[0].start_angle)
    # the bag is no drd recording, and `replay` of it says so (readers audit 13, D11: a JSON decoder's message)
    from drd.record import RecordingError
    from drd.record import read as read_recording

    with pytest.raises(RecordingError, match=r"no drd run in it \(a drd recording has JSON messages on"):
        read_recording(next((tmp_path / "bag").glob("*.mcap")))


def test_the_bags_metadata_is_the_layout_humble_parses(corridor: Run, tmp_path: Path) -> None:
    """Clients audit 9, D5: version 9's `offered_qos_profiles` is a YAML list, which Humble's rosbag2 decodes as a
    string (`as<std::string>()` for version >= 4) and refuses; version 8 writes the string every distribution reads."""
    import yaml

    from drd.record import to_ros2_bag

    to_ros2_bag(corridor.path, tmp_path / "bag")
    info = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 8 and info["storage_identifier"] == "mcap"
    topics = [t["topic_metadata"] for t in info["topics_with_message_count"]]
    assert topics and all(isinstance(t["offered_qos_profiles"], str) for t in topics)


def test_a_cut_recording_gives_the_bag_of_its_complete_chunks_and_a_broken_one_no_folder(corridor: Run,
                                                                                          tmp_path: Path) -> None:
    """Clients audit 9, D3: `replay --ros2-bag` of a cut file failed with the MCAP reader's message and left a
    folder with a 43-byte bag and no metadata; `replay` itself reads the same file up to the cut."""
    from rosbags.rosbag2 import Reader

    from drd.record import RecordingError, to_ros2_bag

    data = corridor.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) * 6 // 10])
    counts = to_ros2_bag(cut, tmp_path / "bag")
    full = to_ros2_bag(corridor.path, tmp_path / "whole")
    assert 0 < sum(counts.values()) < sum(full.values())
    with Reader(tmp_path / "bag") as bag:
        assert {c.topic: c.msgcount for c in bag.connections} == counts
    (tmp_path / "head.mcap").write_bytes(data[:30])
    with pytest.raises(RecordingError, match="head.mcap: cannot write it as a ROS 2 bag"):
        to_ros2_bag(tmp_path / "head.mcap", tmp_path / "none")
    assert not (tmp_path / "none").exists()


def numpy_float32(value: float) -> float:
    import numpy as np

    return float(np.float32(value))


def test_a_trail_is_coloured_as_the_robots_body_not_by_its_id(tmp_path: Path) -> None:
    """Users audit 12, D5: a trail was Scout-orange when the robot's id began with "scout", whatever its body."""
    import yaml

    from drd.record import RANGER_COLOUR, SCOUT_COLOUR
    from drd.sim.world import parse_world

    text = (ROOT / "worlds" / "corridor.yaml").read_text().replace("scout", "drone").replace("ranger1", "scout_rover")
    world = parse_world(yaml.safe_load(text), str(tmp_path / "greenhouse.yaml"))
    path = tmp_path / "trails.mcap"
    recorder = Recorder(path)
    try:
        recorder.scene(world)
        for k in range(12):
            recorder.poses(0.1 * k, {"drone1": (0.2 * k, 0.0, 0.0), "scout_rover": (0.0, 0.2 * k, 0.0)})
    finally:
        recorder.close()
    messages = Run(path, None, None, {}).messages()  # type: ignore[arg-type]
    colours = {e.id.split("/")[1]: e.lines[0].color for topic, _s, _t, m in messages if topic == "/drd/trails"
               for e in m.entities}
    for rid, hex_ in (("drone1", SCOUT_COLOUR), ("scout_rover", RANGER_COLOUR)):
        c, want = colours[rid], tuple(int(hex_[i:i + 2], 16) for i in (1, 3, 5))
        assert (round(c.r * 255), round(c.g * 255), round(c.b * 255)) == want, rid


def test_a_frame_with_nobody_follows_one_with_someone_and_a_view_is_drawn_when_its_camera_is_first_read(
        corridor: Run) -> None:
    """Readers audit 13, D8: each camera's first frame was recorded although nobody was seen, and its field of view
    was drawn only then (scout1's at 44.9 s, though its brightness was read from 7 s on)."""
    messages = corridor.messages()
    last: dict[str, bool] = {}
    for topic, _s, _t, m in messages:
        if topic == "/drd/camera":
            assert m["detections"] or last.get(m["robot"]), f"{m['robot']} at {m['at']}: nobody, and nobody before"
            last[m["robot"]] = bool(m["detections"])
    first_read: dict[str, float] = {}
    for robot, at, *_ in sorted(corridor.reads["camera"] + corridor.reads["brightness"], key=lambda r: r[1]):
        first_read.setdefault(robot, at)
    drawn = {e.frame_id: t for topic, _s, t, m in messages if topic == "/drd/world" for e in m.entities
             if e.id.startswith("fov/")}
    assert drawn == {robot: round(at * 1e9) for robot, at in first_read.items()} and len(drawn) >= 3


def test_each_runs_summary_is_logged_when_its_mission_ended(tmp_path: Path) -> None:
    """Readers audit 13, D9: the summary of a mission that ended first was logged at the end of the whole run."""
    path = tmp_path / "runs.mcap"
    recorder = Recorder(path)
    recorder.end([{"mission": "Late", "sim_time": 29.1}, {"mission": "Early", "sim_time": 16.0},
                  {"mission": "NoTime"}], 29.1)
    logged = [(m["mission"], t) for topic, _s, t, m in Run(path, None, None, {}).messages()  # type: ignore[arg-type]
              if topic == "/drd/runs"]
    assert logged == [("Early", 16_000_000_000), ("Late", 29_100_000_000), ("NoTime", 29_100_000_000)]


def test_a_replay_knows_the_view_of_a_camera_that_never_saw_anyone(corridor: Run, tmp_path: Path) -> None:
    """The review of readers audit 13's D8 fix: with no empty first frame recorded, a camera read only for people
    (no brightness) that never saw anyone left no field of view a replay could read (`replay --render` drew no
    wedge for it); the view's entity says it."""
    recording = read(corridor.path)
    read_cameras = {robot for robot, *_ in corridor.reads["camera"] + corridor.reads["brightness"]}
    assert set(recording.fovs) == read_cameras and len(read_cameras) >= 3
    path = tmp_path / "view.mcap"
    recorder = Recorder(path)
    recorder.record("M-1", rec.Entered(0.0, "M", "M"))
    recorder.view("lookout", 1.0, 1.2, 5.0)  # a camera read, nobody seen: no frame, no brightness
    recorder.end([{"mission": "M", "id": "M-1", "records": "M-1", "sim_time": 2.0}], 2.0)
    assert read(path).fovs == {"lookout": 1.2}


def test_a_runs_time_without_a_controller_is_kept_for_its_replay() -> None:
    """Records audit 26, D1: the run's report said `controller_away` 4.45 s and 11.7x real time; its replay had no
    `controller_away` and said 6.3x (a cluster that could not keep up)."""
    from drd.dryrun import rebuilt, summary

    ran = DryRun("M", "success", "", 60.0, 9.6, speed=20.0, on_cluster=True, mission_id="M-1")
    ran.away = 4.45
    again = rebuilt(orjson.loads(orjson.dumps(summary(ran))), [])
    assert again.away == 4.45 and again.to_dict()["controller_away"] == 4.45
    assert again.to_dict()["real_time_factor"] == ran.to_dict()["real_time_factor"]
