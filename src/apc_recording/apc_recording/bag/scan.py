"""Open a bag source and read an MCAP file front to back, whole or cut short.

A complete file (seekable, ending in a footer, :func:`is_complete`) is best read through its
index; any other file -- a recorder killed mid-run leaves no summary, index or footer; a pipe
cannot seek -- is read front to back by :func:`scan` with mcap's ``StreamReader``, which checks
each chunk's CRC. The scan stops quietly at the first record that is cut short or corrupt, so a
truncated file gives exactly the messages of its complete chunks.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import IO

import zstandard
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.reader import FOOTER_SIZE
from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader
from mcap.writer import MCAP0_MAGIC

from apc_recording.bag.errors import BagError

__all__ = ["Scanned", "Source", "describe", "is_complete", "opened", "scan"]

#: A bag to read: a path, or a binary stream (read from its start if seekable, left open).
Source = str | bytes | os.PathLike | IO[bytes]

#: What reading a record that is cut short or corrupt raises: mcap's errors (``EndOfFile``, a
#: record over the size limit), ``struct.error`` for a field cut in two, ``ValueError`` for a
#: chunk CRC mismatch or undecodable text, ``zstandard.ZstdError`` and (from lz4)
#: ``RuntimeError`` for a compressed chunk cut short.
_CUT_SHORT = (McapError, struct.error, ValueError, zstandard.ZstdError, RuntimeError)


def describe(source: Source) -> str:
    """The name of a source for messages: its path, or the stream's name or type."""
    if isinstance(source, (str, bytes, os.PathLike)):
        return os.fsdecode(source)
    return str(getattr(source, "name", type(source).__name__))


@contextlib.contextmanager
def opened(source: Source) -> Iterator[IO[bytes]]:
    """Open a path (and close it afterwards), or pass a stream through (left open)."""
    if isinstance(source, (str, bytes, os.PathLike)):
        try:
            stream = open(source, "rb")  # closed below
        except OSError as err:
            raise BagError(f"cannot open bag {os.fsdecode(source)!r}: {err}") from None
        try:
            yield stream
        finally:
            stream.close()
    else:
        if source.seekable():
            source.seek(0)
        yield source


def is_complete(stream: IO[bytes]) -> bool:
    """True if a seekable stream ends with an MCAP footer record and the closing magic."""
    if not stream.seekable():
        return False
    size = stream.seek(0, io.SEEK_END)
    ok = False
    if size >= 2 * MAGIC_SIZE + FOOTER_SIZE:
        stream.seek(size - FOOTER_SIZE - MAGIC_SIZE)
        tail = stream.read(FOOTER_SIZE + MAGIC_SIZE)
        ok = (
            tail[FOOTER_SIZE:] == MCAP0_MAGIC
            and tail[0] == Opcode.FOOTER
            and struct.unpack_from("<Q", tail, 1)[0] == FOOTER_SIZE - 9
        )
    stream.seek(0)
    return ok


@dataclass
class Scanned:
    """What a linear read found besides the messages, and whether the file was complete."""

    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: list[Metadata] = field(default_factory=list)
    complete: bool = False
    problem: str = ""


def scan(stream: IO[bytes], found: Scanned, name: str) -> Iterator[Message]:
    """Read records in file order with mcap's stream reader, yielding messages.

    Stops quietly at the first record that is cut short or corrupt (``found.problem`` says
    which): a chunk is yielded only whole and with a valid CRC.

    Raises
    ------
    BagError
        If the stream does not start with the MCAP magic.
    """
    if isinstance(stream, io.RawIOBase):
        stream = io.BufferedReader(stream)  # reads whole records from a stream that reads short
    if stream.read(MAGIC_SIZE) != MCAP0_MAGIC:
        raise BagError(f"{name}: not an MCAP file (bad magic)")
    try:
        for record in StreamReader(stream, skip_magic=True, validate_crcs=True).records:
            if isinstance(record, Message):
                yield record
            elif isinstance(record, Channel):
                found.channels[record.id] = record
            elif isinstance(record, Schema):
                found.schemas[record.id] = record
            elif isinstance(record, Header):
                found.header = record
            elif isinstance(record, Metadata):
                found.metadata.append(record)
            elif isinstance(record, Footer):
                found.complete = True
                return
    except _CUT_SHORT as err:
        cut = isinstance(err, (EndOfFile, struct.error))
        found.problem = "the file ends before its footer" if cut else f"a record is corrupt ({err})"
