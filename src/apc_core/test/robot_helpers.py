"""What the test_robot_* modules share: the PUMA URDFs and their DH reference table, the paper's
gravity, a standard-DH product written from ``config/reference/puma560.json`` alone, frame
poses, gravity torques, and body-by-body snapshots of a model's mass properties.

Not a test module: the test modules and ``conftest.py`` import it by name (pytest puts this
directory on ``sys.path``).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
from numpy.testing import assert_array_equal

from apc_core.config_files import config_dir
from apc_core.robot import Robot

CONFIG = config_dir()
URDF_3 = CONFIG / "puma560_3dof.urdf"
URDF_6 = CONFIG / "puma560.urdf"
REFERENCE = json.loads((CONFIG / "reference" / "puma560.json").read_text())
DH_ROWS = REFERENCE["joints"]
G = 9.8062  # m/s^2, the paper's gravity and the loader's default
D4 = 0.4318  # m, wrist centre along z3


def dh_transform(a: float, d: float, alpha: float, theta: float) -> np.ndarray:
    """Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha) as a 4x4 homogeneous matrix."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_frames(q: np.ndarray) -> list[np.ndarray]:
    """Base -> DH frame i (i = 1..len(q)) from the reference table."""
    out, T = [], np.eye(4)
    for row, qi in zip(DH_ROWS, q, strict=False):
        T = T @ dh_transform(row["a_m"], row["d_m"], row["alpha_rad"], qi)
        out.append(T)
    return out


def frame_pose(robot: Robot, q: np.ndarray, name: str) -> pin.SE3:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(name)].copy()


def frame_position(robot: Robot, q: np.ndarray, name: str) -> np.ndarray:
    return frame_pose(robot, q, name).translation.copy()


def gravity_torque(robot: Robot, q: np.ndarray) -> np.ndarray:
    """c(q): the torque that holds the arm still at q (N m)."""
    return pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q).copy()


def snapshot(model: pin.Model) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(mass, lever, rotational inertia) of every body, as copies."""
    return [(float(b.mass), b.lever.copy(), b.inertia.copy()) for b in model.inertias]


def assert_same_bodies(a: list, b: list) -> None:
    assert len(a) == len(b)
    for (ma, ca, ia), (mb, cb, ib) in zip(a, b, strict=True):
        assert ma == mb
        assert_array_equal(ca, cb)
        assert_array_equal(ia, ib)
