"""Fixtures of the feedback package's tests."""

from __future__ import annotations

import pytest

from apc_core.config_files import config_dir
from apc_core.robot import load_robot, with_inertia_error


@pytest.fixture(scope="module")
def controller_robot():
    """The controllers' 3-joint PUMA 560: 10 % inertia error on its links, alternating."""
    return with_inertia_error(load_robot(config_dir() / "puma560_3dof.urdf"), [0.1, -0.1, 0.1])
