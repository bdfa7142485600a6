"""rosbag2-compatible MCAP, a whole run's worth of topics written and read back: with our reader,
with ``mcap_ros2`` (which decodes with the schema text we wrote, so it proves the text complete)
and with rosbags (bare ``.mcap`` and directory bag), every field compared; the ros2 profile's
encodings, channel metadata and rosbag2 record, ``bag_info``, and the QoS YAML.
"""

from __future__ import annotations

import io
import os
import warnings

import pytest
import yaml
from bag_helpers import T_NS, _write_run, assert_same
from mcap.reader import make_reader
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rosbags.highlevel import AnyReader

import apc_msgs_py as wire
from apc_recording import bag

with warnings.catch_warnings():  # mcap_ros2.reader warns about itself on import (deprecation)
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages


@pytest.fixture(params=["bytesio", "file"])
def run_bag(request, tmp_path):
    """A bag of a short run, in memory or on disk; yields (source, messages)."""
    if request.param == "bytesio":
        buffer = io.BytesIO()
        messages = _write_run(buffer)
        assert not buffer.closed  # a stream passed in is left open
        return buffer, messages
    path = tmp_path / "run.mcap"
    return path, _write_run(path)


def test_round_trip_with_our_reader_every_field(run_bag):
    source, written = run_bag
    read = list(bag.read_messages(source, log_time_order=False))
    assert len(read) == len(written)
    for sequence, (m, (topic, msg, log_time, publish_time, data)) in enumerate(
        zip(read, written, strict=True)
    ):
        assert m.topic == topic
        assert m.type_name == bag.message_type_name(msg)
        assert m.log_time_ns == log_time
        assert m.publish_time_ns == publish_time
        assert m.sequence == sequence
        assert m.data == data
        assert m.decode() == msg
    # log-time order keeps file order for equal times (the goal at t=0 comes first)
    ordered = list(bag.read_messages(source))
    assert [m.log_time_ns for m in ordered] == sorted(w[2] for w in written)
    assert ordered[0].topic == wire.TRAJECTORY_GOAL


def test_round_trip_with_mcap_ros2_reader_decoding_our_schema(run_bag):
    source, written = run_bag
    if isinstance(source, io.BytesIO):
        source.seek(0)
    read = list(read_ros2_messages(source if isinstance(source, io.BytesIO) else str(source)))
    assert len(read) == len(written)
    for m, (topic, msg, log_time, publish_time, _) in zip(read, written, strict=True):
        assert m.channel.topic == topic
        assert m.schema.name == bag.message_type_name(msg)
        assert (m.log_time_ns, m.publish_time_ns) == (log_time, publish_time)
        assert_same(msg, m.ros_msg)


def test_rosbags_reads_the_bare_mcap_and_the_directory_bag(tmp_path):
    path = tmp_path / "run" / "run_0.mcap"
    path.parent.mkdir()
    written = _write_run(path)
    for target in (path, path.parent):
        if target == path.parent:  # rosbag2's directory layout: metadata.yaml beside the file
            metadata = dict(bag.bag_info(path)["rosbag2_metadata"])
            document = {"rosbag2_bagfile_information": metadata}
            (path.parent / "metadata.yaml").write_text(yaml.safe_dump(document, sort_keys=False))
        with AnyReader([target]) as reader:  # a directory bag also checks the type hashes
            types = {c.topic: c.msgtype for c in reader.connections}
            assert types == {s.name: s.type_name for s in wire.TOPICS}
            counts = {c.topic: c.msgcount for c in reader.connections}
            assert counts[wire.JOINT_STATES] == 5 and counts[wire.TRAJECTORY_GOAL] == 1
            rows = list(reader.messages())
            assert len(rows) == len(written)
            by_time = sorted(written, key=lambda w: w[2])
            for (conn, timestamp, data), (topic, msg, log_time, _, _) in zip(
                rows, by_time, strict=True
            ):
                assert (conn.topic, timestamp) == (topic, log_time)
                assert_same(msg, reader.deserialize(data, conn.msgtype))


def test_ros2_profile_encodings_channel_metadata_and_rosbag2_record(run_bag):
    source, written = run_bag
    stream = source if isinstance(source, io.BytesIO) else open(source, "rb")
    try:
        stream.seek(0)
        reader = make_reader(stream)
        header = reader.get_header()
        assert header.profile == "ros2"
        assert header.library.startswith("apc_recording.bag")
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        assert set(schemas) == {s.type_name for s in wire.TOPICS}  # one schema per type
        for schema in schemas.values():
            assert schema.encoding == "ros2msg"
            assert schema.data.decode() == bag.message_definition(schema.name)
        by_topic = {c.topic: c for c in summary.channels.values()}
        for spec in wire.TOPICS:
            channel = by_topic[spec.name]
            assert channel.message_encoding == "cdr"
            assert set(channel.metadata) == {"offered_qos_profiles", "topic_type_hash"}
            assert channel.metadata["topic_type_hash"] == bag.type_description_hash(spec.type_name)
            (qos,) = bag.qos_profiles_from_yaml(channel.metadata["offered_qos_profiles"])
            assert (qos.reliability, qos.durability, qos.depth, qos.history) == (
                spec.qos.reliability,
                spec.qos.durability,
                spec.qos.depth,
                spec.qos.history,
            )
        assert summary.statistics.chunk_count >= 1
        records = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert len(records) == 1
        meta = yaml.safe_load(records[0].metadata["serialized_metadata"])
    finally:
        if stream is not source:
            stream.close()
    assert meta["version"] == 9
    assert meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == len(written)
    assert meta["starting_time"] == {"nanoseconds_since_epoch": 0}
    assert meta["duration"] == {"nanoseconds": 4 * T_NS}
    assert meta["custom_data"] == {"case": "c"}
    assert meta["ros_distro"] == os.environ.get("ROS_DISTRO", "jazzy")
    assert meta["files"][0]["message_count"] == len(written)
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert topics[wire.JOINT_STATES]["message_count"] == 5
    tm = topics[wire.CLOCK]["topic_metadata"]
    assert tm["type"] == "rosgraph_msgs/msg/Clock"
    assert tm["serialization_format"] == "cdr"
    assert tm["offered_qos_profiles"][0]["reliability"] == "best_effort"
    assert tm["type_description_hash"].startswith("RIHS01_")


def test_bag_info(run_bag):
    source, written = run_bag
    info = bag.bag_info(source)
    assert info["profile"] == "ros2" and info["complete"]
    assert info["message_count"] == len(written)
    assert (info["start_ns"], info["end_ns"], info["duration_ns"]) == (0, 4 * T_NS, 4 * T_NS)
    assert info["topics"][wire.ESTIMATE]["type"] == "std_msgs/msg/Float64MultiArray"
    assert info["topics"][wire.ESTIMATE]["message_count"] == 5
    assert info["topics"][wire.ESTIMATE]["schema_encoding"] == "ros2msg"
    assert info["rosbag2_metadata"]["message_count"] == len(written)


def test_qos_yaml_is_rosbag2_v9_and_round_trips():
    text = bag.qos_profiles_to_yaml([wire.CONTROL_QOS, wire.CLOCK_QOS])
    items = yaml.safe_load(text)
    assert list(items[0]) == [
        "history",
        "depth",
        "reliability",
        "durability",
        "deadline",
        "lifespan",
        "liveliness",
        "liveliness_lease_duration",
        "avoid_ros_namespace_conventions",
    ]
    assert items[0]["history"] == "keep_last" and items[0]["reliability"] == "reliable"
    assert items[1]["reliability"] == "best_effort" and items[1]["depth"] == 1
    assert items[0]["deadline"] == {"sec": 0, "nsec": 0}
    back = bag.qos_profiles_from_yaml(text)
    assert back[0].reliability == ReliabilityPolicy.RELIABLE
    assert back[1].reliability == ReliabilityPolicy.BEST_EFFORT
    assert back[0].durability == DurabilityPolicy.VOLATILE
    assert bag.qos_profiles_to_yaml([]) == "[]" and bag.qos_profiles_from_yaml("[]") == []
    # version-8 integers and the foxy "infinite" durations are understood too
    legacy = "- {history: 1, depth: 5, reliability: 2, durability: 1, deadline: {sec: 2147483647,"
    legacy += " nsec: 4294967295}, liveliness: 1}"
    (old,) = bag.qos_profiles_from_yaml(legacy)
    assert old.reliability == ReliabilityPolicy.BEST_EFFORT
    assert old.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert old.deadline.nanoseconds == 0
