"""The simulated ros2_control robot's loop (:class:`RobotDriver`), told the time (no ROS graph)."""

from __future__ import annotations

import numpy as np
import pytest

from apc_core.config_files import resolve_config_path
from apc_core.robot import Payload, load_robot, with_payload
from apc_plant_sim.effects import ArmEffects
from apc_plant_sim.engines import PinocchioEngine
from apc_plant_sim.plant import Plant, PlantConfig
from apc_plant_sim.robot_driver import DriverConfig, DriverError, RobotDriver, WallCycles

NAMES = ("joint_1", "joint_2", "joint_3")


class RecordingEngine:
    """Integrates nothing; records what the driver applies (q' is settable)."""

    def __init__(self) -> None:
        self.joint_names = NAMES
        self.effort_limit = np.array([97.6, 186.4, 89.4])
        self.q = np.array([0.1, 0.2, 0.3])
        self.qd = np.array([1.0, -2.0, 0.5])
        self.applied: list[tuple[np.ndarray, float]] = []
        self.holds = 0

    def advance(self, tau: np.ndarray, duration: float) -> None:
        self.applied.append((np.array(tau), duration))

    def hold(self) -> None:
        self.holds += 1


def _driver(**overrides) -> tuple[RobotDriver, RecordingEngine]:
    engine = RecordingEngine()
    return RobotDriver(engine, DriverConfig(**overrides)), engine


def test_brakes_hold_until_the_first_command_then_it_is_applied_for_one_period():
    driver, engine = _driver(state_rate=250.0)
    driver.advance(0.0)
    assert engine.holds == 1 and not engine.applied and driver.braked
    assert driver.offer([1.0, 2.0, 3.0], 0.001) is None
    driver.advance(0.004)
    tau, duration = engine.applied[-1]
    np.testing.assert_array_equal(tau, [1.0, 2.0, 3.0])
    assert duration == pytest.approx(0.004)
    assert not driver.braked and driver.counts.commands == 1


def test_command_joints_order_maps_data_to_the_urdf_joints():
    driver, engine = _driver(command_joints=("joint_3", "joint_1", "joint_2"))
    driver.offer([3.0, 1.0, 2.0], 0.0)
    driver.advance(0.0)
    np.testing.assert_array_equal(engine.applied[-1][0], [1.0, 2.0, 3.0])


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        ([1.0, 2.0], "2 values, expected 3"),
        ([1.0, 2.0, 3.0, 4.0], "4 values, expected 3"),
        ([], "0 values"),
        ([1.0, float("nan"), 3.0], "non-finite value for ['joint_2']"),
        ([1.0, 2.0, float("inf")], "non-finite value for ['joint_3']"),
    ],
)
def test_bad_commands_are_rejected_counted_and_never_applied(data, reason):
    driver, engine = _driver()
    driver.offer([1.0, 2.0, 3.0], 0.0)
    got = driver.offer(data, 0.001)
    assert got is not None and reason in got
    assert driver.counts.rejected == 1 and driver.counts.commands == 1
    driver.advance(0.002)
    np.testing.assert_array_equal(engine.applied[-1][0], [1.0, 2.0, 3.0])
    # The held command keeps its own time: a rejected one does not refresh the timeout.
    assert driver.command_time == 0.0


def test_commands_beyond_the_effort_limits_are_clipped_and_counted_per_joint():
    driver, engine = _driver()
    driver.offer([500.0, -10.0, -100.0], 0.0)
    driver.advance(0.0)
    np.testing.assert_array_equal(engine.applied[-1][0], [97.6, -10.0, -89.4])
    assert driver.counts.clipped == 1
    assert driver.counts.clipped_per_joint == {"joint_1": 1, "joint_3": 1}


def test_effort_limit_parameter_overrides_the_urdf():
    driver, engine = _driver(effort_limit=(5.0, 5.0, 5.0))
    driver.offer([6.0, -6.0, 1.0], 0.0)
    driver.advance(0.0)
    np.testing.assert_array_equal(engine.applied[-1][0], [5.0, -5.0, 1.0])


def test_after_command_timeout_the_drive_applies_zero_effort_plus_damping():
    driver, engine = _driver(state_rate=100.0, command_timeout=0.055, timeout_damping=2.0)
    driver.offer([1.0, 2.0, 3.0], 1.0)
    for k in range(10):  # 1.00 ... 1.09 s
        driver.advance(1.0 + 0.01 * k)
    applied = [tau for tau, _ in engine.applied]
    for tau in applied[:6]:  # age 0 ... 0.05 s: still the command (timeout 0.055 s)
        np.testing.assert_array_equal(tau, [1.0, 2.0, 3.0])
    for tau in applied[6:]:
        np.testing.assert_allclose(tau, -2.0 * engine.qd)
    assert driver.timed_out
    assert driver.counts.timeouts == 1 and driver.counts.timeout_cycles == 4
    driver.offer([4.0, 5.0, 6.0], 1.1)  # a fresh command ends the timeout
    driver.advance(1.1)
    np.testing.assert_array_equal(engine.applied[-1][0], [4.0, 5.0, 6.0])
    assert not driver.timed_out and driver.counts.timeouts == 1


def test_pure_zero_effort_by_default():
    driver, engine = _driver(command_timeout=0.01)
    driver.offer([1.0, 2.0, 3.0], 0.0)
    driver.advance(0.02)
    np.testing.assert_array_equal(engine.applied[-1][0], np.zeros(3))


def test_measure_in_state_joints_order_with_an_extra_joint_and_optional_fields():
    driver, _ = _driver(
        state_joints=("joint_2", "finger", "joint_3", "joint_1"),
        extra_position=0.04,
        publish_velocity=False,
    )
    driver.offer([1.0, 2.0, 3.0], 0.0)
    driver.advance(0.0)
    reading = driver.measure(12.5)
    assert reading.stamp == 12.5
    assert reading.names == ("joint_2", "finger", "joint_3", "joint_1")
    np.testing.assert_array_equal(reading.position, [0.2, 0.04, 0.3, 0.1])
    assert reading.velocity is None
    np.testing.assert_array_equal(reading.effort, [2.0, 0.0, 3.0, 1.0])
    driver2, _ = _driver(publish_effort=False)
    reading2 = driver2.measure(0.0)
    assert reading2.effort is None
    np.testing.assert_array_equal(reading2.velocity, [1.0, -2.0, 0.5])


@pytest.mark.parametrize(
    ("overrides", "param"),
    [
        ({"state_rate": 0.0}, "state_rate"),
        ({"command_timeout": float("nan")}, "command_timeout"),
        ({"timeout_damping": -1.0}, "timeout_damping"),
        ({"effort_limit": (1.0, 0.0, 1.0)}, "effort_limit"),
        ({"effort_limit": (1.0, 1.0)}, "effort_limit"),
        ({"command_joints": ("joint_1", "joint_2")}, "command_joints"),
        ({"command_joints": ("joint_1", "joint_1", "joint_2")}, "command_joints"),
        ({"state_joints": ("joint_1", "joint_2")}, "state_joints"),
        ({"state_joints": ("joint_1", "joint_2", "joint_3", "joint_1")}, "state_joints"),
    ],
)
def test_bad_configuration_names_the_parameter(overrides, param):
    with pytest.raises(DriverError, match=f"^{param}:"):
        _driver(**overrides)


def test_pinocchio_engine_is_apcs_plant_under_the_same_torques():
    """The driver on the pinocchio engine integrates exactly what apc's plant integrates."""
    robot = load_robot(resolve_config_path("puma560_3dof.urdf"))
    payload = Payload(mass_kg=2.268)
    q0 = np.deg2rad([0.0, -20.0, 30.0])
    engine = PinocchioEngine(robot, payload, period=0.01, max_step=0.0025, q0=q0)
    driver = RobotDriver(engine, DriverConfig(state_rate=100.0))
    plant = Plant(with_payload(robot, payload), PlantConfig(period=0.01, step=0.0025), q0)
    rng = np.random.default_rng(3)
    for k in range(50):
        tau = rng.uniform(-30.0, 30.0, 3)
        driver.offer(tau, 0.01 * k)
        driver.advance(0.01 * k)
        plant.step(tau)
    reading = driver.measure(0.5)
    np.testing.assert_array_equal(reading.position, plant.q)
    np.testing.assert_array_equal(reading.velocity, plant.qd)


def test_pinocchio_engine_picks_the_payload_up():
    robot = load_robot(resolve_config_path("puma560_3dof.urdf"))
    payload = Payload(mass_kg=2.268)
    q0 = np.deg2rad([0.0, -20.0, 30.0])
    engine = PinocchioEngine(robot, payload, period=0.01, max_step=0.005, q0=q0, loaded=False)
    bare = PinocchioEngine(robot, Payload(), period=0.01, max_step=0.005, q0=q0)
    for e in (engine, bare):
        e.advance(np.zeros(3), 0.01)
    np.testing.assert_array_equal(engine.q, bare.q)
    engine.load_payload()
    for e in (engine, bare):
        e.advance(np.zeros(3), 0.01)
    assert not np.allclose(engine.q, bare.q)


class MovingEngine(RecordingEngine):
    """Moves at constant speed qd per period (q' = qd)."""

    def advance(self, tau: np.ndarray, duration: float) -> None:
        super().advance(tau, duration)
        self.q = self.q + self.qd * duration


def test_encoder_quantises_positions_and_the_drive_differences_them():
    engine = MovingEngine()
    counts = (1000.0, 2000.0, 4000.0)
    sensing = ArmEffects(counts_per_rev=counts, velocity="difference")
    driver = RobotDriver(engine, DriverConfig(state_rate=100.0, sensing=sensing))
    resolution = 2 * np.pi / np.array(counts)
    driver.offer([0.0, 0.0, 0.0], 0.0)
    previous = driver.measure(0.0).position
    for k in range(1, 5):
        driver.advance(0.01 * (k - 1))
        reading = driver.measure(0.01 * k)
        steps = reading.position / resolution
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
        assert (np.abs(reading.position - engine.q) <= resolution / 2 + 1e-12).all()
        np.testing.assert_allclose(reading.velocity, (reading.position - previous) / 0.01)
        previous = reading.position


def test_noisy_drive_velocity_has_the_configured_spread_and_a_seed():
    def velocities(seed: int) -> np.ndarray:
        engine = RecordingEngine()
        sensing = ArmEffects(velocity="noisy", velocity_noise_rad_s=0.05, seed=seed)
        driver = RobotDriver(engine, DriverConfig(sensing=sensing))
        driver.offer([0.0, 0.0, 0.0], 0.0)
        out = []
        for k in range(2000):
            driver.advance(0.002 * k)
            out.append(driver.measure(0.002 * k).velocity - engine.qd)
        return np.array(out)

    noise = velocities(1)
    assert np.std(noise) == pytest.approx(0.05, rel=0.05)
    np.testing.assert_array_equal(noise, velocities(1))


def test_command_delay_applies_each_command_whole_periods_later():
    driver, engine = _driver(sensing=ArmEffects(command_delay=2))
    for k in range(5):
        driver.offer([float(k), 0.0, 0.0], 0.002 * k)
        driver.advance(0.002 * k)
    # The first command is held for the two periods before it is due (as the arm held it).
    assert [tau[0] for tau, _ in engine.applied] == [0.0, 0.0, 0.0, 1.0, 2.0]


def test_cycles_that_got_no_new_command_are_counted_as_held():
    driver, _ = _driver(state_rate=1000.0)
    driver.advance(0.000)  # braked, no command yet: not a held cycle
    driver.offer([1.0, 2.0, 3.0], 0.0005)
    driver.advance(0.001)  # the first command
    driver.advance(0.002)  # none arrived: the command of 0.001 again
    driver.offer([1.0, 2.0, 3.0], 0.0025)
    driver.offer([1.5, 2.0, 3.0], 0.0029)  # two in one period: the newest applies, none held
    driver.advance(0.003)
    driver.advance(0.004)
    assert driver.counts.held_command_cycles == 2
    assert driver.counts.cycles == 5 and driver.counts.commands == 3


# -- the robot's clock: command latency and phase ------------------------------------------------


def _first_cycle_applying(engine: RecordingEngine, value: float, cycles: list[float]) -> float:
    """Driver time of the first cycle whose applied torque has ``value`` on joint_1 (the cycles
    braked before the first command applied nothing)."""
    index = next(i for i, (tau, _) in enumerate(engine.applied) if tau[0] == value)
    return cycles[engine.holds + index]


@pytest.mark.parametrize(
    ("latency", "cycle"),
    [(0.0, 0), (0.001, 1), (0.02, 2), (0.025, 3), (0.03, 3)],
)
def test_fixed_latency_applies_a_command_from_the_first_cycle_at_or_after_it(latency, cycle):
    """100 Hz driver, a command offered at cycle 0: applicable at 0 + latency, applied from the
    first cycle at or after (0.02 s lands on cycle 2 exactly, compared to the nanosecond)."""
    driver, engine = _driver(state_rate=100.0, command_latency=latency)
    driver.offer([7.0, 0.0, 0.0], 0.0)
    assert driver.has_command
    for i in range(6):
        driver.advance(driver.config.cycle_time(i))
        # The brakes hold the arm until the command is applicable.
        assert driver.braked == (i < cycle)
    assert engine.holds == cycle
    assert [tau[0] for tau, _ in engine.applied] == [7.0] * (6 - cycle)
    assert driver.command_time == pytest.approx(latency)


def test_latency_keeps_the_arm_on_the_previous_command_until_the_new_one_is_applicable():
    driver, engine = _driver(state_rate=100.0, command_latency=0.015)
    driver.offer([1.0, 0.0, 0.0], -0.02)  # applicable at -0.005
    for i in range(5):
        t = driver.config.cycle_time(i)
        if i == 1:
            driver.offer([2.0, 0.0, 0.0], t)  # applicable at 0.025: cycle 3
        driver.advance(t)
    assert [tau[0] for tau, _ in engine.applied] == [1.0, 1.0, 1.0, 2.0, 2.0]
    # Cycles 1 and 2 re-applied the held command: the new one was on its way.
    assert driver.counts.held_command_cycles == 3


def _random_latency_delays(seed: int) -> list[float]:
    """Delays (s) from offer to application of 200 commands spaced wider than the latency."""
    driver, engine = _driver(
        state_rate=10_000.0,
        command_latency=0.002,
        command_latency_max=0.006,
        latency_seed=seed,
        effort_limit=(1e6, 1e6, 1e6),
    )
    cycles = [driver.config.cycle_time(i) for i in range(200 * 100)]
    offers = {}
    for i, t in enumerate(cycles):
        if i % 100 == 0:  # every 10 ms, a new value
            offers[float(i // 100 + 1)] = t
            driver.offer([float(i // 100 + 1), 0.0, 0.0], t)
        driver.advance(t)
    return [_first_cycle_applying(engine, v, cycles) - t for v, t in offers.items()]


def test_random_latency_stays_within_its_bounds_and_a_seed_reproduces_it():
    delays = _random_latency_delays(seed=5)
    # Applied at the first 0.1 ms cycle at or after the drawn latency in [2, 6] ms.
    assert min(delays) >= 0.002 - 1e-12 and max(delays) < 0.006 + 1e-4
    # Spread over the interval (uniform draws), not one value.
    assert min(delays) < 0.0025 and max(delays) > 0.0055
    assert np.std(delays) == pytest.approx(0.004 / np.sqrt(12), rel=0.2)
    assert delays == _random_latency_delays(seed=5)
    assert delays != _random_latency_delays(seed=6)


def test_random_latency_keeps_the_commands_order_and_the_newest_applicable_wins():
    """A command every 1 ms cycle with a latency of 0-10 ms: many are drawn shorter than their
    predecessor's; none overtakes it, and a cycle applies the newest one that is due."""
    driver, engine = _driver(
        state_rate=1000.0,
        command_latency=0.0,
        command_latency_max=0.01,
        latency_seed=2,
        effort_limit=(1e6, 1e6, 1e6),
    )
    for i in range(300):
        t = driver.config.cycle_time(i)
        driver.offer([float(i + 1), 0.0, 0.0], t)
        driver.advance(t)
    applied = [tau[0] for tau, _ in engine.applied]
    assert applied == sorted(applied)
    # Several commands became applicable at the same cycle: only the newest was applied.
    assert len(set(applied)) < len(applied) - 10 and applied[-1] > 280.0


def test_latency_composes_with_command_delay_cycles():
    """Latency picks the cycle the drive takes a command up; command_delay then delays the torque
    decided there by whole periods: offered at cycle i, 15 ms at 100 Hz -> cycle i + 2, + 2."""
    driver, engine = _driver(
        state_rate=100.0, command_latency=0.015, sensing=ArmEffects(command_delay=2)
    )
    for i in range(8):
        t = driver.config.cycle_time(i)
        driver.offer([float(i + 1), 0.0, 0.0], t)
        driver.advance(t)
    # Braked for cycles 0-1; command 1 applicable at cycle 2, applied over cycle 4.
    assert engine.holds == 2
    assert [tau[0] for tau, _ in engine.applied] == [1.0, 1.0, 1.0, 2.0, 3.0, 4.0]


def test_the_command_timeout_counts_from_when_a_command_became_applicable():
    driver, engine = _driver(state_rate=100.0, command_latency=0.05, command_timeout=0.02)
    driver.offer([3.0, 0.0, 0.0], 0.0)
    for i in range(9):
        driver.advance(driver.config.cycle_time(i))
    # Braked 0-40 ms, the command from 50 ms (age 0-20 ms), zero effort at 80 ms (age 30 ms).
    assert [tau[0] for tau, _ in engine.applied] == [3.0, 3.0, 3.0, 0.0]
    assert driver.timed_out and driver.counts.timeouts == 1


def test_phase_offsets_the_driver_cycles_and_their_stamps():
    driver, _ = _driver(state_rate=500.0, phase=0.0007)
    stamps = []
    for i in range(5):
        t = driver.config.cycle_time(i)
        driver.advance(t)
        stamps.append(round(driver.measure(t).stamp * 1e9))
    assert stamps == [700_000 + i * 2_000_000 for i in range(5)]
    assert [driver.config.cycle_time_ns(i) for i in range(3)] == [700_000, 2_700_000, 4_700_000]
    assert DriverConfig(state_rate=500.0).cycle_time(3) == 0.006


@pytest.mark.parametrize(
    ("overrides", "param"),
    [
        ({"command_latency": -0.001}, "command_latency"),
        ({"command_latency": float("inf")}, "command_latency"),
        ({"command_latency": 0.01, "command_latency_max": 0.005}, "command_latency_max"),
        ({"command_latency_max": float("nan")}, "command_latency_max"),
        ({"latency_seed": -1}, "latency_seed"),
        ({"state_rate": 100.0, "phase": 0.01}, "phase"),
        ({"phase": -1e-4}, "phase"),
        ({"phase": float("nan")}, "phase"),
    ],
)
def test_bad_latency_or_phase_names_the_parameter(overrides, param):
    with pytest.raises(DriverError, match=f"^{param}:"):
        _driver(**overrides)


@pytest.mark.parametrize(
    ("next_cycle_ns", "interval_ns"),
    [
        (10_700_000, 2_000_000),  # on the phase (0.7 ms after a multiple of 2 ms)
        (10_710_000, 2_000_000),  # within the tolerance
        (11_000_000, 1_700_000),  # 0.3 ms late: the interval after it is shortened
        (11_700_000, 1_000_000),  # 1 ms late (half a period): shortened
        (12_500_000, 2_200_000),  # 0.2 ms early: lengthened
    ],
)
def test_aligning_interval_puts_the_cycle_after_the_next_on_the_phase(next_cycle_ns, interval_ns):
    config = DriverConfig(state_rate=500.0, phase=0.0007)
    assert config.aligning_interval_ns(next_cycle_ns, tolerance_ns=20_000) == interval_ns
    assert (next_cycle_ns + interval_ns - 700_000) % 2_000_000 in (0, 10_000)


def test_a_wall_timers_callback_stands_for_the_cycles_due_since_the_last_one():
    """On wall time each state is stamped with its cycle's instant, not the callback's: a late
    callback (jitter) runs its own cycle, one more than a period late runs the missed one too,
    an early one runs the next cycle, never one twice."""
    config = DriverConfig(state_rate=1000.0, phase=0.0003)
    cycles = WallCycles(config)
    base = 5_000_000 * config.period_ns + config.phase_ns  # cycle 5e6's instant
    assert list(cycles.due(base + 400_000)) == [5_000_000]  # 0.4 ms late: its own cycle
    assert list(cycles.due(base + 1_000_000)) == [5_000_001]  # on time
    assert list(cycles.due(base + 3_700_000)) == [5_000_002, 5_000_003]  # one missed
    assert list(cycles.due(base + 3_900_000)) == [5_000_004]  # early: the next, not 3 again
    assert config.cycle_time_ns(5_000_003) == base + 3_000_000
