"""rosbag2-compatible MCAP recording and reading (no rclpy node code here).

Files are written the way rosbag2's MCAP storage plugin (``rosbag2_storage_mcap``, Jazzy) writes
them, so they open in Foxglove, PlotJuggler, ``ros2 bag info/play`` and rosbags:

- header profile ``ros2``;
- one schema per message type: name ``<pkg>/msg/<Type>``, encoding ``ros2msg``, data = the full
  text of the type's ``.msg`` followed, for each dependency (depth first, sorted, each once), by
  ``"\\n" + "=" * 80 + "\\nMSG: <pkg>/<Type>\\n" + text`` (:func:`message_definition`);
- one channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles`` (rosbag2's
  version-9 QoS YAML, :func:`qos_profiles_to_yaml`) and ``topic_type_hash`` (``RIHS01_...`` from
  the type's ``.json`` description, :func:`type_description_hash`);
- message records with log time = receive (or sample) time and publish time, integer ns;
- at :meth:`BagWriter.finish`, a metadata record ``rosbag2`` whose ``serialized_metadata`` is the
  YAML of rosbag2's ``BagMetadata`` (version 9: duration, starting_time, message_count,
  topics_with_message_count, files, custom_data, ros_distro ...).

Chunks are compressed (zstd by default) and **written through to the OS as soon as each chunk is
complete**, so a recorder killed with SIGKILL loses at most the chunk in progress; the
readers here read such a truncated file (every message of every complete chunk), and
:func:`recover` rewrites it into a complete, indexed file.

Raw bytes, not ``serialize_message``
------------------------------------
``rclpy.serialization.serialize_message`` returns a buffer sized by an *estimate*, which is exact
for full ``JointState``, set point, estimate, ``Clock`` and ``DiagnosticArray`` messages but
longer than the CDR for messages with empty numeric sequences: 4 bytes per empty ``float64[]``
(8 for a torque ``JointState``, whose ``position`` and ``velocity`` are empty; 44 for a
three-point goal with positions only), 3 for ``std_msgs/Empty``. rosbags rejects a message with
4 or more trailing bytes. A subscription created with ``raw=True`` hands over the
exact bytes that were on the wire (what rosbag2 records), so the recorder passes those to
:meth:`BagWriter.write`. :meth:`BagWriter.write_message` (for code that holds a message object,
e.g. an offline run) serialises with :func:`serialize_exact`, which trims the buffer to the size
the CDR rules give (:func:`cdr_size`); that size is checked against raw subscription bytes in the
tests. Padding *inside* a message (alignment gaps) is not zeroed by either path, so two
recordings of the same run can differ in those bytes but never in any decoded value.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import importlib.util
import io
import json
import os
import re
import struct
import sys
import threading
import warnings
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap.writer import __version__ as mcap_version
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser.definition import (
    AbstractSequence,
    AbstractString,
    AbstractWString,
    Array,
    BasicType,
    NamespacedType,
)

__all__ = [
    "DEFAULT_CHUNK_SIZE",
    "LIBRARY",
    "PROFILE",
    "ROSBAG2_METADATA_VERSION",
    "BagError",
    "BagMessage",
    "BagTruncatedWarning",
    "BagWriter",
    "bag_info",
    "cdr_size",
    "get_message_class",
    "message_definition",
    "message_type_name",
    "qos_profiles_from_yaml",
    "qos_profiles_to_yaml",
    "read_messages",
    "recover",
    "serialize_exact",
    "type_description_hash",
    "write_metadata_yaml",
]

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
ROSBAG2_METADATA_VERSION = 9
#: Header ``library`` field: this writer, then the MCAP library it drives (rosbag2 writes
#: ``libmcap <version>``).
LIBRARY = f"apc_core.bag 0.1.0; mcap-python {mcap_version}"
#: Uncompressed bytes per chunk (rosbag2's default too). At apc's ~200 kB/s this is ~5 s of a run;
#: pass ``max_chunk_interval_ns`` to bound the loss on a crash in time as well.
DEFAULT_CHUNK_SIZE = 1024 * 1024

_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_TAIL = 1 + 8 + 20 + len(_MAGIC)  # opcode, length, footer body, magic
_DELIMITER = "=" * 80 + "\n"
_RECORD_LIMIT = 4 * 2**30
_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
    None: CompressionType.NONE,
}


class BagError(Exception):
    """A bag cannot be written or read as asked; the message says what and where."""


class BagTruncatedWarning(UserWarning):
    """A bag ends without its footer (the writer was killed); only complete chunks were read."""


# ----------------------------------------------------------------------------------------------
# Message types
# ----------------------------------------------------------------------------------------------
_TYPE_RE = re.compile(
    r"^([a-zA-Z][a-zA-Z0-9_]*)/(?:([a-zA-Z][a-zA-Z0-9_]*)/)?([a-zA-Z][a-zA-Z0-9_]*)$"
)


def _split_type_name(type_name: str) -> tuple[str, str, str]:
    """``"pkg/msg/Type"`` or ``"pkg/Type"`` -> ``(pkg, "msg", Type)``."""
    match = _TYPE_RE.match(type_name) if isinstance(type_name, str) else None
    if match is None:
        raise BagError(f"type name {type_name!r} is not of the form 'pkg/msg/Type'")
    pkg, interface, name = match.groups()
    return pkg, interface or "msg", name


def _canonical(type_name: str | type) -> str:
    if isinstance(type_name, type):
        return message_type_name(type_name)
    pkg, interface, name = _split_type_name(type_name)
    return f"{pkg}/{interface}/{name}"


@functools.cache
def get_message_class(type_name: str) -> type:
    """Import the rclpy message class of ``type_name``.

    Parameters
    ----------
    type_name : str
        ``"sensor_msgs/msg/JointState"`` (or ``"sensor_msgs/JointState"``).

    Raises
    ------
    BagError
        If the name is malformed or no such Python message class is installed.
    """
    pkg, interface, name = _split_type_name(type_name)
    try:
        module = importlib.import_module(f"{pkg}.{interface}")
        cls = getattr(module, name)
    except (ImportError, AttributeError) as err:
        raise BagError(f"message type {type_name!r} is not installed: {err}") from None
    return cls


def message_type_name(msg_or_class: Any) -> str:
    """ROS type name of a message or message class, e.g. ``"sensor_msgs/msg/JointState"``.

    Raises
    ------
    BagError
        If the argument is not a rosidl-generated message (class).
    """
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    parts = cls.__module__.split(".")
    if not hasattr(cls, "get_fields_and_field_types") or len(parts) < 2:
        raise BagError(f"{cls.__module__}.{cls.__name__} is not a ROS message class")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


# ----------------------------------------------------------------------------------------------
# Message definitions and type hashes (read from share/<pkg>/msg)
# ----------------------------------------------------------------------------------------------
@functools.cache
def _share_dirs(pkg: str) -> tuple[Path, ...]:
    """Candidate ``share/<pkg>`` directories, best first.

    1. the ament index (``AMENT_PREFIX_PATH``), as rosbag2 does;
    2. the install prefix of the package's Python module: walking up from
       ``<prefix>/lib/pythonX.Y/site-packages/<pkg>`` to ``<prefix>/share/<pkg>`` finds the venv
       of the PyPI wheels, ``/opt/ros/<distro>`` and a colcon ``install/<pkg>`` alike;
    3. ``sys.prefix/share`` and ``$VIRTUAL_ENV/share``.
    """
    candidates: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory(pkg)))
    except (ImportError, LookupError, OSError, ValueError):
        pass  # no AMENT_PREFIX_PATH (the wheels do not set it) or package not indexed
    try:
        spec = importlib.util.find_spec(pkg)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        for parent in list(Path(spec.origin).resolve().parents)[:6]:
            candidates.append(parent / "share" / pkg)
    for prefix in (sys.prefix, os.environ.get("VIRTUAL_ENV")):
        if prefix:
            candidates.append(Path(prefix) / "share" / pkg)
    seen: list[Path] = []
    for c in candidates:
        if c.is_dir() and c not in seen:
            seen.append(c)
    return tuple(seen)


def _interface_file(type_name: str, suffix: str) -> Path:
    pkg, interface, name = _split_type_name(type_name)
    dirs = _share_dirs(pkg)
    for share in dirs:
        path = share / interface / f"{name}{suffix}"
        if path.is_file():
            return path
    raise BagError(
        f"no {interface}/{name}{suffix} for {type_name!r} in any share directory of {pkg!r} "
        f"(looked in {[str(d) for d in dirs] or 'none found'}; set AMENT_PREFIX_PATH?)"
    )


# Exactly rosbag2's rules (rosbag2_cpp local_message_definition_source.cpp).
_MSG_FIELD_TYPE_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "string",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
    }
)


def _msg_dependencies(text: str, package: str) -> list[str]:
    deps = set()
    for match in _MSG_FIELD_TYPE_RE.finditer(text):
        typ = match.group(1)
        if typ in _PRIMITIVES:
            continue
        deps.add(typ if "/" in typ else f"{package}/{typ}")
    return sorted(deps)


@functools.cache
def _msg_text(type_name: str) -> str:
    return _interface_file(type_name, ".msg").read_bytes().decode("utf-8")


@functools.cache
def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of a type, exactly as rosbag2 builds it.

    The type's ``.msg`` text, then for each dependency -- the field types named in the text,
    sorted, visited depth first, each once -- ``"\\n" + "=" * 80 + "\\nMSG: <pkg>/<Type>\\n"``
    and its text (followed by its own dependencies). Builtin types such as
    ``builtin_interfaces/Time`` are dependencies like any other.

    Parameters
    ----------
    type_name : str
        ``"sensor_msgs/msg/JointState"`` or ``"sensor_msgs/JointState"``.

    Raises
    ------
    BagError
        If a ``.msg`` file of the type or of a dependency cannot be found.
    """
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise BagError(f"max recursion depth reached resolving {type_name!r}")
        text = _msg_text(name)
        pkg = _split_type_name(name)[0]
        for dep in _msg_dependencies(text, pkg):
            if dep not in seen:
                seen.add(dep)
                text += "\n" + _DELIMITER + "MSG: " + dep + "\n" + append(dep, depth - 1)
        return text

    return append(type_name, 50)


@functools.cache
def type_description_hash(type_name: str) -> str:
    """The ``RIHS01_...`` type hash of a type, from its ``share/<pkg>/msg/<Type>.json``.

    Returns ``""`` if the description file is missing (what rosbag2 stores when it does not
    know the hash).
    """
    full = _canonical(type_name)
    try:
        path = _interface_file(full, ".json")
        data = json.loads(path.read_text(encoding="utf-8"))
    except (BagError, OSError, ValueError):
        return ""
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return str(entry.get("hash_string", ""))
    return ""


# ----------------------------------------------------------------------------------------------
# Exact CDR serialisation
# ----------------------------------------------------------------------------------------------
_PRIMITIVE_SIZE = {
    "boolean": 1,
    "octet": 1,
    "char": 1,
    "int8": 1,
    "uint8": 1,
    "int16": 2,
    "uint16": 2,
    "int32": 4,
    "uint32": 4,
    "int64": 8,
    "uint64": 8,
    "float": 4,
    "double": 8,
}


@functools.cache
def _fields(cls: type) -> tuple[tuple[str, Any], ...]:
    return tuple(zip(cls.get_fields_and_field_types().keys(), cls.SLOT_TYPES, strict=True))


def _align(offset: int, size: int) -> int:
    return (offset + size - 1) & ~(size - 1)


def _primitive_size(typ: BasicType) -> int:
    try:
        return _PRIMITIVE_SIZE[typ.typename]
    except KeyError:
        raise BagError(f"cannot size CDR primitive {typ.typename!r}") from None


def _struct_end(msg: Any, offset: int) -> int:
    fields = _fields(type(msg))
    if not fields:
        return offset + 1  # an empty struct carries one uint8 (structure_needs_at_least_one_member)
    for name, typ in fields:
        offset = _value_end(getattr(msg, name), typ, offset)
    return offset


def _value_end(value: Any, typ: Any, offset: int) -> int:
    if isinstance(typ, BasicType):
        size = _primitive_size(typ)
        return _align(offset, size) + size
    if isinstance(typ, AbstractString):
        return _align(offset, 4) + 4 + len(value.encode("utf-8")) + 1
    if isinstance(typ, NamespacedType):
        return _struct_end(value, offset)
    if isinstance(typ, AbstractSequence):
        return _elements_end(value, typ.value_type, _align(offset, 4) + 4)
    if isinstance(typ, Array):
        return _elements_end(value, typ.value_type, offset)
    if isinstance(typ, AbstractWString):
        raise BagError("wstring fields are not supported by cdr_size")
    raise BagError(f"cannot size field type {type(typ).__name__}")


def _elements_end(values: Any, typ: Any, offset: int) -> int:
    if isinstance(typ, BasicType):
        count = len(values)
        if count == 0:
            return offset  # an empty sequence is not aligned (checked against rmw_fastrtps)
        size = _primitive_size(typ)
        return _align(offset, size) + count * size
    for value in values:
        offset = _value_end(value, typ, offset)
    return offset


def cdr_size(msg: Any) -> int:
    """Exact size in bytes of the CDR serialisation of ``msg`` (4-byte encapsulation included).

    Plain little-endian CDR as ``rmw_fastrtps`` writes it for ROS 2: primitives aligned to their
    size relative to the end of the encapsulation header, strings and sequences prefixed by a
    ``uint32`` length, an empty sequence not aligned, an empty struct one byte.

    Raises
    ------
    BagError
        For ``wstring`` fields and ``long double``, which apc never sends.
    """
    return 4 + _struct_end(msg, 0)


def serialize_exact(msg: Any) -> bytes:
    """``serialize_message(msg)`` trimmed to :func:`cdr_size` -- the bytes a subscriber receives.

    ``serialize_message`` sizes its buffer by an estimate that can exceed the CDR by a few bytes
    (see the module docstring); everything up to the CDR size is the real serialisation, so
    trimming gives the same bytes a ``raw=True`` subscription delivers.
    """
    buffer = serialize_message(msg)
    size = cdr_size(msg)
    if size > len(buffer):
        raise BagError(
            f"{message_type_name(msg)}: computed CDR size {size} exceeds the serialized "
            f"buffer ({len(buffer)} bytes); cdr_size does not know this type"
        )
    return bytes(buffer[:size])


# ----------------------------------------------------------------------------------------------
# QoS <-> rosbag2 YAML
# ----------------------------------------------------------------------------------------------
_LEGACY_INFINITE = {(0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF)}


def _duration_dict(duration: Duration) -> dict[str, int]:
    sec, nsec = divmod(int(duration.nanoseconds), 10**9)
    return {"sec": sec, "nsec": nsec}


def _qos_dict(qos: QoSProfile) -> dict[str, Any]:
    return {
        "history": HistoryPolicy(qos.history).name.lower(),
        "depth": int(qos.depth),
        "reliability": ReliabilityPolicy(qos.reliability).name.lower(),
        "durability": DurabilityPolicy(qos.durability).name.lower(),
        "deadline": _duration_dict(qos.deadline),
        "lifespan": _duration_dict(qos.lifespan),
        "liveliness": LivelinessPolicy(qos.liveliness).name.lower(),
        "liveliness_lease_duration": _duration_dict(qos.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def qos_profiles_to_yaml(profiles: Iterable[QoSProfile]) -> str:
    """rosbag2's ``offered_qos_profiles`` text (metadata version 9) for a list of profiles.

    One entry per publisher: ``history`` / ``reliability`` / ``durability`` / ``liveliness`` as
    lower-case names (``keep_last``, ``reliable``, ``volatile``, ``automatic``), ``depth``, and the
    durations ``deadline``, ``lifespan``, ``liveliness_lease_duration`` as ``{sec, nsec}``
    (``0, 0`` = unspecified, i.e. the default). An empty list gives ``"[]"``.
    """
    dicts = [_qos_dict(p) for p in profiles]
    if not dicts:
        return "[]"
    return yaml.safe_dump(dicts, sort_keys=False, default_flow_style=False).rstrip("\n")


def _policy(enum: Any, value: Any) -> Any:
    if isinstance(value, int):
        return enum(value)
    try:
        return enum[str(value).upper()]
    except KeyError:
        return enum.UNKNOWN


def _duration(value: Mapping[str, int] | None) -> Duration:
    if not value:
        return Duration()
    sec, nsec = int(value.get("sec", 0)), int(value.get("nsec", 0))
    if (sec, nsec) in _LEGACY_INFINITE or sec * 10**9 + nsec >= 2**63:
        return Duration()  # infinite == unspecified for deadline, lifespan and lease
    return Duration(seconds=sec, nanoseconds=nsec)


def qos_profiles_from_yaml(text: str) -> list[QoSProfile]:
    """Parse an ``offered_qos_profiles`` text (metadata version 8 or 9) into QoS profiles.

    The player uses it to offer what the recorded publishers offered, as ``ros2 bag play`` does.

    Raises
    ------
    BagError
        If the text is not a YAML list of profiles.
    """
    try:
        items = yaml.safe_load(text) if text else []
    except yaml.YAMLError as err:
        raise BagError(f"offered_qos_profiles: not YAML ({err})") from None
    if items is None:
        items = []
    if not isinstance(items, list):
        raise BagError(f"offered_qos_profiles: expected a list, got {type(items).__name__}")
    profiles = []
    for item in items:
        history = _policy(HistoryPolicy, item.get("history", "keep_last"))
        profiles.append(
            QoSProfile(
                history=history,
                depth=int(item.get("depth", 0)) or 1,
                reliability=_policy(ReliabilityPolicy, item.get("reliability", "reliable")),
                durability=_policy(DurabilityPolicy, item.get("durability", "volatile")),
                deadline=_duration(item.get("deadline")),
                lifespan=_duration(item.get("lifespan")),
                liveliness=_policy(LivelinessPolicy, item.get("liveliness", "automatic")),
                liveliness_lease_duration=_duration(item.get("liveliness_lease_duration")),
                avoid_ros_namespace_conventions=bool(
                    item.get("avoid_ros_namespace_conventions", False)
                ),
            )
        )
    return profiles


# ----------------------------------------------------------------------------------------------
# Writer
# ----------------------------------------------------------------------------------------------
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


@dataclass
class _Topic:
    channel_id: int
    type_name: str
    qos_yaml: str
    type_hash: str
    count: int = 0


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
        self._topics: dict[str, _Topic] = {}
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
        name = _canonical(type_name)
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
            schema = b"" if name in self._schema_ids else message_definition(name).encode()
            return self._add_channel(topic, name, SCHEMA_ENCODING, schema, qos_yaml, type_hash)

    def _add_channel(
        self,
        topic: str,
        type_name: str,
        schema_encoding: str,
        schema_data: bytes,
        qos_yaml: str,
        type_hash: str,
    ) -> int:
        """Register the schema (once per type) and the channel; the caller holds the lock."""
        schema_id = self._schema_ids.get(type_name)
        if schema_id is None:
            schema_id = self._mcap.register_schema(
                name=type_name, encoding=schema_encoding, data=schema_data
            )
            self._schema_ids[type_name] = schema_id
        channel_id = self._mcap.register_channel(
            topic=topic,
            message_encoding=MESSAGE_ENCODING,
            schema_id=schema_id,
            metadata={"offered_qos_profiles": qos_yaml, "topic_type_hash": type_hash},
        )
        self._topics[topic] = _Topic(channel_id, type_name, qos_yaml, type_hash)
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

    def write_message(
        self,
        topic: str,
        msg: Any,
        log_time_ns: int,
        publish_time_ns: int | None = None,
    ) -> None:
        """Serialise ``msg`` with :func:`serialize_exact` and write it.

        The topic is added (with no QoS information) if it was not. For recording live traffic
        use :meth:`write` with the bytes of a ``raw=True`` subscription instead: they are what
        was on the wire and cost no serialisation.

        Raises
        ------
        BagError
            As :meth:`write`, or if ``msg``'s type differs from the topic's.
        """
        name = message_type_name(msg)
        if topic not in self._topics:
            self.add_topic(topic, name)
        elif self._topics[topic].type_name != name:
            raise BagError(
                f"topic {topic!r} has type {self._topics[topic].type_name!r}, got a {name!r}"
            )
        self.write(topic, serialize_exact(msg), log_time_ns, publish_time_ns)

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
                self._mcap.add_metadata("rosbag2", {"serialized_metadata": self._metadata_yaml()})
                self._mcap.finish()
                self._stream.flush()
            finally:
                if self._owned is not None:
                    self._owned.close()

    close = finish

    def _check_open(self) -> None:
        if self._finished:
            raise BagError("the bag writer is finished")

    def _metadata_yaml(self) -> str:
        start = self._start_ns if self._start_ns is not None else 0
        duration = (self._end_ns - start) if self._end_ns is not None else 0
        file_name = self.path.name if self.path is not None else ""
        topics = []
        for name, info in self._topics.items():
            try:
                qos = yaml.safe_load(info.qos_yaml) if info.qos_yaml else []
            except yaml.YAMLError:
                qos = info.qos_yaml
            topics.append(
                {
                    "topic_metadata": {
                        "name": name,
                        "type": info.type_name,
                        "serialization_format": MESSAGE_ENCODING,
                        "offered_qos_profiles": qos if qos is not None else [],
                        "type_description_hash": info.type_hash,
                    },
                    "message_count": info.count,
                }
            )
        document = {
            "version": ROSBAG2_METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self._count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [file_name],
            "files": [
                {
                    "path": file_name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": self._count,
                }
            ],
            "custom_data": dict(self._custom_data),
            "ros_distro": self._ros_distro,
        }
        return yaml.safe_dump(document, sort_keys=False, default_flow_style=False)


def _check_time(value: Any, name: str) -> int:
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise BagError(f"{name}: must be integer nanoseconds, got {type(value).__name__}")
    if not 0 <= value < 2**64:
        raise BagError(f"{name}: {value} is outside [0, 2**64) ns")
    return value


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------
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


@contextlib.contextmanager
def _opened(source: str | bytes | os.PathLike | IO[bytes]) -> Iterator[IO[bytes]]:
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


def _is_complete(stream: IO[bytes]) -> bool:
    """True if a seekable stream ends with an MCAP footer and the closing magic."""
    if not stream.seekable():
        return False
    size = stream.seek(0, io.SEEK_END)
    ok = False
    if size >= len(_MAGIC) * 2 + _FOOTER_TAIL:
        stream.seek(size - _FOOTER_TAIL)
        tail = stream.read(_FOOTER_TAIL)
        ok = (
            tail[-len(_MAGIC) :] == _MAGIC
            and tail[0] == Opcode.FOOTER
            and struct.unpack_from("<Q", tail, 1)[0] == 20
        )
    stream.seek(0)
    return ok


class _Scan:
    """State of a linear scan: what was found, and whether the file was complete."""

    def __init__(self) -> None:
        self.header: Header | None = None
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.metadata: list[Metadata] = []
        self.complete = False
        self.problem = ""


def _read_exact(stream: IO[bytes], size: int) -> bytes:
    """Read ``size`` bytes, or fewer only at the end of the stream (raw streams read short)."""
    data = stream.read(size)
    if data is None or len(data) == size or not data:
        return data or b""
    parts = [data]
    got = len(data)
    while got < size:
        more = stream.read(size - got)
        if not more:
            break
        parts.append(more)
        got += len(more)
    return b"".join(parts)


def _scan(stream: IO[bytes], state: _Scan) -> Iterator[Message]:
    """Read records in file order, yielding messages; stop quietly at a truncated record.

    Unlike mcap's stream reader this checks each record's full length before parsing it and
    validates chunk CRCs, so a file cut anywhere (a killed recorder) yields exactly the
    messages of its complete chunks.
    """
    remaining: int | None = None
    if stream.seekable():
        here = stream.tell()
        remaining = stream.seek(0, io.SEEK_END) - here
        stream.seek(here)
    if _read_exact(stream, len(_MAGIC)) != _MAGIC:
        raise BagError("not an MCAP file (bad magic)")
    if remaining is not None:
        remaining -= len(_MAGIC)
    while True:
        head = _read_exact(stream, 9)
        if len(head) < 9:
            state.problem = "file ends without a footer"
            return
        opcode, length = struct.unpack("<BQ", head)
        if remaining is not None:
            remaining -= 9
            if length > remaining:
                state.problem = f"record {opcode:#04x} at the end is cut short"
                return
            remaining -= length
        elif length > _RECORD_LIMIT:
            state.problem = f"record {opcode:#04x} claims {length} bytes"
            return
        body = _read_exact(stream, length)
        if len(body) < length:
            state.problem = f"record {opcode:#04x} at the end is cut short"
            return
        rs = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == Opcode.FOOTER:
                state.complete = True
                return
            if opcode == Opcode.HEADER:
                state.header = Header.read(rs)
            elif opcode == Opcode.SCHEMA:
                schema = Schema.read(rs)
                state.schemas[schema.id] = schema
            elif opcode == Opcode.CHANNEL:
                channel = Channel.read(rs)
                state.channels[channel.id] = channel
            elif opcode == Opcode.MESSAGE:
                yield Message.read(rs, length)
            elif opcode == Opcode.METADATA:
                state.metadata.append(Metadata.read(rs))
            elif opcode == Opcode.CHUNK:
                records = breakup_chunk(Chunk.read(rs), validate_crc=True)
                for record in records:
                    if isinstance(record, Schema):
                        state.schemas[record.id] = record
                    elif isinstance(record, Channel):
                        state.channels[record.id] = record
                    elif isinstance(record, Message):
                        yield record
        except (McapError, ValueError, struct.error, EOFError) as err:
            state.problem = f"record {opcode:#04x} is corrupt ({err})"
            return


def _describe(source: Any) -> str:
    if isinstance(source, (str, bytes, os.PathLike)):
        return os.fsdecode(source)
    return str(getattr(source, "name", type(source).__name__))


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
    source: str | bytes | os.PathLike | IO[bytes],
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
    with _opened(source) as stream:
        if _is_complete(stream):
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
                raise BagError(f"{_describe(source)}: {err}") from None
        state = _Scan()
        selected: list[BagMessage] = []
        for message in _scan(stream, state):
            channel = state.channels.get(message.channel_id)
            if channel is None:
                continue
            if wanted is not None and channel.topic not in wanted:
                continue
            if start_ns is not None and message.log_time < start_ns:
                continue
            if end_ns is not None and message.log_time >= end_ns:
                continue
            item = _bag_message(state.schemas.get(channel.schema_id), channel, message)
            if log_time_order:
                selected.append(item)
            else:
                yield item
        if not state.complete:
            warnings.warn(
                f"{_describe(source)}: {state.problem}; read the messages of the complete chunks",
                BagTruncatedWarning,
                stacklevel=2,
            )
        if log_time_order:
            selected.sort(key=lambda m: m.log_time_ns)
            yield from selected


def _rosbag2_metadata(records: Iterable[Metadata]) -> dict | None:
    for record in records:
        if record.name == "rosbag2" and "serialized_metadata" in record.metadata:
            try:
                return yaml.safe_load(record.metadata["serialized_metadata"])
            except yaml.YAMLError:
                return None
    return None


def bag_info(source: str | bytes | os.PathLike | IO[bytes]) -> dict[str, Any]:
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
    with _opened(source) as stream:
        if _is_complete(stream):
            try:
                reader = SeekingReader(stream)
                header = reader.get_header()
                summary = reader.get_summary()
                metadata = list(reader.iter_metadata())
            except McapError as err:
                raise BagError(f"{_describe(source)}: {err}") from None
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
        state = _Scan()
        counts: dict[int, int] = {}
        first = last = None
        total = 0
        for message in _scan(stream, state):
            counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
            total += 1
            first = message.log_time if first is None else min(first, message.log_time)
            last = message.log_time if last is None else max(last, message.log_time)
        return _info(
            state.header,
            state.schemas,
            state.channels,
            counts,
            total,
            first,
            last,
            state.complete,
            state.metadata,
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
        "rosbag2_metadata": _rosbag2_metadata(metadata),
    }


def recover(
    source: str | bytes | os.PathLike | IO[bytes],
    destination: str | os.PathLike | IO[bytes],
    *,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    compression: str | None = "zstd",
) -> int:
    """Rewrite a (possibly truncated) bag into a complete, indexed one.

    Every message of every complete chunk is copied in file order, with its channel's schema
    text, ``offered_qos_profiles`` and type hash as recorded; the new file gets a summary and a
    ``rosbag2`` metadata record, so every tool opens it quickly.

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
    with _opened(source) as stream, warnings.catch_warnings():
        warnings.simplefilter("ignore", BagTruncatedWarning)
        state = _Scan()
        with BagWriter(destination, chunk_size=chunk_size, compression=compression) as out:
            for message in _scan(stream, state):
                channel = state.channels.get(message.channel_id)
                if channel is None:
                    continue
                if channel.topic not in out.topics:
                    schema = state.schemas.get(channel.schema_id)
                    if schema is None:
                        continue
                    with out._lock:  # copy the recorded schema and channel metadata verbatim
                        out._add_channel(
                            channel.topic,
                            schema.name,
                            schema.encoding,
                            schema.data,
                            channel.metadata.get("offered_qos_profiles", "[]"),
                            channel.metadata.get("topic_type_hash", ""),
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


def write_metadata_yaml(bag_path: str | os.PathLike) -> Path:
    """Write ``metadata.yaml`` beside a finished ``.mcap``, making its directory a rosbag2 bag.

    ``ros2 bag`` and rosbags read a bare ``.mcap`` file; some tools (and ``ros2 bag`` given a
    directory) want the directory layout ``<dir>/metadata.yaml`` + ``<dir>/<name>.mcap``. The
    content is the file's ``rosbag2`` metadata record under ``rosbag2_bagfile_information``.

    Returns
    -------
    pathlib.Path
        The ``metadata.yaml`` written.

    Raises
    ------
    BagError
        If the bag has no ``rosbag2`` metadata record (e.g. it was truncated: :func:`recover` it).
    """
    bag_path = Path(bag_path)
    info = bag_info(bag_path)
    metadata = info["rosbag2_metadata"]
    if not metadata:
        raise BagError(f"{bag_path}: no rosbag2 metadata record (truncated? use recover())")
    metadata = dict(metadata)
    metadata["relative_file_paths"] = [bag_path.name]
    for entry in metadata.get("files") or []:
        entry["path"] = bag_path.name
    target = bag_path.parent / "metadata.yaml"
    text = yaml.safe_dump(
        {"rosbag2_bagfile_information": metadata}, sort_keys=False, default_flow_style=False
    )
    target.write_text(text, encoding="utf-8")
    return target
