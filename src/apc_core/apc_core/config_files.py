"""Where apc's config files (URDFs, parameter files, the paper's reference numbers) are found.

In a ROS install they are in ``share/apc_core/config`` (found through the ament index); in a
source checkout in its ``config/``. No rclpy here.
"""

from __future__ import annotations

import os
from pathlib import Path

from apc_core.robot import EXAMPLE_ROBOT_DATA, example_robot_urdf

#: Where ``config/`` is in a source checkout (src/apc_core/apc_core/ -> repo root).
_REPO_CONFIG = Path(__file__).resolve().parents[3] / "config"


def config_dirs() -> list[Path]:
    """Directories searched for config files: the ROS share dir, then the source checkout's
    (each only if it exists)."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory("apc_core")) / "config")
    except Exception:  # no ament index (plain venv without AMENT_PREFIX_PATH)
        pass
    dirs.append(_REPO_CONFIG)
    return [d for d in dirs if d.is_dir()]


def config_dir() -> Path:
    """apc's config directory: the installed one in a ROS install, else the checkout's."""
    dirs = config_dirs()
    if not dirs:
        raise FileNotFoundError(
            "apc's config directory is neither installed (share/apc_core/config) nor in a "
            f"source checkout ({_REPO_CONFIG})"
        )
    return dirs[0]


def resolve_config_path(name: str) -> Path:
    """Find a config file by absolute path, path relative to the cwd, name in config dirs, or
    ``example-robot-data/<path under its robots/>`` (a URDF of that package)."""
    if name.startswith(EXAMPLE_ROBOT_DATA):
        try:
            return example_robot_urdf(name[len(EXAMPLE_ROBOT_DATA) :])
        except FileNotFoundError:
            return Path(name)
    path = Path(os.path.expanduser(name))
    if path.is_absolute() or path.exists():
        return path
    for base in config_dirs():
        candidate = base / name
        if candidate.exists():
            return candidate
        candidate = base / path.name
        if candidate.exists():
            return candidate
    return path
