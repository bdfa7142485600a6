"""ROS message types as a bag stores them: names, classes, schema text and type hashes.

rosbag2 stores one schema per type: name ``<pkg>/msg/<Type>``, encoding ``ros2msg``, data = the
full text of the type's ``.msg`` followed by its dependencies (:func:`message_definition`), and
each channel carries the type's ``RIHS01_...`` hash (:func:`type_description_hash`). Both are
read from the ``share/<pkg>/msg`` directory the message package installs.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import json
import os
import re
import sys
from pathlib import Path
from typing import Any

from apc_recording.bag.errors import BagError

__all__ = [
    "SCHEMA_ENCODING",
    "canonical_type_name",
    "get_message_class",
    "message_definition",
    "message_type_name",
    "type_description_hash",
]

#: Schema encoding of a ``.msg`` text with its dependencies.
SCHEMA_ENCODING = "ros2msg"
_DELIMITER = "=" * 80 + "\n"

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


def canonical_type_name(type_name: str | type) -> str:
    """``"pkg/msg/Type"`` of a type name (also ``"pkg/Type"``) or of a message class."""
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
    full = canonical_type_name(type_name)
    try:
        path = _interface_file(full, ".json")
        data = json.loads(path.read_text(encoding="utf-8"))
    except (BagError, OSError, ValueError):
        return ""
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return str(entry.get("hash_string", ""))
    return ""
