"""What a run is: arm, payload, model error, move, timing and controller, and how to build it.

A :class:`Scenario` is plain data (loadable from YAML or argparse); :func:`build` turns it into
the plant's robot, the controller's robot and the plan (the feedback law by name is
:func:`apc_feedback.laws.make_law`). The paper's three cases are :func:`paper_scenario`.

Angles
------
All joint angles in apc are the URDF's, which for the PUMA are the standard-DH angles of
``config/reference/puma560.json``. The paper's angles (Lee's PUMA convention) map onto them as
``(q1, -q2, -q3)``: the paper's start (0, 45, 45) deg is (0, -45, -45) deg here, its end
(90, -45, 135) deg is (90, 45, -135) deg, and its stretched pose (45, 0, 90) deg at 0.5 s is
(45, 0, -90) deg, where upper arm and forearm are in line (checked in ``test/test_robot.py``).
``PAPER_JOINT_SIGN`` converts errors to the paper's sign convention for plots.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from apc_core.config_files import config_dir
from apc_core.defaults import load as load_defaults
from apc_core.robot import (
    PAPER_GOAL_DEG,
    PAPER_GRAVITY_M_S2,
    PAPER_MAX_PAYLOAD_KG,
    PAPER_START_DEG,
    Payload,
    Robot,
    load_robot,
    with_inertia_error,
    with_payload,
)
from apc_feedback.laws import make_law
from apc_feedback.presets import (  # noqa: F401  (re-exported: the runs name them from here)
    PRESETS,
    paper_settings,
    physical_settings,
    recommended_settings,
)
from apc_feedforward.four_three_four import LIFT_OFF, SEGMENT_TIMES, SET_DOWN, FourThreeFour
from apc_feedforward.nominal import Feedforward
from apc_lab.offline import RunResult, run_closed_loop
from apc_plant_sim.effects import ArmEffects, PhysicalArm
from apc_plant_sim.plant import Plant, PlantConfig

#: apc's config directory: ``share/apc_core/config`` in a ROS install, else the checkout's.
CONFIG_DIR = config_dir()
PUMA_3DOF_URDF = CONFIG_DIR / "puma560_3dof.urdf"
PAPER_JOINT_SIGN = np.array([1.0, -1.0, -1.0])
PAPER_CASES = {"a": 0.0, "b": PAPER_MAX_PAYLOAD_KG / 2.0, "c": PAPER_MAX_PAYLOAD_KG}


class ScenarioError(ValueError):
    """A bad scenario value; the message names the field."""


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one run except the feedback law's own settings.

    Attributes
    ----------
    urdf : str
        Path to the arm's URDF.
    payload_kg : float
        Payload mass on the plant only (the controllers do not know it).
    payload_frame : str or None
        Frame carrying the payload (``None``: body of the last joint).
    payload_com_m : 3 floats
        Payload centre of mass in ``payload_frame`` (m).
    payload_at_s : float
        Time the payload appears on the plant (picked up mid-motion); 0 = from the start.
    inertia_error : n floats
        Relative error of the controller's link inertia tensors (paper: +-10 %).
    q_start_deg, q_goal_deg : n floats
        The move, in URDF angles (deg).
    segment_times : 3 floats
        4-3-4 segment durations (s).
    lift_off, set_down : float
        4-3-4 via points as fractions of each joint's travel.
    period, step : float
        Sampling period T and RK4 step h (s).
    hold_s : float
        Time simulated after the move ends (s).
    gravity : float
        m/s^2.
    """

    urdf: str = str(PUMA_3DOF_URDF)
    payload_kg: float = 0.0
    payload_frame: str | None = "wrist_center"
    payload_com_m: tuple[float, ...] = (0.0, 0.0, 0.0)
    payload_at_s: float = 0.0
    inertia_error: tuple[float, ...] = (0.1, -0.1, 0.1)
    q_start_deg: tuple[float, ...] = PAPER_START_DEG
    q_goal_deg: tuple[float, ...] = PAPER_GOAL_DEG
    segment_times: tuple[float, ...] = SEGMENT_TIMES
    lift_off: float = LIFT_OFF
    set_down: float = SET_DOWN
    period: float = PlantConfig.period
    step: float = PlantConfig.step
    hold_s: float = 0.5
    gravity: float = PAPER_GRAVITY_M_S2
    lock_joints: tuple[str, ...] = field(default_factory=tuple)

    @staticmethod
    def from_dict(
        values: Mapping[str, Any], report: Callable[[str], None] | None = None
    ) -> Scenario:
        """Build from a mapping (YAML); unknown keys are rejected with their name. A mapping
        that names its ``urdf`` gets the per-joint fields it leaves out from that URDF
        (:func:`for_urdf`), each told to ``report``."""
        known = {f.name for f in fields(Scenario)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ScenarioError(f"unknown scenario key {unknown[0]!r}")
        clean = {}
        for key, value in values.items():
            clean[key] = tuple(value) if isinstance(value, list) else value
        if "urdf" in clean:
            return for_urdf(clean.pop("urdf"), report, **clean)
        return Scenario(**clean)

    @property
    def duration(self) -> float:
        return float(sum(self.segment_times))

    @property
    def n_samples(self) -> int:
        """Periods simulated: the move plus the hold."""
        return round((self.duration + self.hold_s) / self.period)

    @property
    def move_end_sample(self) -> int:
        return round(self.duration / self.period)

    def move(self) -> FourThreeFour:
        """The planned 4-3-4 move."""
        return FourThreeFour(
            np.deg2rad(self.q_start_deg),
            np.deg2rad(self.q_goal_deg),
            segment_times=tuple(self.segment_times),
            lift_off=self.lift_off,
            set_down=self.set_down,
        )


#: Scenario fields with one value per joint, or naming a link of the arm: the paper's for its
#: 3-joint PUMA; derived from the URDF (:mod:`apc_core.defaults`) for any other arm.
PER_JOINT_FIELDS = ("q_start_deg", "q_goal_deg", "inertia_error", "payload_frame")


def for_urdf(
    urdf: str | Path, report: Callable[[str], None] | None = None, **values: Any
) -> Scenario:
    """A scenario on the arm of ``urdf``: ``values`` as given (Scenario fields), and each of
    :data:`PER_JOINT_FIELDS` not given derived from the URDF, told to ``report`` in one line."""
    _, defaults = load_defaults(
        urdf,
        gravity=values.get("gravity", PAPER_GRAVITY_M_S2),
        lock_joints=tuple(values.get("lock_joints", ())),
    )
    for name in PER_JOINT_FIELDS:
        if name not in values:
            values[name] = getattr(defaults, name)
            if report is not None:
                report(defaults.describe(name))
    return Scenario(urdf=str(urdf), **values)


def paper_scenario(case: str, **overrides: Any) -> Scenario:
    """The paper's experiment, case ``a`` (no load), ``b`` (half of 5 lb) or ``c`` (5 lb)."""
    if case not in PAPER_CASES:
        raise ScenarioError(f"case must be one of {sorted(PAPER_CASES)}, got {case!r}")
    return Scenario(payload_kg=PAPER_CASES[case], **overrides)


@dataclass(frozen=True)
class Built:
    """The objects a run needs."""

    plant_robot: Robot
    controller_robot: Robot
    unloaded_robot: Robot
    trajectory: FourThreeFour
    plant_config: PlantConfig


def build(scenario: Scenario) -> Built:
    """Load the URDF once and derive the plant's and the controller's robots and the plan."""
    robot = load_robot(scenario.urdf, gravity=scenario.gravity, lock_joints=scenario.lock_joints)
    n = robot.n_joints
    for name in ("inertia_error", "q_start_deg", "q_goal_deg"):
        if len(getattr(scenario, name)) != n:
            raise ScenarioError(f"{name} needs {n} values for {robot.source}")
    plant_robot = with_payload(
        robot,
        Payload(
            mass_kg=scenario.payload_kg,
            com_m=tuple(scenario.payload_com_m),
            frame=scenario.payload_frame,
        ),
    )
    controller_robot = with_inertia_error(robot, scenario.inertia_error)
    trajectory = scenario.move()
    plant_config = PlantConfig(period=scenario.period, step=scenario.step)
    return Built(plant_robot, controller_robot, robot, trajectory, plant_config)


def run_offline(
    scenario: Scenario,
    controller: str,
    params: Mapping[str, Any] | None = None,
    n_samples: int | None = None,
    effects: ArmEffects | None = None,
) -> RunResult:
    """Build the scenario and run the closed loop without ROS (on the ideal plant, or with
    what a physical arm adds: :mod:`apc_plant_sim.effects`)."""
    built = build(scenario)
    q0, qd0, _ = built.trajectory.sample(0.0)
    pickup = payload_pickup_sample(scenario)
    initial = built.unloaded_robot if pickup else built.plant_robot
    if effects is None:
        plant = Plant(initial, built.plant_config, q0, qd0)
    else:
        plant = PhysicalArm(initial, built.plant_config, effects, q0, qd0)
    feedforward = Feedforward(built.controller_robot.model, built.trajectory, scenario.period)
    feedback = make_law(controller, built.controller_robot, scenario.period, params)
    result = run_closed_loop(
        plant,
        feedforward,
        feedback,
        scenario.n_samples if n_samples is None else n_samples,
        plant_changes={pickup: built.plant_robot} if pickup else None,
    )
    result.meta.update(
        controller=controller, payload_kg=scenario.payload_kg, params=dict(params or {})
    )
    return result


def payload_pickup_sample(scenario: Scenario) -> int:
    """Sample at which the payload appears on the plant (0: there from the start)."""
    if scenario.payload_kg == 0.0 or scenario.payload_at_s <= 0.0:
        return 0
    return round(scenario.payload_at_s / scenario.period)


def joint_sign_to_paper(n: int) -> np.ndarray:
    """Sign per joint that turns URDF-angle errors into the paper's convention (PUMA only)."""
    sign = np.ones(n)
    sign[: min(n, 3)] = PAPER_JOINT_SIGN[: min(n, 3)]
    return sign


__all__: Sequence[str] = (
    "PAPER_CASES",
    "Built",
    "Scenario",
    "ScenarioError",
    "build",
    "paper_scenario",
    "paper_settings",
    "run_offline",
)
