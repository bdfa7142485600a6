"""The PUMA models the test_robot_* modules load: 3-dof, 6-dof, and both in turn."""

from __future__ import annotations

import pytest
from robot_helpers import URDF_3, URDF_6

from apc_core.robot import Robot, load_robot


@pytest.fixture(scope="module")
def puma3() -> Robot:
    return load_robot(URDF_3)


@pytest.fixture(scope="module")
def puma6() -> Robot:
    return load_robot(URDF_6)


@pytest.fixture(params=["3dof", "6dof"])
def puma(request, puma3, puma6) -> Robot:
    return puma3 if request.param == "3dof" else puma6
