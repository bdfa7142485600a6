"""Recover a bag a killed writer left without summary, index and footer (``bag_recover``).

Like ``mcap recover``: every message of every complete chunk is copied into a new, complete and
indexed file that every tool opens quickly, with each channel's schema text,
``offered_qos_profiles`` and type hash as recorded (so no message type needs to be installed).

    bag_recover runs/killed.mcap runs/killed_recovered.mcap
    ros2 run apc_recording bag_recover runs/killed.mcap runs/killed_recovered.mcap
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path
from typing import IO

from apc_recording.bag.errors import BagError
from apc_recording.bag.reader import bag_info
from apc_recording.bag.scan import Scanned, Source, describe, opened, scan
from apc_recording.bag.writer import DEFAULT_CHUNK_SIZE, BagWriter

__all__ = ["main", "recover"]

_COMPRESSIONS = ("zstd", "lz4", "none")


def recover(
    source: Source,
    destination: str | os.PathLike | IO[bytes],
    *,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    compression: str | None = "zstd",
) -> int:
    """Rewrite a (possibly truncated) bag into a complete, indexed one.

    Every message of every complete chunk is copied in file order, with its channel's schema
    text, ``offered_qos_profiles`` and type hash as recorded; the new file gets a summary and a
    ``rosbag2`` metadata record.

    Returns
    -------
    int
        Number of messages recovered.

    Raises
    ------
    BagError
        If the source is not an MCAP file.
    """
    count = 0
    with opened(source) as stream:
        found = Scanned()
        with BagWriter(destination, chunk_size=chunk_size, compression=compression) as out:
            for message in scan(stream, found, describe(source)):
                channel = found.channels.get(message.channel_id)
                if channel is None:
                    continue
                if channel.topic not in out.topics:
                    schema = found.schemas.get(channel.schema_id)
                    if schema is None:
                        continue
                    out.add_topic(
                        channel.topic,
                        schema.name,
                        channel.metadata.get("offered_qos_profiles", "[]"),
                        type_hash=channel.metadata.get("topic_type_hash", ""),
                        schema=(schema.encoding, schema.data),
                    )
                out.write(
                    channel.topic,
                    message.data,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                )
                count += 1
    return count


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bag_recover",
        description=(
            "Copy every message of every complete chunk of an MCAP bag (e.g. one a killed"
            " recorder left without summary and footer) into a complete, indexed bag."
        ),
    )
    parser.add_argument("source", type=Path, help="the bag to recover")
    parser.add_argument("destination", type=Path, help="the complete bag to write")
    parser.add_argument(
        "--compression", choices=_COMPRESSIONS, default="zstd", help="chunk compression"
    )
    parser.add_argument(
        "--chunk-size",
        type=int,
        default=DEFAULT_CHUNK_SIZE,
        help="uncompressed bytes per chunk (default %(default)s)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite the destination")
    return parser


def main(args: list[str] | None = None) -> int:
    """``bag_recover SOURCE DESTINATION``: exit 0 with one line saying what was recovered.

    The destination is written beside itself under a ``.part`` name and renamed when complete,
    so a failure leaves no half-written bag and an existing file is replaced only on success.
    """
    options = _parser().parse_args(args)
    source: Path = options.source
    destination: Path = options.destination
    if destination.exists() and not options.force:
        print(f"bag_recover: {destination} exists (--force replaces it)", file=sys.stderr)
        return 1
    if destination.exists() and destination.resolve() == source.resolve():
        print("bag_recover: the destination is the source", file=sys.stderr)
        return 1
    part = destination.with_name(destination.name + ".part")
    try:
        complete = bag_info(source)["complete"]
        count = recover(
            source, part, chunk_size=options.chunk_size, compression=options.compression
        )
        os.replace(part, destination)
    except (BagError, OSError) as err:
        with contextlib.suppress(FileNotFoundError):
            part.unlink()
        print(f"bag_recover: {err}", file=sys.stderr)
        return 1
    topics = len(bag_info(destination)["topics"])
    state = "was complete" if complete else "ends before its footer"
    print(f"{source} {state}: {count} messages on {topics} topics written to {destination}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
