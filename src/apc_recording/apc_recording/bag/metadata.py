"""The ``rosbag2`` metadata record: rosbag2's ``BagMetadata`` (version 9) as YAML.

rosbag2 stores it in an MCAP metadata record named ``rosbag2`` (key ``serialized_metadata``);
``ros2 bag info`` and rosbags read the topic list, counts and times from it. The writer builds
it at finish (:func:`rosbag2_metadata_yaml`), :func:`~apc_recording.bag.reader.bag_info` parses it
(:func:`parse_rosbag2_metadata`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import yaml
from mcap.records import Metadata

__all__ = [
    "MESSAGE_ENCODING",
    "METADATA_NAME",
    "ROSBAG2_METADATA_VERSION",
    "RecordedTopic",
    "parse_rosbag2_metadata",
    "rosbag2_metadata_yaml",
]

#: Message encoding of every channel (and ``serialization_format`` of every topic).
MESSAGE_ENCODING = "cdr"
ROSBAG2_METADATA_VERSION = 9
METADATA_NAME = "rosbag2"
_KEY = "serialized_metadata"


@dataclass
class RecordedTopic:
    """A topic as the writer keeps it: its channel, what the metadata says, messages so far."""

    channel_id: int
    type_name: str
    qos_yaml: str
    type_hash: str
    count: int = 0


def rosbag2_metadata_yaml(
    topics: Mapping[str, RecordedTopic],
    *,
    message_count: int,
    start_ns: int | None,
    end_ns: int | None,
    file_name: str,
    custom_data: Mapping[str, str],
    ros_distro: str,
) -> dict[str, str]:
    """The metadata record's content (``{"serialized_metadata": yaml}``) for a finished file.

    ``start_ns`` / ``end_ns`` are the first and last log time (``None`` for an empty file).
    """
    start = start_ns if start_ns is not None else 0
    duration = (end_ns - start) if end_ns is not None else 0
    entries = []
    for name, topic in topics.items():
        try:
            qos = yaml.safe_load(topic.qos_yaml) if topic.qos_yaml else []
        except yaml.YAMLError:
            qos = topic.qos_yaml
        entries.append(
            {
                "topic_metadata": {
                    "name": name,
                    "type": topic.type_name,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": qos if qos is not None else [],
                    "type_description_hash": topic.type_hash,
                },
                "message_count": topic.count,
            }
        )
    document = {
        "version": ROSBAG2_METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": message_count,
        "topics_with_message_count": entries,
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": message_count,
            }
        ],
        "custom_data": dict(custom_data),
        "ros_distro": ros_distro,
    }
    return {_KEY: yaml.safe_dump(document, sort_keys=False, default_flow_style=False)}


def parse_rosbag2_metadata(records: Iterable[Metadata]) -> dict[str, Any] | None:
    """The parsed ``BagMetadata`` of the first ``rosbag2`` record, or ``None`` (none, not YAML)."""
    for record in records:
        if record.name == METADATA_NAME and _KEY in record.metadata:
            try:
                return yaml.safe_load(record.metadata[_KEY])
            except yaml.YAMLError:
                return None
    return None
