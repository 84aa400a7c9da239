"""Channel mappings and the log readers: ROS 2 bags in MCAP and sqlite3 storage and ROS 1 bags
(written with rosbags, at mixed topic rates) and LeRobot datasets (v2.1 and v3.0 layouts) built from simulated Panda
episodes come back as the episodes' observations; bad input gets one clear error."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import StoragePlugin

from neural_asm.experiments.robot_logs.write import (START_NS, BagWriter, _write, bag_file, bag_mapping, lerobot_mapping, write_bag, write_bag_folders,
                                          write_lerobot, write_mapping)
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import check_checkpoint, load_mapping, parse_mapping
from neural_asm.logs.sources import episode_position, read_mapped
from neural_asm.sim.channels import CHANNEL_NAMES
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "panda_ros2.toml"


@pytest.fixture(scope="module")
def episodes():
    return [run_episode(SKILLS[i % 2], 300 + i) for i in range(4)]


@pytest.fixture(scope="module")
def native(episodes):
    return np.stack([e.observations for e in episodes])


@pytest.fixture(scope="module")
def bag(episodes, tmp_path_factory):
    return write_bag(episodes, tmp_path_factory.mktemp("bag") / "set")


def _mapping(**changes):
    doc = bag_mapping("marker")
    for key, value in changes.items():
        doc[key] = value
    return parse_mapping(doc, "test mapping")


# --------------------------------------------------------------------------- mapping files


def test_example_mapping_parses_and_marks_the_joints():
    m = load_mapping(EXAMPLE)
    assert m.kind == "rosbag" and m.source.split == "gap" and m.source.stamp == "header"
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
    assert seqs.provenance["mapping"]["source"]["split"] == split


def test_a_folder_of_rosbag2_bags_is_one_episode_per_bag(episodes, native, tmp_path):
    folder = write_bag_folders(episodes, tmp_path / "bags", jitter_s=0.002)
    seqs = read_mapped(folder, parse_mapping(bag_mapping("file"), "m"))
    assert len(seqs.data) == 4 and seqs.episodes[0].origin == "bag episode_0000, episode 0"
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
    with pytest.raises(LogError, match=r"episode 0 is too short: .* 20 steps of 0.5 s need 9.5 s"):
        read_mapped(bag, parse_mapping(doc, "m"))


def _joint_bag(path: Path, stamps_s: list[float]) -> Path:
    """A bag of /joint_states whose header stamps are ``stamps_s``, logged in order."""
    with BagWriter(path) as w:
        for i, t in enumerate(stamps_s):
            msg = w.message("sensor_msgs/msg/JointState", header=w.header(int(t * 1e9)), name=["panda_joint1"],
                            position=np.array([0.1 * i]), velocity=np.zeros(0), effort=np.zeros(0))
            w.write("/joint_states", "sensor_msgs/msg/JointState", i * 10**8, msg)
    return path


ONE_JOINT = {"timing": {"period_s": 0.5, "steps": 3, "max_gap_s": 0.3}, "episodes": {"stamp": "header"},
             "channels": [{"name": "joint1", "topic": "/joint_states", "field": "position", "index": 0,
                           "units": "rad", "joint": True}]}


def test_gaps_and_stamps_that_go_back_are_refused(tmp_path):
    mapping = parse_mapping(ONE_JOINT, "m")
    ok = read_mapped(_joint_bag(tmp_path / "ok", [0.0, 0.25, 0.5, 0.75, 1.0]), mapping)
    np.testing.assert_allclose(ok.data[0, :, 0], [0.0, 0.2, 0.4])
    with pytest.raises(LogError, match=r"no sample between 0.250 s and 1.000 s \(a gap of 0.750 s"):
        read_mapped(_joint_bag(tmp_path / "gap", [0.0, 0.25, 1.0, 1.25]), mapping)
    with pytest.raises(LogError, match="time stamps do not increase: sample 2 at 0.100000 s follows sample 1 at 0.250000 s"):
        read_mapped(_joint_bag(tmp_path / "back", [0.0, 0.25, 0.1, 0.5, 0.75, 1.0]), mapping)


def _small_chunks(bag: Path, path: Path) -> Path:
    """The bag's MCAP rewritten with 4 kB chunks (as a recorder flushing often leaves it), by the mcap library."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(bag_file(bag), "rb") as src, open(path, "wb") as dst:
        reader, writer = make_reader(src), Writer(dst, chunk_size=4096)
        writer.start(profile="ros2")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schemas[schema.id])
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        writer.finish()
    return path


def test_a_truncated_bag_gives_what_it_can_and_says_so(bag, native, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = _small_chunks(bag, tmp_path / "small.mcap").read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    seqs = read_mapped(cut, _mapping())
    warnings = seqs.provenance["warnings"]
    assert 1 <= len(seqs.data) < 4
    assert any("truncated or damaged" in w for w in warnings)
    np.testing.assert_allclose(seqs.data, native[: len(seqs.data)], atol=1e-9)  # what was kept is intact
    if len(warnings) == 2:
        assert "dropped the last episode" in warnings[1]


@pytest.mark.slow
@pytest.mark.parametrize("storage", ["sqlite3", "ros1"])
def test_sqlite3_and_ros1_bags_give_the_episodes_back(episodes, native, tmp_path, storage):
    path = tmp_path / ("set.bag" if storage == "ros1" else "set")
    bag = write_bag(episodes, path, storage=storage)
    for source in (bag, bag_file(bag)):  # the rosbag2 folder and its .db3 alone; the .bag file
        seqs = read_mapped(source, _mapping())
        assert seqs.labels.tolist() == [e.skill for e in episodes] and seqs.provenance["warnings"] == []
        np.testing.assert_allclose(seqs.data, native, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_bag_without_message_definitions_is_decoded_with_the_ros2_types(episodes, native, tmp_path, storage):
    bag = write_bag(episodes[:1], tmp_path / "bare", storage=storage, definitions=storage == "sqlite3")
    if storage == "sqlite3":
        with sqlite3.connect(bag_file(bag)) as db:  # as ROS 2 Humble's bags: no definitions stored
            db.execute("DELETE FROM message_definitions")
    seqs = read_mapped(bag, _mapping())
    np.testing.assert_allclose(seqs.data, native[:1], atol=1e-9)


@pytest.mark.parametrize("suffix", [".mcap", ".db3", ".bag"])
def test_a_corrupt_bag_file_gives_one_line_naming_it(tmp_path, suffix):
    broken = tmp_path / f"broken{suffix}"
    broken.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 64 if suffix == ".mcap" else bytes(range(256)) * 64)
    with pytest.raises(LogError) as err:
        read_mapped(broken, _mapping())
    assert str(broken) in str(err.value) and "holds no episode" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow
def test_a_corrupt_chunk_keeps_the_episodes_before_it(bag, native, tmp_path):
    data = bytearray(_small_chunks(bag, tmp_path / "small.mcap").read_bytes())
    middle = int(len(data) * 0.6)
    data[middle: middle + 2000] = bytes(2000)  # zeros over records in the middle: not a clean cut
    (tmp_path / "corrupt.mcap").write_bytes(bytes(data))
    seqs = read_mapped(tmp_path / "corrupt.mcap", _mapping())
    assert 1 <= len(seqs.data) < 4 and "truncated or damaged" in seqs.provenance["warnings"][0]
    np.testing.assert_allclose(seqs.data, native[: len(seqs.data)], atol=1e-9)


@pytest.mark.slow
def test_a_label_just_before_the_first_sample_names_the_episode(episodes, tmp_path):
    folder = tmp_path / "bags"
    for i, ep in enumerate(episodes[:2]):
        with BagWriter(folder / f"run{i}") as w:
            label_ns = START_NS - 10_000_000  # 10 ms before the first sample
            w.write("/task", "std_msgs/msg/String", label_ns, w.message("std_msgs/msg/String", data=ep.skill))
            _write(w, [(START_NS, ep)], np.random.default_rng(0), 0.0, label=None)
    doc = bag_mapping("file")
    doc["episodes"]["label_topic"] = "/task"
    seqs = read_mapped(folder, parse_mapping(doc, "m"))
    assert seqs.labels.tolist() == [e.skill for e in episodes[:2]] and seqs.provenance["warnings"] == []
    doc["episodes"]["label_tolerance_s"] = 0.005
    seqs = read_mapped(folder, parse_mapping(doc, "m"))
    assert seqs.labels.tolist() == ["run0", "run1"]
    assert seqs.provenance["warnings"][0] == ("bag run0, episode 0: no message on /task in it or up to 0.005 s "
                                              "before it; named 'run0'")


@pytest.mark.slow
def test_a_bag_without_the_label_topic_is_read_with_a_warning(episodes, tmp_path):
    folder = write_bag_folders(episodes[:2], tmp_path / "bags", label=None)
    seqs = read_mapped(folder, parse_mapping(bag_mapping("file"), "m"))
    assert seqs.labels.tolist() == ["episode_0000", "episode_0001"] and len(seqs.provenance["warnings"]) == 2


@pytest.mark.slow
def test_a_dropout_is_an_error_or_skipped_by_number(episodes, native, tmp_path):
    folder = tmp_path / "bags"
    for i, ep in enumerate(episodes[:3]):
        with BagWriter(folder / f"episode_{i:04d}") as w:
            _write(w, [(START_NS, ep)], np.random.default_rng(0), 0.0)
    _dropout(folder / "episode_0001", tmp_path / "dropout", 3.0, 3.6)
    shutil.rmtree(folder / "episode_0001")
    (tmp_path / "dropout").rename(folder / "episode_0001")
    mapping = parse_mapping(bag_mapping("file"), "m")
    with pytest.raises(LogError, match=r"bag episode_0001, episode 1, topic /.*: no sample between .*--skip-bad"):
        read_mapped(folder, mapping)
    seqs = read_mapped(folder, mapping, skip_bad=True)
    assert [e.number for e in seqs.episodes] == [0, 2]
    assert seqs.provenance["warnings"][0].startswith("skipped episode 1: bag episode_0001, episode 1")
    np.testing.assert_allclose(seqs.data, native[[0, 2]], atol=1e-9)
    assert episode_position(seqs, 2) == 1
    with pytest.raises(LogError, match="episode 1 is not among the episodes read .*: skipped episode 1"):
        episode_position(seqs, 1)


def _dropout(src: Path, dst: Path, from_s: float, to_s: float) -> None:
    """A copy of a bag without its messages logged between ``from_s`` and ``to_s`` after START_NS."""
    from rosbags.rosbag2 import Reader, Writer

    with Reader(src) as reader, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        out = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest)
               for c in reader.connections}
        for c, t, raw in reader.messages():
            if not START_NS + from_s * 1e9 <= t < START_NS + to_s * 1e9:
                writer.write(out[c.id], t, raw)


@pytest.mark.slow
def test_metadata_that_declares_more_messages_is_an_error(episodes, tmp_path):
    folder = write_bag_folders(episodes[:1], tmp_path / "bags")
    meta = folder / "episode_0000" / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    for topic in doc["rosbag2_bagfile_information"]["topics_with_message_count"]:
        topic["message_count"] += 5
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(LogError, match=r"bag episode_0000 is missing messages: metadata.yaml declares \d+ messages on"):
        read_mapped(folder, parse_mapping(bag_mapping("file"), "m"))
    assert "missing messages" in read_mapped(folder, parse_mapping(bag_mapping("file"), "m"), skip_bad=True).provenance["warnings"][0]


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
    with pytest.raises(LogError, match="is a LeRobot dataset, but the mapping reads a ROS bag source"):
        read_mapped(root, _mapping())


@pytest.mark.slow
@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_a_lerobot_dataset_missing_an_episode_is_an_error_or_skipped_by_number(episodes, native, tmp_path, version):
    root = write_lerobot(episodes, tmp_path / "ds", version)
    if version == "v2.1":
        (root / "data/chunk-000/episode_000002.parquet").unlink()
        message = r"episodes \[2\] \(meta/episodes.jsonl\) have no rows .*missing files: \['data/chunk-000/episode_000002"
    else:  # the data file lost episode 2's rows
        import pyarrow.compute as pc
        import pyarrow.parquet as pq
        path = root / "data/chunk-000/file-000.parquet"
        table = pq.read_table(path)
        pq.write_table(table.filter(pc.not_equal(table.column("episode_index"), 2)), path)
        message = r"episodes \[2\] \(meta/episodes/\) have no rows in the data files"
    mapping = parse_mapping(lerobot_mapping(), "m")
    with pytest.raises(LogError, match=message):
        read_mapped(root, mapping)
    seqs = read_mapped(root, mapping, skip_bad=True)
    assert [e.number for e in seqs.episodes] == [0, 1, 3]
    assert "episode 2" in seqs.provenance["warnings"][0]
    np.testing.assert_allclose(seqs.data, native[[0, 1, 3]], rtol=1e-6, atol=1e-6)


@pytest.mark.slow
def test_the_lerobot_example_mapping_reads_a_panda_dataset(episodes, native, tmp_path):
    root = write_lerobot(episodes[:2], tmp_path / "ds", "v2.1")
    seqs = read_mapped(root, load_mapping(EXAMPLE.with_name("panda_lerobot.toml")))
    picks = [CHANNEL_NAMES.index(n) for n in (*CHANNEL_NAMES[:7], "finger_left", "finger_right")]
    assert seqs.channel_names == tuple(CHANNEL_NAMES[i] for i in picks)
    np.testing.assert_allclose(seqs.data, native[:2][..., picks], rtol=1e-6, atol=1e-6)
