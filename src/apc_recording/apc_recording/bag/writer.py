"""Write rosbag2-compatible MCAP files, chunk by chunk, safe against a killed writer.

Files are written the way rosbag2's MCAP storage plugin (``rosbag2_storage_mcap``, Jazzy) writes
them, so they open in Foxglove, PlotJuggler, ``ros2 bag info/play`` and rosbags:

- header profile ``ros2``;
- one schema per message type (:func:`~apc_recording.bag.interfaces.message_definition`);
- one channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles`` (rosbag2's
  version-9 QoS YAML, :mod:`apc_recording.bag.qos_yaml`) and ``topic_type_hash``;
- message records with log time = receive (or sample) time and publish time, integer ns;
- at :meth:`BagWriter.finish`, the ``rosbag2`` metadata record (:mod:`apc_recording.bag.metadata`).

Chunks are compressed (zstd by default) and written through to the OS as soon as each chunk is
complete, so a writer killed with SIGKILL loses at most the chunk in progress.

The writer takes raw CDR bytes, the bytes a ``raw=True`` subscription delivers (what rosbag2
records). ``rclpy.serialization.serialize_message`` is no substitute: it sizes its buffer by an
estimate that is 4 bytes long per empty ``float64[]`` (a torque ``JointState``, a goal with
positions only), and rosbags rejects a message with 4 or more trailing bytes.
"""

from __future__ import annotations

import contextlib
import io
import os
import threading
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap.writer import __version__ as mcap_version
from rclpy.qos import QoSProfile

from apc_recording.bag.errors import BagError
from apc_recording.bag.interfaces import (
    SCHEMA_ENCODING,
    canonical_type_name,
    message_definition,
    type_description_hash,
)
from apc_recording.bag.metadata import (
    MESSAGE_ENCODING,
    METADATA_NAME,
    RecordedTopic,
    rosbag2_metadata_yaml,
)
from apc_recording.bag.qos_yaml import qos_profiles_to_yaml

__all__ = [
    "DEFAULT_CHUNK_SIZE",
    "LIBRARY",
    "PROFILE",
    "BagWriter",
]

PROFILE = "ros2"
#: Header ``library`` field: this writer, then the MCAP library it drives (rosbag2 writes
#: ``libmcap <version>``).
LIBRARY = f"apc_recording.bag 0.1.0; mcap-python {mcap_version}"
#: Uncompressed bytes per chunk (rosbag2's default too). At apc's ~200 kB/s this is ~5 s of a run;
#: pass ``max_chunk_interval_ns`` to bound the loss on a crash in time as well.
DEFAULT_CHUNK_SIZE = 1024 * 1024

_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
    None: CompressionType.NONE,
}


class _WriteThrough:
    """The stream the MCAP writer sees: every write is pushed to the OS at once.

    The mcap writer buffers messages in a chunk in memory and writes to its stream only when a
    chunk is complete (the chunk, then its message indexes), for metadata and at finish. So
    flushing after each write puts every completed chunk in the OS page cache immediately,
    where it survives the process being killed (``fsync=True`` also survives power loss).
    ``tell`` is counted here, so pipes work too.
    """

    def __init__(self, raw: IO[bytes], fsync: bool) -> None:
        self._raw = raw
        self._fsync = fsync
        try:
            self._pos = raw.tell()
        except (OSError, AttributeError, io.UnsupportedOperation):
            self._pos = 0
        self.writes = 0

    def write(self, data: bytes) -> int:
        if not data:
            return 0
        self._raw.write(data)
        self._pos += len(data)
        self.writes += 1
        self.flush()
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        flush = getattr(self._raw, "flush", None)
        if flush is not None:
            flush()
        if self._fsync:
            with contextlib.suppress(AttributeError, OSError, io.UnsupportedOperation):
                os.fsync(self._raw.fileno())


class BagWriter:
    """Write a rosbag2-compatible MCAP file (see the module docstring for the format).

    Parameters
    ----------
    output : str, os.PathLike or binary stream
        A path (the file is created and closed by the writer) or a writable binary stream (left
        open; ``tell`` is not required).
    chunk_size : int
        Uncompressed bytes per chunk (default 1 MiB). Small values make more, smaller chunks.
    compression : {"zstd", "lz4", "none"}
        Per-chunk compression.
    fsync : bool
        Also ``os.fsync`` after each chunk (survives power loss, not just a killed process).
    max_chunk_interval_ns : int, optional
        Also close a chunk once it spans this much log time, bounding what a crash can lose in
        time as well as in bytes.
    custom_data : mapping of str to str, optional
        Stored in the ``rosbag2`` metadata (``custom_data``), e.g. the experiment configuration.
    ros_distro : str, optional
        Stored in the ``rosbag2`` metadata; default ``$ROS_DISTRO`` or ``"jazzy"``.

    Examples
    --------
    >>> with BagWriter("run.mcap") as bag:                                     # doctest: +SKIP
    ...     bag.add_topic("joint_states", "sensor_msgs/msg/JointState", CONTROL_QOS)
    ...     bag.write("joint_states", raw_bytes, log_time_ns=k * 10_000_000)

    Times are integer nanoseconds. The writer is thread safe; :meth:`finish` (called on leaving
    the ``with`` block, also on an exception) is idempotent.
    """

    def __init__(
        self,
        output: str | os.PathLike | IO[bytes],
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str | None = "zstd",
        fsync: bool = False,
        max_chunk_interval_ns: int | None = None,
        custom_data: Mapping[str, str] | None = None,
        ros_distro: str | None = None,
    ) -> None:
        if compression not in _COMPRESSION:
            raise BagError(f"compression must be 'zstd', 'lz4' or 'none', got {compression!r}")
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size <= 0:
            raise BagError(f"chunk_size must be a positive integer, got {chunk_size!r}")
        if max_chunk_interval_ns is not None and max_chunk_interval_ns <= 0:
            raise BagError(f"max_chunk_interval_ns must be > 0, got {max_chunk_interval_ns}")
        self._custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self._ros_distro = ros_distro or os.environ.get("ROS_DISTRO") or "jazzy"
        self._owned: IO[bytes] | None = None
        if isinstance(output, (str, os.PathLike)):
            self.path: Path | None = Path(output)
            try:
                self._owned = open(self.path, "wb")  # closed in finish()
            except OSError as err:
                raise BagError(f"cannot create bag {str(self.path)!r}: {err}") from None
            raw: IO[bytes] = self._owned
        else:
            name = getattr(output, "name", None)
            self.path = Path(name) if isinstance(name, str) else None
            raw = output
        self._stream = _WriteThrough(raw, fsync)
        try:
            self._mcap = McapWriter(
                self._stream,  # type: ignore[arg-type]
                chunk_size=chunk_size,
                compression=_COMPRESSION[compression],
                enable_crcs=True,
            )
            self._mcap.start(profile=PROFILE, library=LIBRARY)
        except Exception:
            if self._owned is not None:
                self._owned.close()
            raise
        self._lock = threading.Lock()
        self._topics: dict[str, RecordedTopic] = {}
        self._schema_ids: dict[str, int] = {}
        self._count = 0
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        self._interval = max_chunk_interval_ns
        self._chunk_since: int | None = None
        self._finished = False

    # -- context manager ------------------------------------------------------------------------
    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()

    # -- properties -----------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        """True once :meth:`finish` has run."""
        return self._finished

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._count

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> type name of every topic added."""
        return {name: t.type_name for name, t in self._topics.items()}

    # -- topics ---------------------------------------------------------------------------------
    def add_topic(
        self,
        topic: str,
        type_name: str | type,
        qos: QoSProfile | Iterable[QoSProfile] | str | None = None,
        *,
        type_hash: str | None = None,
        schema: tuple[str, bytes] | None = None,
    ) -> int:
        """Declare a topic (an MCAP channel) before writing to it.

        Parameters
        ----------
        topic : str
            Topic name as it should appear in the bag (the recorder uses the resolved name).
        type_name : str or message class
            ``"sensor_msgs/msg/JointState"`` or ``sensor_msgs.msg.JointState``.
        qos : QoSProfile, list of QoSProfile, str or None
            What the publisher(s) offered (stored as ``offered_qos_profiles``; a ``str`` is
            stored as is). ``None`` stores an empty list.
        type_hash : str, optional
            ``RIHS01_...``; default: from the type's description file.
        schema : (encoding, data), optional
            A schema read from another bag, stored as it is under ``type_name`` as it is;
            default: the ``ros2msg`` text built from the installed ``.msg`` files. Copying a
            bag this way needs none of its types installed.

        Returns
        -------
        int
            The channel id. Adding the same topic again with the same type returns the same id.

        Raises
        ------
        BagError
            If the topic exists with another type, the type's ``.msg`` files cannot be found, or
            the writer is finished.
        """
        if schema is not None and isinstance(type_name, str):
            name = type_name
        else:
            name = canonical_type_name(type_name)
        if isinstance(qos, str):
            qos_yaml = qos
        elif qos is None:
            qos_yaml = qos_profiles_to_yaml([])
        elif isinstance(qos, QoSProfile):
            qos_yaml = qos_profiles_to_yaml([qos])
        else:
            qos_yaml = qos_profiles_to_yaml(qos)
        if type_hash is None:
            type_hash = type_description_hash(name)
        with self._lock:
            self._check_open()
            if topic in self._topics:
                known = self._topics[topic]
                if known.type_name != name:
                    raise BagError(
                        f"topic {topic!r} already added with type {known.type_name!r}, not {name!r}"
                    )
                return known.channel_id
            schema_id = self._schema_ids.get(name)
            if schema_id is None:  # one schema per type
                encoding, data = schema or (SCHEMA_ENCODING, message_definition(name).encode())
                schema_id = self._mcap.register_schema(name=name, encoding=encoding, data=data)
                self._schema_ids[name] = schema_id
            channel_id = self._mcap.register_channel(
                topic=topic,
                message_encoding=MESSAGE_ENCODING,
                schema_id=schema_id,
                metadata={"offered_qos_profiles": qos_yaml, "topic_type_hash": type_hash},
            )
            self._topics[topic] = RecordedTopic(channel_id, name, qos_yaml, type_hash)
            return channel_id

    # -- messages -------------------------------------------------------------------------------
    def write(
        self,
        topic: str,
        raw_cdr: bytes | bytearray | memoryview,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        sequence: int = 0,
    ) -> None:
        """Write one serialized message (raw CDR bytes, as a ``raw=True`` subscription gives).

        Parameters
        ----------
        topic : str
            A topic added with :meth:`add_topic`.
        raw_cdr : bytes-like
            The CDR bytes including the 4-byte encapsulation header.
        log_time_ns : int
            Receive time (rosbag2's ``recv_timestamp``); apc logs the sample time ``kT`` in
            lockstep runs.
        publish_time_ns : int, optional
            Send time; default ``log_time_ns``.
        sequence : int
            Optional publisher sequence number.

        Raises
        ------
        BagError
            Unknown topic, data without a CDR encapsulation header, a time that is not a
            non-negative integer, or a finished writer.
        """
        data = raw_cdr if type(raw_cdr) is bytes else bytes(raw_cdr)
        if len(data) < 4 or data[0] != 0 or data[1] > 0x0B:
            raise BagError(f"{topic}: data is not CDR (no encapsulation header): {data[:4]!r}")
        log_time = _check_time(log_time_ns, "log_time_ns")
        publish_time = (
            log_time if publish_time_ns is None else _check_time(publish_time_ns, "publish_time_ns")
        )
        with self._lock:
            self._check_open()
            info = self._topics.get(topic)
            if info is None:
                raise BagError(f"topic {topic!r} was not added (call add_topic first)")
            writes = self._stream.writes
            self._mcap.add_message(
                channel_id=info.channel_id,
                log_time=log_time,
                data=data,
                publish_time=publish_time,
                sequence=int(sequence),
            )
            info.count += 1
            self._count += 1
            self._start_ns = log_time if self._start_ns is None else min(self._start_ns, log_time)
            self._end_ns = log_time if self._end_ns is None else max(self._end_ns, log_time)
            if self._interval is not None:
                if self._stream.writes != writes:
                    self._chunk_since = None  # the writer just closed a chunk by size
                elif self._chunk_since is None:
                    self._chunk_since = log_time
                elif log_time - self._chunk_since >= self._interval:
                    self._mcap.flush()
                    self._chunk_since = None

    def flush(self) -> None:
        """Close the chunk in progress (if any) and push everything to the OS now."""
        with self._lock:
            self._check_open()
            self._mcap.flush()
            self._chunk_since = None

    def finish(self) -> None:
        """Write the ``rosbag2`` metadata record and the summary, then close what was opened.

        Idempotent. A stream passed in is flushed, not closed.
        """
        with self._lock:
            if self._finished:
                return
            self._finished = True
            try:
                self._mcap.flush()
                self._mcap.add_metadata(
                    METADATA_NAME,
                    rosbag2_metadata_yaml(
                        self._topics,
                        message_count=self._count,
                        start_ns=self._start_ns,
                        end_ns=self._end_ns,
                        file_name=self.path.name if self.path is not None else "",
                        custom_data=self._custom_data,
                        ros_distro=self._ros_distro,
                    ),
                )
                self._mcap.finish()
                self._stream.flush()
            finally:
                if self._owned is not None:
                    self._owned.close()

    close = finish

    def _check_open(self) -> None:
        if self._finished:
            raise BagError("the bag writer is finished")


def _check_time(value: Any, name: str) -> int:
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise BagError(f"{name}: must be integer nanoseconds, got {type(value).__name__}")
    if not 0 <= value < 2**64:
        raise BagError(f"{name}: {value} is outside [0, 2**64) ns")
    return value
