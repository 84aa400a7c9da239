"""The recordings' 3D world: Foxglove scene geometry in the MCAP, the Rerun workcell and faulty-joint
marker, the shipped Foxglove layout against the topics a file has, and a user's Rerun layout."""

import json
from pathlib import Path

import numpy as np
import orjson
import pytest
from google.protobuf import descriptor_pb2
from jsonschema import Draft202012Validator
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from neural_asm.client.world import WORKCELL, world_trace
from neural_asm.recordings import EpisodeRecorder
from neural_asm.recordings.episode import View
from neural_asm.recordings import blueprint as bp
from neural_asm.recordings import view
from neural_asm.recordings.paths import APP_ID
from neural_asm.recordings.readers import read_mcap
from neural_asm.recordings.records import StepRecord
from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_CHANNELS
from neural_asm.sim.disturbances import FallingObject
from neural_asm.sim.episode import Episode

LAYOUT = Path(__file__).resolve().parents[2] / "recordings" / "layouts" / "neural_asm.json"
FAULT_STEP = 2


def episode(disturbance: FallingObject | None, rows: int = 12) -> Episode:
    """A short synthetic episode at 40 Hz: the arm at rest in a bent pose, the box falling."""
    q = np.tile([0.0, -0.4, 0.0, -2.0, 0.0, 1.6, 0.8], (rows, 1))
    t = np.arange(rows) / 40.0
    return Episode(observations=np.zeros((2, len(CHANNEL_NAMES))), skill="pick_left_place_right", seed=0, fault=None,
                   disturbance=disturbance, success=True, cube_error_m=0.0, plan=q[:2], t_hi=t, qpos_hi=q,
                   command_hi=q, ee_hi=np.zeros((rows, 3)), cube_hi=np.tile([0.5, 0.0, 0.025], (rows, 1)),
                   box_hi=np.tile([0.3, 0.0, 0.8], (rows, 1)))


def record(tmp_path: Path, ep: Episode, name: str = "client-scene") -> EpisodeRecorder:
    """The episode's world, with a fault flagged on joint4 from step FAULT_STEP (steps every 0.1 s)."""
    names = CHANNEL_NAMES
    with EpisodeRecorder(name, names, folder=tmp_path, view=View(0.1, tuple(range(JOINT_CHANNELS.stop)))) as rec:
        rows = world_trace(ep)
        for k in range(len(rows) // 4):
            for w in rows[4 * k: 4 * k + 4]:
                rec.log_world(w)
            x = np.zeros(len(names))
            rec.log_step(StepRecord(k, x, expected=x, prediction=x, errors=x, energy=1e3 if k >= FAULT_STEP else 1.0,
                                    threshold=10.0, fault=k >= FAULT_STEP, isolated_joint="joint4", time_s=0.1 * k))
    return rec


def entities(messages: list[dict]) -> list[dict]:
    return [e for m in messages for e in m["entities"]]


def test_mcap_scene_draws_the_arm_cube_and_table(tmp_path):
    m = read_mcap(record(tmp_path, episode(None)).paths["mcap"])
    assert len(m["/scene"]) == len(m["/tf"]) == 12
    arm = [e for e in entities(m["/scene"]) if e["id"] == "arm"]
    # 10 link origins, two pairs coincide (Franka's frames 1-2 and 5-6): 8 spheres, 7 links between them
    assert len(arm) == 12 and all(len(e["spheres"]) == 8 and len(e["cylinders"]) == 7 for e in arm)
    assert {e["frame_id"] for e in entities(m["/scene"])} == {"world"}
    [cube] = {json.dumps(e["cubes"][0]["size"]) for e in entities(m["/scene"]) if e["id"] == "cube"}
    assert json.loads(cube) == {k: 2 * WORKCELL.cube_half_size for k in "xyz"}
    [table] = entities(m["/scene/workcell"])  # once, on a topic of its own
    assert table["id"] == "table" and table["cubes"][0]["size"]["y"] == 2 * WORKCELL.table_half_size[1]
    assert "falling_box" not in {e["id"] for e in entities(m["/scene"])}


def test_the_falling_box_is_drawn_from_its_release_only_when_the_episode_has_one(tmp_path):
    rec = record(tmp_path, episode(FallingObject(release_s=0.1)))
    m = read_mcap(rec.paths["mcap"])
    with_box = [i for i, u in enumerate(m["/scene"]) if "falling_box" in {e["id"] for e in u["entities"]}]
    assert with_box == list(range(5, 12))  # rows at 40 Hz after t = 0.1 s
    size = entities(m["/scene"])[-1]["cubes"][0]["size"]
    assert [size[k] for k in "xyz"] == [2 * h for h in WORKCELL.box_half_size]
    paths = {c.entity_path for c in RrdReader(rec.paths["rrd"]).stream()}
    assert bp.BOX in paths and bp.TABLE in paths
    calm = record(tmp_path, episode(None), "client-calm")
    assert bp.BOX not in {c.entity_path for c in RrdReader(calm.paths["rrd"]).stream()}


def test_mcap_is_indexed_and_its_schemas_are_valid(tmp_path):
    path = record(tmp_path, episode(FallingObject(release_s=0.1))).paths["mcap"]
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.chunk_indexes and all(c.message_index_offsets for c in summary.chunk_indexes)
    for schema in summary.schemas.values():
        if schema.encoding == "protobuf":
            files = descriptor_pb2.FileDescriptorSet.FromString(schema.data).file
            package, _, message = schema.name.rpartition(".")
            assert any(f.package == package and message in {t.name for t in f.message_type} for f in files)
        else:
            assert schema.encoding == "jsonschema"
            Draft202012Validator.check_schema(orjson.loads(schema.data))
    encodings = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert encodings["/scene"] == encodings["/scene/workcell"] == "foxglove.SceneUpdate"
    assert encodings["/tf"] == "foxglove.FrameTransforms"


def test_rerun_marks_the_faulty_joint_from_its_detection(tmp_path):
    rec = record(tmp_path, episode(None))
    marks = [c.to_record_batch() for c in RrdReader(rec.paths["rrd"]).stream() if c.entity_path == bp.FAULTY_JOINT]
    times = sorted(t for b in marks for t in b.column("step").to_pylist())
    assert times and times[0] == FAULT_STEP  # from the flagged step on, not before
    positions = np.asarray([p for b in marks for p in b.column("Points3D:positions").to_pylist()]).reshape(-1, 3)
    joint4 = world_trace(episode(None))[0].link_positions[4]
    np.testing.assert_allclose(positions, np.tile(joint4, (len(positions), 1)), atol=1e-6)


def test_the_foxglove_layout_plots_what_the_files_hold(tmp_path):
    layout = json.loads(LAYOUT.read_text())
    m = read_mcap(record(tmp_path, episode(FallingObject(release_s=0.1))).paths["mcap"])
    panels = layout["configById"]
    assert {p.split("!")[0] for p in panels} >= {"3D", "Plot", "StateTransitions"}
    paths = [s["value"] for p in panels.values() for s in p.get("paths", [])]
    paths += [p["topicPath"] for p in panels.values() if "topicPath" in p]
    for path in paths:
        topic, _, field = path.partition(".")
        assert topic in m, path
        assert not field or field in m[topic][-1], path
    assert set(panels["3D!panda"]["topics"]) <= set(m)

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


def test_a_users_blueprint_is_loaded_after_the_recordings(tmp_path, monkeypatch):
    """The viewer makes the blueprint it receives last the active one (checked with the real
    viewer: see recordings/view.py), so the user's file, or a screenshot's, comes last."""
    (tmp_path / "client-1.rrd").write_bytes(b"")
    mine = tmp_path / "mine.rbl"
    bp.training_blueprint().save(APP_ID, mine)
    commands = []

    def run(command, **kwargs):
        commands.append(command)
        if "--screenshot-to" in command:
            layout = Path(command[-1])
            [store] = RrdReader(layout).blueprints()  # a layout for our recordings, written for the call
            assert layout.suffix == ".rbl" and store.application_id == APP_ID
            Path(command[command.index("--screenshot-to") + 1]).write_bytes(b"png")
        return type("Done", (), {"returncode": 0, "stderr": ""})()

    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(view.subprocess, "run", run)
    view.view("client-1", tmp_path, blueprint=mine)
    view.view("client-1", tmp_path, screenshot=tmp_path / "a.png")
    assert commands[0][-2:] == [str(tmp_path / "client-1.rrd"), str(mine)]
    assert commands[1][-2] == str(tmp_path / "client-1.rrd")
    with pytest.raises(view.RunNotFound, match="rbl"):
        view.view("client-1", tmp_path, blueprint=tmp_path / "missing.rbl")
