"""rosbag2-compatible MCAP recording and reading (no rclpy node code here).

Modules by job:

- :mod:`~apc_recording.bag.interfaces`: ROS type names and classes, the ``ros2msg`` schema text and
  the ``RIHS01`` type hash of a type, read from its installed ``.msg``/``.json`` files;
- :mod:`~apc_recording.bag.qos_yaml`: QoS profiles <-> rosbag2's ``offered_qos_profiles`` YAML;
- :mod:`~apc_recording.bag.writer`: :class:`BagWriter`, the file format and its crash safety;
- :mod:`~apc_recording.bag.metadata`: the ``rosbag2`` metadata record (rosbag2's ``BagMetadata``);
- :mod:`~apc_recording.bag.scan`: opening a source, and reading a file front to back even when a
  killed writer left it without summary and footer;
- :mod:`~apc_recording.bag.reader`: :func:`read_messages` and :func:`bag_info`;
- :mod:`~apc_recording.bag.recovery`: :func:`recover` and its command ``bag_recover``.

The names below are the package's API; the recorder, the player, the analysis and the tests
import them from here.
"""

from apc_recording.bag.errors import BagError, BagTruncatedWarning
from apc_recording.bag.interfaces import (
    get_message_class,
    message_definition,
    message_type_name,
    type_description_hash,
)
from apc_recording.bag.metadata import ROSBAG2_METADATA_VERSION
from apc_recording.bag.qos_yaml import qos_profiles_from_yaml, qos_profiles_to_yaml
from apc_recording.bag.reader import BagMessage, bag_info, read_messages
from apc_recording.bag.recovery import recover
from apc_recording.bag.writer import (
    DEFAULT_CHUNK_SIZE,
    LIBRARY,
    PROFILE,
    BagWriter,
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
    "get_message_class",
    "message_definition",
    "message_type_name",
    "qos_profiles_from_yaml",
    "qos_profiles_to_yaml",
    "read_messages",
    "recover",
    "type_description_hash",
]
