"""Channel mappings and the log readers: ROS 2 bags (written with mcap-ros2-support's writer, at
mixed topic rates) and LeRobot datasets (v2.1 and v3.0 layouts) built from simulated Panda
episodes come back as the episodes' observations; bad input gets one clear error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer

from experiments.robot_logs.write import (MSGDEFS, bag_mapping, lerobot_mapping, write_bag, write_bag_folders,
                                          write_lerobot, write_mapping)
from logs.errors import LogError
from logs.mapping import check_checkpoint, load_mapping, parse_mapping
from logs.sources import read_mapped
from sim.channels import CHANNEL_NAMES
from sim.runner import run_episode
from sim.skills import SKILLS

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "panda_ros2.toml"


@pytest.fixture(scope="module")
def episodes():
    return [run_episode(SKILLS[i % 2], 300 + i) for i in range(4)]


@pytest.fixture(scope="module")
def native(episodes):
    return np.stack([e.observations for e in episodes])


@pytest.fixture(scope="module")
def bag(episodes, tmp_path_factory):
    return write_bag(episodes, tmp_path_factory.mktemp("bag") / "set.mcap", chunk_size=4096)


def _mapping(**changes):
    doc = bag_mapping("marker")
    for key, value in changes.items():
        doc[key] = value
    return parse_mapping(doc, "test mapping")


# --------------------------------------------------------------------------- mapping files


def test_example_mapping_parses_and_marks_the_joints():
    m = load_mapping(EXAMPLE)
    assert m.kind == "rosbag" and m.split.split == "gap" and m.split.stamp == "header"
    assert [c.name for c in m.channels if c.joint] == [f"joint{i}" for i in range(1, 8)]
    assert {c.units for c in m.channels} == {"rad", "m", "N", "N m"}


def test_yaml_and_toml_mappings_are_the_same_schema(tmp_path):
    path = write_mapping(bag_mapping("gap"), tmp_path / "m.yaml")
    assert load_mapping(path).channel_names == CHANNEL_NAMES
    (tmp_path / "bad.toml").write_text("[timing]\nperiod_s = 0.5\nsteps = 15\n[[channels]]\nname = 'joint1'\n"
                                       "topik = '/joint_states'\nfield = 'position'\nunits = 'rad'\njoint = true\n")
    with pytest.raises(LogError, match=r"channels\[0\] \('joint1'\)\.topik: Extra inputs"):
        load_mapping(tmp_path / "bad.toml")
    (tmp_path / "broken.toml").write_text("[timing\n")
    with pytest.raises(LogError, match="not valid TOML"):
        load_mapping(tmp_path / "broken.toml")


@pytest.mark.parametrize("change, message", [
    ({"name": "wrist_angle", "joint": True}, "joint channels, and only they, must be named joint"),
    ({"feature": "observation.state"}, "either topic .* or feature"),
    ({"index": 0, "key": "panda_joint1"}, "index or key, not both"),
    ({"units": ""}, "units"),
])
def test_a_bad_channel_is_refused_with_its_reason(change, message):
    doc = bag_mapping("marker")
    doc["channels"][0] |= change
    with pytest.raises(LogError, match=message):
        parse_mapping(doc, "m")


def test_split_rules_are_checked():
    doc = bag_mapping("marker")
    del doc["episodes"]["marker_topic"]
    with pytest.raises(LogError, match="needs marker_topic"):
        parse_mapping(doc, "m")
    doc = bag_mapping("gap")
    doc["episodes"]["gap_s"] = 0.1
    with pytest.raises(LogError, match="must exceed timing.max_gap_s"):
        parse_mapping(doc, "m")


def test_a_mapping_that_does_not_match_the_checkpoint_is_refused():
    m = _mapping()
    trained = {"mapping": m.to_dict()}
    check_checkpoint(m, CHANNEL_NAMES, trained)
    with pytest.raises(LogError, match=r"missing \['extra_channel'\]"):
        check_checkpoint(m, (*CHANNEL_NAMES, "extra_channel"), trained)
    deg = bag_mapping("marker")
    deg["channels"][0]["units"] = "deg"
    with pytest.raises(LogError, match="joint1 is in 'deg' in the mapping but the model was trained on 'rad'"):
        check_checkpoint(parse_mapping(deg, "m"), CHANNEL_NAMES, trained)
    slow = bag_mapping("marker")
    slow["timing"]["period_s"] = 1.0
    with pytest.raises(LogError, match="trained on 15 steps of 0.5 s"):
        check_checkpoint(parse_mapping(slow, "m"), CHANNEL_NAMES, trained)


# --------------------------------------------------------------------------- ROS 2 bags


@pytest.mark.parametrize("split", ["marker", "gap"])
def test_one_bag_at_mixed_rates_gives_the_episodes_back(bag, native, episodes, split):
    seqs = read_mapped(bag, parse_mapping(bag_mapping(split), "m"))
    assert seqs.data.shape == native.shape and seqs.channel_names == CHANNEL_NAMES
    assert seqs.labels.tolist() == [e.skill for e in episodes]  # from the /episode marker's text
    np.testing.assert_allclose(seqs.data, native, atol=1e-9)
    assert seqs.provenance["format"] == "rosbag" and seqs.provenance["warnings"] == []
    assert seqs.provenance["mapping"]["episodes"]["split"] == split


def test_a_folder_of_rosbag2_bags_is_one_episode_per_bag(episodes, native, tmp_path):
    folder = write_bag_folders(episodes, tmp_path / "bags", jitter_s=0.002)
    seqs = read_mapped(folder, parse_mapping(bag_mapping("file"), "m"))
    assert len(seqs.data) == 4 and seqs.provenance["episodes"][0] == "bag episode_0000, episode 0"
    joints = slice(0, 7)
    assert np.abs(seqs.data[..., joints] - native[..., joints]).max() < 0.01  # 2 ms of jitter on moving joints
    assert np.abs(seqs.data[..., joints] - native[..., joints]).max() > 0  # ... which the resampling sees


def test_unknown_topic_names_the_bags_topics(bag):
    doc = bag_mapping("marker")
    doc["channels"][0]["topic"] = "/joint_state"
    with pytest.raises(LogError, match=r"no topic /joint_state; its topics: .*/joint_states \(sensor_msgs/msg/JointState\)"):
        read_mapped(bag, parse_mapping(doc, "m"))


@pytest.mark.parametrize("change, message", [
    ({"field": "positon"}, r"no field 'positon' \('positon' is not among \['header', 'name', 'position'"),
    ({"field": "header.frame_id", "key": None}, "is text"),
    ({"key": "panda_joint9"}, "no element named 'panda_joint9'"),
    ({"key": None}, "is an array of 9; give index or key"),
])
def test_a_field_of_the_wrong_kind_is_refused(bag, change, message):
    doc = bag_mapping("marker")
    doc["channels"][0] = {k: v for k, v in (doc["channels"][0] | change).items() if v is not None}
    with pytest.raises(LogError, match=message):
        read_mapped(bag, parse_mapping(doc, "m"))


def test_an_episode_too_short_is_refused(bag):
    doc = bag_mapping("marker")
    doc["timing"]["steps"] = 20
    with pytest.raises(LogError, match=r"episode 0 .* is too short: .* 20 steps of 0.5 s need 9.5 s"):
        read_mapped(bag, parse_mapping(doc, "m"))


def _joint_bag(path: Path, stamps_s: list[float]) -> Path:
    """A bag of /joint_states whose header stamps are ``stamps_s``, logged in order."""
    with open(path, "wb") as f:
        writer = Writer(f)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", MSGDEFS["sensor_msgs/msg/JointState"])
        for i, t in enumerate(stamps_s):
            ns = int(t * 1e9)
            writer.write_message("/joint_states", schema, {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": ["panda_joint1"], "position": [0.1 * i], "velocity": [], "effort": []}, log_time=i * 10**8)
        writer.finish()
    return path


ONE_JOINT = {"timing": {"period_s": 0.5, "steps": 3, "max_gap_s": 0.3}, "episodes": {"stamp": "header"},
             "channels": [{"name": "joint1", "topic": "/joint_states", "field": "position", "index": 0,
                           "units": "rad", "joint": True}]}


def test_gaps_and_stamps_that_go_back_are_refused(tmp_path):
    mapping = parse_mapping(ONE_JOINT, "m")
    ok = read_mapped(_joint_bag(tmp_path / "ok.mcap", [0.0, 0.25, 0.5, 0.75, 1.0]), mapping)
    np.testing.assert_allclose(ok.data[0, :, 0], [0.0, 0.2, 0.4])
    with pytest.raises(LogError, match=r"no sample between 0.250 s and 1.000 s \(a gap of 0.750 s"):
        read_mapped(_joint_bag(tmp_path / "gap.mcap", [0.0, 0.25, 1.0, 1.25]), mapping)
    with pytest.raises(LogError, match="time stamps do not increase: sample 2 at 0.100000 s follows sample 1 at 0.250000 s"):
        read_mapped(_joint_bag(tmp_path / "back.mcap", [0.0, 0.25, 0.1, 0.5, 0.75, 1.0]), mapping)


def test_a_truncated_bag_gives_what_it_can_and_says_so(bag, native, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = bag.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    seqs = read_mapped(cut, _mapping())
    warnings = seqs.provenance["warnings"]
    assert 1 <= len(seqs.data) < 4
    assert any("truncated or damaged" in w for w in warnings)
    np.testing.assert_allclose(seqs.data, native[: len(seqs.data)], atol=1e-9)  # what was kept is intact
    if len(warnings) == 2:
        assert "dropped the last episode" in warnings[1]


def test_rosbag2_storage_other_than_mcap_is_refused(tmp_path):
    (tmp_path / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n"
                                            "  relative_file_paths: [x_0.db3]\n")
    with pytest.raises(LogError, match="uses 'sqlite3' storage; only MCAP bags"):
        read_mapped(tmp_path, _mapping())


# --------------------------------------------------------------------------- LeRobot datasets


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_a_lerobot_dataset_gives_the_episodes_back(episodes, native, tmp_path, version):
    root = write_lerobot(episodes, tmp_path / "ds", version)
    seqs = read_mapped(root, parse_mapping(lerobot_mapping(), "m"))
    assert seqs.labels.tolist() == [e.skill for e in episodes]  # from the tasks file
    assert seqs.provenance["format"] == "lerobot"
    np.testing.assert_allclose(seqs.data, native, rtol=1e-6, atol=1e-6)  # stored as float32


def test_unknown_features_and_names_are_refused(episodes, tmp_path):
    root = write_lerobot(episodes[:2], tmp_path / "ds")
    doc = lerobot_mapping()
    doc["channels"][0]["feature"] = "observation.joints"
    with pytest.raises(LogError, match=r"no feature 'observation.joints'; the dataset has \[.*'observation.state'"):
        read_mapped(root, parse_mapping(doc, "m"))
    doc = lerobot_mapping()
    doc["channels"][0]["key"] = "shoulder"
    with pytest.raises(LogError, match="no element named 'shoulder'; its names: \\['panda_joint1'"):
        read_mapped(root, parse_mapping(doc, "m"))
    with pytest.raises(LogError, match="mapping's channels read topics"):
        read_mapped(root, _mapping())
