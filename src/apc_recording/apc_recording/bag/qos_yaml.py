"""QoS profiles as rosbag2 stores them: the ``offered_qos_profiles`` YAML of a channel.

The recorder stores what each publisher offered; the player offers the same again, as
``ros2 bag record`` and ``ros2 bag play`` do.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import yaml
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from apc_recording.bag.errors import BagError

__all__ = ["qos_profiles_from_yaml", "qos_profiles_to_yaml"]

#: (sec, nsec) that older rosbag2 versions write for an infinite duration.
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
