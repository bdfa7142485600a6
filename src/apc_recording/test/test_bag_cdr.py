"""rosbag2-compatible MCAP, types and bytes: message type names and classes, the schema text
(rosbag2's concatenated definition; rosbags' hash of it is the shipped type hash), and exact CDR.

``serialize_message`` pads what rosbags rejects, so the writer takes the raw bytes a ``raw=True``
subscription delivers: those bytes are checked over DDS on localhost to have the exact CDR size,
and go through a bag read back with our reader, ``mcap_ros2`` and rosbags.
"""

from __future__ import annotations

import random
import sys
import time
import warnings
from pathlib import Path

import pytest
import rclpy
from bag_helpers import SAMPLES, T_NS, _cdr, assert_same
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import get_rmw_implementation_identifier
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

import apc_msgs_py as wire
from apc_recording import bag
from apc_recording.bag import BagError, BagWriter

with warnings.catch_warnings():  # mcap_ros2.reader warns about itself on import (deprecation)
    warnings.simplefilter("ignore", DeprecationWarning)
    from mcap_ros2.reader import read_ros2_messages


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
