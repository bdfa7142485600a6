"""rosbag2-compatible MCAP: writing, reading back with three readers, and crash recovery.

The writer takes raw CDR bytes, as a ``raw=True`` subscription delivers them (the bytes rosbag2
records); the tests that need no DDS make the same bytes with rosbags' serializer (:func:`_cdr`,
checked against raw subscription bytes). Files are read back with our reader, with ``mcap_ros2``
(which decodes with the schema text we wrote, so it proves the text complete) and with rosbags
(bare ``.mcap`` and directory bag), and every field is compared.
"""

from __future__ import annotations

import array
import io
import os
import random
import select
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mcap.reader import make_reader
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import get_rmw_implementation_identifier
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_recording import bag
from apc_recording.bag import BagError, BagTruncatedWarning, BagWriter
from apc_recording.bag.recovery import main as bag_recover

with warnings.catch_warnings():  # mcap_ros2.reader warns about itself on import (deprecation)
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages

T_NS = 10_000_000  # 10 ms
#: rosbags' ROS 2 Jazzy types: the serializer the tests make exact CDR bytes with.
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def _cdr(msg) -> bytes:
    """The CDR bytes of ``msg`` that a ``raw=True`` subscription receives (same length).

    ``serialize_message`` sizes its buffer by an estimate that can be a few bytes long; rosbags
    reads the message from it and serializes it again at its exact size. Alignment gaps come out
    zeroed here (rclpy leaves them as they are), so only decoded values compare equal.
    """
    type_name = bag.message_type_name(msg)
    estimate = bytes(serialize_message(msg))
    msgdef = JAZZY.get_msgdef(type_name)
    decoded, _ = msgdef.deserialize_cdr_le(estimate[4:], 0, msgdef.cls, JAZZY)
    return bytes(JAZZY.serialize_cdr(decoded, type_name))


def _write(writer: BagWriter, topic: str, msg, log_time_ns: int) -> None:
    """Write ``msg`` on ``topic`` (added with no QoS the first time), as its exact CDR."""
    writer.add_topic(topic, type(msg))
    writer.write(topic, _cdr(msg), log_time_ns)


def _names(n: int) -> list[str]:
    return [f"joint_{i + 1}" for i in range(n)]


def _joint_state(n: int, k: int = 1, effort: bool = True) -> JointState:
    rng = np.random.default_rng(k)
    return wire.arrays_to_joint_state(
        k * T_NS,
        _names(n),
        rng.normal(size=n),
        rng.normal(size=n),
        rng.normal(size=n) if effort else None,
    )


def _goal(n: int) -> JointTrajectory:
    points = [
        JointTrajectoryPoint(
            positions=[0.1 * i] * n, time_from_start=wire.ns_to_duration(i * 10**9)
        )
        for i in (1, 2, 3)
    ]
    return JointTrajectory(joint_names=_names(n), points=points)


def _diagnostics(k: int = 1) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = wire.ns_to_stamp(k * T_NS)
    msg.status = [
        DiagnosticStatus(
            level=DiagnosticStatus.WARN,
            name="plant_node: loop",
            message="late torque",
            hardware_id="sim",
            values=[KeyValue(key="late", value=str(k)), KeyValue(key="missing", value="0")],
        )
    ]
    return msg


def _clock(k: int = 1) -> Clock:
    return Clock(clock=wire.ns_to_stamp(k * T_NS))


def _estimate(n: int, k: int = 1) -> Float64MultiArray:
    rng = np.random.default_rng(k)
    p = 2 * n
    return wire.estimate_to_msg(
        rng.normal(size=(p, p)),
        rng.normal(size=(p, n)),
        rng.normal(size=p),
        3.0,
        0.5,
        stamp_ns=k * T_NS,
    )


def _setpoint(n: int, k: int = 1) -> JointTrajectory:
    v = np.linspace(-1.0, 1.0, n) * k
    return wire.setpoint_to_msg(k * T_NS, _names(n), v, 2 * v, 3 * v, 4 * v, k * T_NS)


#: The messages apc sends, at the sizes that matter (n = 3, 6, 7 joints), plus edge cases of CDR
#: sizing. Value: (message, bytes serialize_message adds beyond the exact CDR).
SAMPLES = {
    **{f"joint_states n={n}": (_joint_state(n), 0) for n in (3, 6, 7)},
    "joint_states n=7 no effort": (_joint_state(7, effort=False), 4),
    **{
        f"torque n={n}": (wire.torque_to_msg(T_NS, _names(n), np.arange(n) + 0.5), 8)
        for n in (3, 6, 7)
    },
    **{f"setpoint n={n}": (_setpoint(n), 0) for n in (3, 6, 7)},
    "goal n=6 positions only": (_goal(6), 44),
    **{f"estimate n={n}": (_estimate(n), 0) for n in (3, 6, 7)},
    "clock": (_clock(), 0),
    "diagnostics": (_diagnostics(), 0),
    "diagnostics empty": (DiagnosticArray(), 0),
    "std_msgs Empty": (Empty(), 3),
    "std_msgs String odd": (String(data="abc"), 0),
}


def _plain(value):
    """Normalise rclpy / mcap_ros2 / rosbags field values for comparison."""
    if isinstance(value, bytes) and len(value) == 1:
        return value[0]  # rclpy's `byte` is bytes, the others give an int
    if isinstance(value, (array.array, np.ndarray, list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def assert_same(ros_msg, other, path="msg") -> None:
    """Every field of the rclpy message equals the same field of ``other`` (any reader's)."""
    for name in ros_msg.get_fields_and_field_types():
        a, b = getattr(ros_msg, name), getattr(other, name)
        here = f"{path}.{name}"
        if hasattr(a, "get_fields_and_field_types"):
            assert_same(a, b, here)
        elif isinstance(a, list) and a and hasattr(a[0], "get_fields_and_field_types"):
            assert len(a) == len(b), here
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                assert_same(x, y, f"{here}[{i}]")
        else:
            assert _plain(a) == _plain(b), here


# ----------------------------------------------------------------------------------------------
# Types, schema text, hashes, exact serialisation (no DDS)
# ----------------------------------------------------------------------------------------------
def test_type_names_and_classes():
    assert bag.message_type_name(JointState) == "sensor_msgs/msg/JointState"
    assert bag.message_type_name(Clock()) == "rosgraph_msgs/msg/Clock"
    assert bag.get_message_class("sensor_msgs/msg/JointState") is JointState
    assert bag.get_message_class("sensor_msgs/JointState") is JointState
    with pytest.raises(BagError, match="not installed"):
        bag.get_message_class("sensor_msgs/msg/NoSuchType")
    with pytest.raises(BagError, match="not of the form"):
        bag.get_message_class("JointState")
    with pytest.raises(BagError, match="not a ROS message"):
        bag.message_type_name(dict)


def _share(type_dir: str) -> str:
    pkg, name = type_dir.split("/")
    return (Path(sys.prefix) / "share" / pkg / "msg" / f"{name}.msg").read_bytes().decode()


def test_message_definition_is_rosbag2s_concatenation():
    sep = "\n" + "=" * 80 + "\nMSG: "
    expected = (
        _share("sensor_msgs/JointState")
        + sep
        + "std_msgs/Header\n"
        + _share("std_msgs/Header")
        + sep
        + "builtin_interfaces/Time\n"
        + _share("builtin_interfaces/Time")
    )
    assert bag.message_definition("sensor_msgs/msg/JointState") == expected
    # depth first, dependencies sorted, each once, unqualified names resolved in the package
    order = {
        "trajectory_msgs/msg/JointTrajectory": [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "trajectory_msgs/JointTrajectoryPoint",
            "builtin_interfaces/Duration",
        ],
        "std_msgs/msg/Float64MultiArray": [
            "std_msgs/MultiArrayLayout",
            "std_msgs/MultiArrayDimension",
        ],
        "diagnostic_msgs/msg/DiagnosticArray": [
            "diagnostic_msgs/DiagnosticStatus",
            "diagnostic_msgs/KeyValue",
            "std_msgs/Header",
            "builtin_interfaces/Time",
        ],
        "rosgraph_msgs/msg/Clock": ["builtin_interfaces/Time"],
    }
    for type_name, deps in order.items():
        text = bag.message_definition(type_name)
        assert [line[5:] for line in text.splitlines() if line.startswith("MSG: ")] == deps
    with pytest.raises(BagError, match=r"no msg/Nope\.msg"):
        bag.message_definition("sensor_msgs/msg/Nope")


@pytest.mark.parametrize("spec", wire.TOPICS, ids=lambda s: s.name)
def test_schema_text_is_complete_rosbags_hash_of_it_equals_the_type_hash(spec):
    """rosbags parses our schema text and hashes it (RIHS01): equal to the shipped type hash."""
    type_name = spec.type_name
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(get_types_from_msg(bag.message_definition(type_name), type_name))
    type_hash = bag.type_description_hash(type_name)
    assert type_hash.startswith("RIHS01_")
    assert typestore.hash_rihs01(type_name) == type_hash


@pytest.mark.parametrize("label", list(SAMPLES))
def test_serialize_message_pads_what_rosbags_rejects_so_the_writer_takes_raw_bytes(label):
    msg, padding = SAMPLES[label]
    exact = _cdr(msg)
    extra = len(serialize_message(msg)) - len(exact)
    if get_rmw_implementation_identifier() == "rmw_fastrtps_cpp":
        assert extra == padding  # what serialize_message pads (its buffer size is an estimate)
    assert extra >= 0
    assert deserialize_message(exact, type(msg)) == msg
    # rosbags is strict about the size: it accepts the exact bytes ...
    type_name = bag.message_type_name(msg)
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(get_types_from_msg(bag.message_definition(type_name), type_name))
    decoded = typestore.deserialize_cdr(exact, type_name)
    assert_same(msg, decoded)
    assert len(typestore.serialize_cdr(decoded, type_name)) == len(exact)
    # ... and rejects serialize_message's buffer when it carries 4 or more extra bytes.
    if extra > 3:
        with pytest.raises(Exception, match="size mismatch"):
            typestore.deserialize_cdr(bytes(serialize_message(msg)), type_name)


# ----------------------------------------------------------------------------------------------
# Raw subscription bytes (one process, DDS on localhost)
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def raw_samples():
    """Publish every sample once and capture it with a ``raw=True`` subscription."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROS_DOMAIN_ID", str(random.randint(1, 200)))
        mp.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        context = Context()
        rclpy.init(context=context)
        node = None
        try:
            node = rclpy.create_node("apc_test_bag_raw", context=context)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            got: dict[str, bytes] = {}
            pubs = {}
            for i, (label, (msg, _)) in enumerate(SAMPLES.items()):
                topic = f"raw_probe_{i}"
                pubs[label] = node.create_publisher(type(msg), topic, wire.CONTROL_QOS)
                node.create_subscription(
                    type(msg),
                    topic,
                    lambda data, label=label: got.setdefault(label, data),
                    wire.CONTROL_QOS,
                    raw=True,
                )
            deadline = time.monotonic() + 10.0
            while any(p.get_subscription_count() == 0 for p in pubs.values()):
                assert time.monotonic() < deadline, "publishers and raw subscriptions did not match"
                executor.spin_once(timeout_sec=0.01)
            for label, pub in pubs.items():
                pub.publish(SAMPLES[label][0])
            while len(got) < len(SAMPLES):
                assert time.monotonic() < deadline, f"not received: {set(SAMPLES) - set(got)}"
                executor.spin_once(timeout_sec=0.01)
            return got
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown(context=context)


@pytest.mark.ros
@pytest.mark.parametrize("label", list(SAMPLES))
def test_raw_subscription_bytes_have_the_exact_cdr_size(raw_samples, label):
    msg, _ = SAMPLES[label]
    raw = raw_samples[label]
    assert isinstance(raw, bytes)
    assert len(raw) == len(_cdr(msg))
    assert deserialize_message(raw, type(msg)) == msg


@pytest.mark.ros
def test_raw_bytes_through_a_bag_read_by_three_readers(raw_samples, tmp_path):
    """Record raw subscription bytes as the recorder does, read them back three ways."""
    path = tmp_path / "raw.mcap"
    labels = [label for label in SAMPLES if not label.startswith("std_msgs")]
    with BagWriter(path) as writer:
        for i, label in enumerate(labels):
            writer.add_topic(f"t{i}", type(SAMPLES[label][0]), wire.CONTROL_QOS)
            writer.write(f"t{i}", raw_samples[label], log_time_ns=(i + 1) * T_NS)
    ours = list(bag.read_messages(path))
    assert [m.data for m in ours] == [raw_samples[label] for label in labels]
    for m, label in zip(ours, labels, strict=True):
        assert m.decode() == SAMPLES[label][0]
    decoded = list(read_ros2_messages(str(path)))
    for m, label in zip(decoded, labels, strict=True):
        assert_same(SAMPLES[label][0], m.ros_msg)
    with AnyReader([path]) as reader:
        rows = list(reader.messages())
        assert len(rows) == len(labels)
        for (conn, timestamp, data), label in zip(rows, labels, strict=True):
            assert timestamp == (labels.index(label) + 1) * T_NS
            assert_same(SAMPLES[label][0], reader.deserialize(data, conn.msgtype))


# ----------------------------------------------------------------------------------------------
# Round trip of a whole run's worth of topics
# ----------------------------------------------------------------------------------------------
N = 6


def _run_messages(samples: int = 5) -> list[tuple[str, object, int, int]]:
    """(topic, message, log_time_ns, publish_time_ns) of a short run on every apc topic."""
    out = []
    goal = _goal(N)
    out.append((wire.TRAJECTORY_GOAL, goal, 0, 0))
    for k in range(samples):
        t = k * T_NS
        out.append((wire.CLOCK, _clock(k), t, t))
        out.append((wire.JOINT_STATES, _joint_state(N, k), t, t + 1))
        out.append((wire.SETPOINT, _setpoint(N, k), t, t + 2))
        out.append(
            (wire.FEEDFORWARD_TORQUE, wire.torque_to_msg(t, _names(N), np.ones(N) * k), t, t)
        )
        out.append((wire.FEEDBACK_TORQUE, wire.torque_to_msg(t, _names(N), -np.ones(N) * k), t, t))
        out.append((wire.ESTIMATE, _estimate(N, k), t, t))
        out.append((wire.DIAGNOSTICS, _diagnostics(k), t, t))
    return out


def _write_run(target, **kwargs) -> list[tuple[str, object, int, int, bytes]]:
    """Write a short run; return (topic, message, log time, publish time, bytes written).

    The bytes are kept: alignment gaps inside a CDR message are not zeroed by rclpy, so two
    serialisations of one message may differ there (never in a decoded value).
    """
    messages = []
    with BagWriter(target, custom_data={"case": "c"}, **kwargs) as writer:
        for spec in wire.TOPICS:
            writer.add_topic(spec.name, spec.msg_type, spec.qos)
        for sequence, (topic, msg, log_time, publish_time) in enumerate(_run_messages()):
            data = _cdr(msg)
            writer.write(topic, data, log_time, publish_time, sequence)
            messages.append((topic, msg, log_time, publish_time, data))
    return messages


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


# ----------------------------------------------------------------------------------------------
# Writer behaviour
# ----------------------------------------------------------------------------------------------
def test_small_chunks_lz4_and_idempotent_finish():
    buffer = io.BytesIO()
    writer = BagWriter(buffer, chunk_size=512, compression="lz4")
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(7, k), k * T_NS)
    assert writer.topics == {wire.JOINT_STATES: "sensor_msgs/msg/JointState"}
    assert writer.message_count == 100
    writer.finish()
    writer.finish()
    assert writer.finished
    buffer.seek(0)
    summary = make_reader(buffer).get_summary()
    assert summary.statistics.chunk_count > 10
    assert {c.compression for c in summary.chunk_indexes} == {"lz4"}
    read = list(bag.read_messages(buffer))
    assert [m.decode() for m in read] == [_joint_state(7, k) for k in range(100)]
    with pytest.raises(BagError, match="finished"):
        writer.write(wire.JOINT_STATES, read[0].data, 0)


def test_writer_errors(tmp_path):
    with pytest.raises(BagError, match="compression"):
        BagWriter(io.BytesIO(), compression="gzip")
    with pytest.raises(BagError, match="chunk_size"):
        BagWriter(io.BytesIO(), chunk_size=0)
    with pytest.raises(BagError, match="cannot create bag"):
        BagWriter(tmp_path / "missing_dir" / "x.mcap")
    data = _cdr(_joint_state(3))
    with BagWriter(io.BytesIO()) as writer:
        assert writer.add_topic("js", "sensor_msgs/msg/JointState") == writer.add_topic(
            "js", JointState
        )
        with pytest.raises(BagError, match="already added with type"):
            writer.add_topic("js", Clock)
        with pytest.raises(BagError, match="was not added"):
            writer.write("other", data, 0)
        with pytest.raises(BagError, match="not CDR"):
            writer.write("js", b"\x07\x07\x00\x00abcd", 0)
        with pytest.raises(BagError, match="integer nanoseconds"):
            writer.write("js", data, 0.5)
        with pytest.raises(BagError, match="outside"):
            writer.write("js", data, -1)
        with pytest.raises(BagError, match=r"no msg/Nope\.msg"):
            writer.add_topic("nope", "sensor_msgs/msg/Nope")
        writer.write("js", data, np.int64(5))


def test_context_manager_finishes_on_exception_and_closes_only_its_file(tmp_path):
    path = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError), BagWriter(path) as writer:
        _write(writer, "js", _joint_state(3), 1)
        raise RuntimeError("boom")
    assert writer._owned.closed
    assert bag.bag_info(path)["complete"]
    assert [m.decode() for m in bag.read_messages(path)] == [_joint_state(3)]


def test_read_filters_and_orders(tmp_path):
    path = tmp_path / "f.mcap"
    times = [30, 10, 20, 10, 40]
    with BagWriter(path) as writer:
        for i, t in enumerate(times):
            _write(writer, "a" if i % 2 == 0 else "b", String(data=str(i)), t)

    def data(**kw):
        return [m.decode().data for m in bag.read_messages(path, **kw)]

    assert data(log_time_order=False) == ["0", "1", "2", "3", "4"]
    assert data() == ["1", "3", "2", "0", "4"]
    assert data(topics="a") == ["2", "0", "4"]
    assert data(topics=["b"]) == ["1", "3"]
    assert data(start_ns=20, end_ns=40) == ["2", "0"]  # end excluded
    with open(path, "rb") as stream:  # a stream is read from its start and left open
        stream.read(10)
        assert len(list(bag.read_messages(stream))) == 5
        assert not stream.closed


class _NonSeekable(io.RawIOBase):
    def __init__(self, data: bytes) -> None:
        self._inner = io.BytesIO(data)

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        chunk = self._inner.read(min(len(b), 7))  # short reads, like a pipe
        b[: len(chunk)] = chunk
        return len(chunk)


def test_non_seekable_stream_is_scanned():
    buffer = io.BytesIO()
    written = _write_run(buffer)
    stream = _NonSeekable(buffer.getvalue())
    read = list(bag.read_messages(stream, log_time_order=False))
    assert [m.data for m in read] == [w[4] for w in written]
    info = bag.bag_info(_NonSeekable(buffer.getvalue()))
    assert info["complete"] and info["message_count"] == len(written)


def test_not_an_mcap():
    with pytest.raises(BagError, match="not an MCAP"):
        list(bag.read_messages(io.BytesIO(b"hello world, this is not a bag at all")))
    with pytest.raises(BagError, match="cannot open"):
        list(bag.read_messages("/nonexistent/x.mcap"))


# ----------------------------------------------------------------------------------------------
# Crash safety
# ----------------------------------------------------------------------------------------------
def _complete_chunks_end_times(data: bytes) -> list[tuple[int, int]]:
    """(end offset, last log time) of each chunk of a finished bag, from its chunk index."""
    summary = make_reader(io.BytesIO(data)).get_summary()
    return [
        (c.chunk_start_offset + c.chunk_length, c.message_end_time) for c in summary.chunk_indexes
    ]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_truncated_file_yields_every_message_of_the_complete_chunks(tmp_path, compression):
    buffer = io.BytesIO()
    times = [k * T_NS for k in range(300)]
    with BagWriter(buffer, chunk_size=2000, compression=compression) as writer:
        writer.add_topic(wire.JOINT_STATES, JointState, wire.CONTROL_QOS)
        for k, t in enumerate(times):
            writer.write(wire.JOINT_STATES, _cdr(_joint_state(6, k)), t)
    full = buffer.getvalue()
    chunks = _complete_chunks_end_times(full)
    assert len(chunks) > 20
    data_end = chunks[-1][0]
    rng = np.random.default_rng(0)
    cuts = sorted({*(end for end, _ in chunks), *(end - 1 for end, _ in chunks[:5])}) + [
        int(c) for c in rng.integers(8, data_end, size=25)
    ]
    for cut in cuts:
        done = [last for end, last in chunks if end <= cut]
        expected = [t for t in times if done and t <= done[-1]]
        with pytest.warns(BagTruncatedWarning, match="complete chunks"):
            read = list(bag.read_messages(io.BytesIO(full[:cut])))
        assert [m.log_time_ns for m in read] == expected, cut
        assert all(m.decode() == _joint_state(6, m.log_time_ns // T_NS) for m in read)
        info = bag.bag_info(io.BytesIO(full[:cut]))
        assert not info["complete"] and info["message_count"] == len(expected)
    # the same from a file on disk, and recover() makes it complete again
    cut = chunks[len(chunks) // 2][0] + 100
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(full[:cut])
    fixed = tmp_path / "fixed.mcap"
    count = bag.recover(broken, fixed)
    expected = [t for t in times if t <= chunks[len(chunks) // 2][1]]
    assert count == len(expected)
    info = bag.bag_info(fixed)
    assert info["complete"] and info["message_count"] == count
    assert info["topics"][wire.JOINT_STATES]["offered_qos_profiles"] == bag.qos_profiles_to_yaml(
        [wire.CONTROL_QOS]
    )
    assert [m.log_time_ns for m in bag.read_messages(fixed)] == expected
    with AnyReader([fixed]) as reader:
        assert sum(1 for _ in reader.messages()) == count


def test_bag_recover_command(tmp_path, capsys):
    """``bag_recover BROKEN FIXED``: one line on stdout; errors name the problem, exit 1, and
    leave no file behind."""
    buffer = io.BytesIO()
    with BagWriter(buffer, chunk_size=2000) as writer:
        writer.add_topic(wire.JOINT_STATES, JointState, wire.CONTROL_QOS)
        for k in range(100):
            writer.write(wire.JOINT_STATES, _cdr(_joint_state(6, k)), k * T_NS)
    full = buffer.getvalue()
    end, last = _complete_chunks_end_times(full)[3]
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(full[: end + 50])
    fixed = tmp_path / "fixed.mcap"
    assert bag_recover([str(broken), str(fixed)]) == 0
    count = last // T_NS + 1
    line = f"{broken} ends before its footer: {count} messages on 1 topics written to {fixed}"
    assert capsys.readouterr().out.strip() == line
    assert bag.bag_info(fixed)["complete"] and bag.bag_info(fixed)["message_count"] == count
    with AnyReader([fixed]) as reader:
        assert sum(1 for _ in reader.messages()) == count

    assert bag_recover([str(broken), str(fixed)]) == 1  # never replaced unless asked
    assert "exists (--force replaces it)" in capsys.readouterr().err
    assert bag_recover([str(fixed), str(fixed), "--force"]) == 1
    assert "the destination is the source" in capsys.readouterr().err
    complete = tmp_path / "complete.mcap"
    complete.write_bytes(full)
    assert bag_recover([str(complete), str(fixed), "--force", "--compression", "lz4"]) == 0
    assert capsys.readouterr().out.startswith(f"{complete} was complete: 100 messages")
    assert bag.bag_info(fixed)["message_count"] == 100

    not_a_bag = tmp_path / "notes.txt"
    not_a_bag.write_text("hello world, this is not a bag at all")
    out = tmp_path / "out.mcap"
    assert bag_recover([str(not_a_bag), str(out)]) == 1
    assert "not an MCAP file (bad magic)" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "broken.mcap",
        "complete.mcap",
        "fixed.mcap",
        "notes.txt",
    ]


def test_a_chunk_is_in_the_stream_as_soon_as_it_is_complete():
    """No finish(): what is in the stream already is every complete chunk (nothing buffered)."""
    buffer = io.BytesIO()
    writer = BagWriter(buffer, chunk_size=1500, max_chunk_interval_ns=None)
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(6, k), k * T_NS)
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(io.BytesIO(buffer.getvalue())))
    per_chunk = 1500 // len(_cdr(_joint_state(6))) + 1
    assert 100 - per_chunk <= len(read) < 100
    # max_chunk_interval_ns bounds the loss in (log) time, too
    buffer = io.BytesIO()
    writer = BagWriter(buffer, max_chunk_interval_ns=5 * T_NS)
    for k in range(100):
        _write(writer, wire.JOINT_STATES, _joint_state(6, k), k * T_NS)
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(io.BytesIO(buffer.getvalue())))
    assert 100 - 6 <= len(read) < 100
    writer.flush()  # an explicit flush closes the open chunk
    with pytest.warns(BagTruncatedWarning):  # still no footer: finish() writes it
        assert len(list(bag.read_messages(io.BytesIO(buffer.getvalue())))) == 100


_CHILD = textwrap.dedent(
    """
    import sys, time
    from rclpy.serialization import serialize_message
    import apc_msgs_py as wire
    from apc_recording import bag
    import numpy as np
    path, n = sys.argv[1], int(sys.argv[2])
    writer = bag.BagWriter(path, chunk_size=2048)
    writer.add_topic(wire.JOINT_STATES, "sensor_msgs/msg/JointState", wire.CONTROL_QOS)
    for k in range(n):
        t = k * 10_000_000
        msg = wire.arrays_to_joint_state(t, ["a", "b", "c"], np.full(3, k), np.zeros(3))
        writer.write(wire.JOINT_STATES, bytes(serialize_message(msg)), t)
    print("written", flush=True)
    time.sleep(60)
    """
)


def test_sigkill_loses_at_most_the_open_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    n = 1000
    errors = tmp_path / "child.err"
    with open(errors, "w") as stderr:
        child = subprocess.Popen(
            [sys.executable, "-c", _CHILD, str(path), str(n)],
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
        )
    try:
        ready, _, _ = select.select([child.stdout], [], [], 30.0)
        line = child.stdout.readline() if ready else ""
        assert line.strip() == "written", f"child did not finish writing: {errors.read_text()}"
    finally:
        child.send_signal(signal.SIGKILL)  # no finish(): the file has no summary and no footer
        child.wait(timeout=10)
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    with pytest.warns(BagTruncatedWarning):
        read = list(bag.read_messages(path))
    size = len(serialize_message(wire.arrays_to_joint_state(0, ["a", "b", "c"], np.zeros(3))))
    per_chunk = 2048 // size + 1
    assert n - per_chunk <= len(read) < n
    assert [m.log_time_ns for m in read] == [k * T_NS for k in range(len(read))]
    assert [m.decode().position[0] for m in read] == [float(k) for k in range(len(read))]
