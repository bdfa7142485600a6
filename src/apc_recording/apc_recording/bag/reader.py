"""Read rosbag2 MCAP files: the messages (:func:`read_messages`) and a summary (:func:`bag_info`).

A complete file is read through its summary and chunk index with mcap's ``SeekingReader``; a file
a killed writer left without summary and footer, or a stream that cannot seek, is read front to
back (:func:`~apc_recording.bag.scan.scan`): every message of every complete chunk, with a
:class:`~apc_recording.bag.errors.BagTruncatedWarning` if the footer is missing.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Header, Message, Metadata, Schema
from rclpy.serialization import deserialize_message

from apc_recording.bag.errors import BagError, BagTruncatedWarning
from apc_recording.bag.interfaces import get_message_class
from apc_recording.bag.metadata import parse_rosbag2_metadata
from apc_recording.bag.scan import Scanned, Source, describe, is_complete, opened, scan

__all__ = ["BagMessage", "bag_info", "read_messages"]


@dataclass(frozen=True)
class BagMessage:
    """One message read from a bag.

    Attributes
    ----------
    topic : str
    type_name : str
        ``"sensor_msgs/msg/JointState"`` (the schema name).
    log_time_ns : int
        Receive / log time.
    publish_time_ns : int
    data : bytes
        The raw CDR bytes.
    sequence : int
    """

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int = 0

    def decode(self) -> Any:
        """Deserialise :attr:`data` into the installed rclpy message class.

        Raises
        ------
        BagError
            If the type is not installed.
        """
        return deserialize_message(self.data, get_message_class(self.type_name))


def _bag_message(schema: Schema | None, channel: Channel, message: Message) -> BagMessage:
    return BagMessage(
        topic=channel.topic,
        type_name=schema.name if schema is not None else "",
        log_time_ns=message.log_time,
        publish_time_ns=message.publish_time,
        data=message.data,
        sequence=message.sequence,
    )


def read_messages(
    source: Source,
    topics: Iterable[str] | str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
    *,
    log_time_order: bool = True,
) -> Iterator[BagMessage]:
    """Iterate over the messages of a bag.

    Parameters
    ----------
    source : path or binary stream
        A path is opened and closed here; a stream is read from its start (if seekable) and left
        open.
    topics : str or iterable of str, optional
        Only these topics.
    start_ns, end_ns : int, optional
        Only messages with ``start_ns <= log_time < end_ns`` (the end is excluded, as in mcap).
    log_time_order : bool
        Yield in log-time order (ties in file order); else in file order.

    Yields
    ------
    BagMessage

    Notes
    -----
    A complete file is read through its index. A file without footer (a recorder killed
    mid-run) or a non-seekable stream is scanned linearly instead; for a truncated file every
    message of every complete chunk is yielded and a :class:`BagTruncatedWarning` is issued.

    Raises
    ------
    BagError
        If the source is not an MCAP file.
    """
    wanted = {topics} if isinstance(topics, str) else (set(topics) if topics is not None else None)
    with opened(source) as stream:
        if is_complete(stream):
            try:
                reader = SeekingReader(stream)
                iterator = reader.iter_messages(
                    topics=sorted(wanted) if wanted is not None else None,
                    log_time_order=log_time_order,
                    starting_at=start_ns,
                    ending_before=end_ns,
                )
                for schema, channel, message in iterator:
                    yield _bag_message(schema, channel, message)
                return
            except McapError as err:
                raise BagError(f"{describe(source)}: {err}") from None
        found = Scanned()
        selected: list[BagMessage] = []
        for message in scan(stream, found, describe(source)):
            channel = found.channels.get(message.channel_id)
            if channel is None:
                continue
            if wanted is not None and channel.topic not in wanted:
                continue
            if start_ns is not None and message.log_time < start_ns:
                continue
            if end_ns is not None and message.log_time >= end_ns:
                continue
            item = _bag_message(found.schemas.get(channel.schema_id), channel, message)
            if log_time_order:
                selected.append(item)
            else:
                yield item
        if not found.complete:
            warnings.warn(
                f"{describe(source)}: {found.problem}; read the messages of the complete chunks",
                BagTruncatedWarning,
                stacklevel=2,
            )
        if log_time_order:
            selected.sort(key=lambda m: m.log_time_ns)
            yield from selected


def bag_info(source: Source) -> dict[str, Any]:
    """Summarise a bag, like ``ros2 bag info``.

    Returns
    -------
    dict
        ``profile``, ``library``, ``complete`` (False for a truncated file), ``message_count``,
        ``start_ns`` / ``end_ns`` (first and last log time, ``None`` if empty), ``duration_ns``,
        ``topics``: ``{topic: {"type", "message_count", "serialization_format",
        "offered_qos_profiles", "type_hash", "schema_encoding"}}``, and ``rosbag2_metadata``
        (the parsed ``serialized_metadata``, or ``None``).

    Raises
    ------
    BagError
        If the source is not an MCAP file.
    """
    with opened(source) as stream:
        if is_complete(stream):
            try:
                reader = SeekingReader(stream)
                header = reader.get_header()
                summary = reader.get_summary()
                metadata = list(reader.iter_metadata())
            except McapError as err:
                raise BagError(f"{describe(source)}: {err}") from None
            if summary is not None and summary.statistics is not None:
                stats = summary.statistics
                counts = dict(stats.channel_message_counts)
                total = stats.message_count
                first = stats.message_start_time if total else None
                last = stats.message_end_time if total else None
                return _info(
                    header,
                    summary.schemas,
                    summary.channels,
                    counts,
                    total,
                    first,
                    last,
                    True,
                    metadata,
                )
            stream.seek(0)
        found = Scanned()
        counts: dict[int, int] = {}
        first = last = None
        total = 0
        for message in scan(stream, found, describe(source)):
            counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
            total += 1
            first = message.log_time if first is None else min(first, message.log_time)
            last = message.log_time if last is None else max(last, message.log_time)
        return _info(
            found.header,
            found.schemas,
            found.channels,
            counts,
            total,
            first,
            last,
            found.complete,
            found.metadata,
        )


def _info(
    header: Header | None,
    schemas: Mapping[int, Schema],
    channels: Mapping[int, Channel],
    counts: Mapping[int, int],
    total: int,
    first: int | None,
    last: int | None,
    complete: bool,
    metadata: Iterable[Metadata],
) -> dict[str, Any]:
    topics = {}
    for cid, channel in sorted(channels.items()):
        schema = schemas.get(channel.schema_id)
        topics[channel.topic] = {
            "type": schema.name if schema is not None else "",
            "message_count": counts.get(cid, 0),
            "serialization_format": channel.message_encoding,
            "offered_qos_profiles": channel.metadata.get("offered_qos_profiles", ""),
            "type_hash": channel.metadata.get("topic_type_hash", ""),
            "schema_encoding": schema.encoding if schema is not None else "",
        }
    return {
        "profile": header.profile if header is not None else "",
        "library": header.library if header is not None else "",
        "complete": complete,
        "message_count": total,
        "start_ns": first,
        "end_ns": last,
        "duration_ns": (last - first) if first is not None and last is not None else 0,
        "topics": topics,
        "rosbag2_metadata": parse_rosbag2_metadata(metadata),
    }
