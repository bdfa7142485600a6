"""The plant's torque intake (apc_plant_sim.intake), no ROS graph: every stamp rule (rejected,
out of order, stale, duplicate, kept ahead), lockstep's "both torques of sample k" rule, and
the real-time watchdog (nominal only, brake, release) counted in samples; and Plant.brake."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import apc_msgs_py as wire
from apc_core.config_files import config_dir
from apc_core.robot import load_robot
from apc_plant_sim.intake import Action, Filed, Source, TorqueIntake
from apc_plant_sim.plant import Plant, PlantConfig

T = 10_000_000  # ns
N = 3
NOMINAL, FEEDBACK = Source.NOMINAL, Source.FEEDBACK
A, B = np.array([5.0, 40.0, 10.0]), np.array([-5.0, 30.0, 2.0])


def intake(lockstep: bool, watchdog_ns: int = 5 * T) -> TorqueIntake:
    result = TorqueIntake(T, lockstep, watchdog_ns)
    result.started = True
    return result


@pytest.mark.parametrize("lockstep", [True, False])
def test_nothing_is_taken_before_sample_0_is_sent(lockstep):
    got = TorqueIntake(T, lockstep, 5 * T)
    with pytest.raises(wire.WireError, match="not a sample the plant sent"):
        got.take(NOMINAL, 0, A, 0)


@pytest.mark.parametrize("lockstep", [True, False])
@pytest.mark.parametrize(
    "source, stamp",
    [
        (NOMINAL, (wire.MAX_LOOKAHEAD + 2) * T),  # beyond the feedforward's lookahead
        (FEEDBACK, 2 * T),  # a feedback torque is never ahead of the state
        (NOMINAL, T + 5),  # off the grid
        (FEEDBACK, -T),  # negative
    ],
)
def test_stamps_no_controller_can_have_computed_are_rejected(lockstep, source, stamp):
    got = intake(lockstep)
    with pytest.raises(wire.WireError):
        got.take(source, stamp, A, 1)
    assert not got.pending[source] and got.latest[source] is None and not got.ahead


def test_nominal_torques_up_to_the_largest_lookahead_are_accepted():
    got = intake(lockstep=True)
    assert got.take(NOMINAL, (1 + wire.MAX_LOOKAHEAD) * T, A, 1) is Filed.TAKEN


def test_lockstep_steps_when_both_torques_of_the_sample_are_in():
    got = intake(lockstep=True)
    assert got.missing(0) == [NOMINAL, FEEDBACK] and not got.complete(0)
    assert got.take(FEEDBACK, 0, B, 0) is Filed.TAKEN
    assert got.missing(0) == [NOMINAL] and not got.complete(0)
    assert got.take(NOMINAL, 0, A, 0) is Filed.TAKEN
    assert got.complete(0)
    assert_array_equal(got.pop(0), A + B)
    assert got.missing(0) == [NOMINAL, FEEDBACK]


def test_lockstep_keeps_the_first_of_two_torques_for_a_sample():
    got = intake(lockstep=True)
    got.take(NOMINAL, 0, A, 0)
    assert got.take(NOMINAL, 0, 3.0 * A, 0) is Filed.DUPLICATE
    got.take(FEEDBACK, 0, B, 0)
    assert_array_equal(got.pop(0), A + B)


def test_lockstep_ignores_answers_to_integrated_samples_and_older_stamps():
    got = intake(lockstep=True)
    got.take(NOMINAL, 0, A, 0)
    got.take(FEEDBACK, 0, B, 0)
    got.pop(0)
    assert got.take(NOMINAL, 0, A, 1) is Filed.STALE  # an answer to a resend of sample 0
    assert got.take(FEEDBACK, 0, A, 1) is Filed.STALE
    got.take(NOMINAL, 2 * T, A, 1)  # one ahead
    assert got.take(NOMINAL, T, A, 1) is Filed.OUT_OF_ORDER
    assert got.missing(1) == [NOMINAL, FEEDBACK]


def test_lockstep_keeps_a_nominal_torque_ahead_for_its_sample():
    got = intake(lockstep=True)
    got.take(NOMINAL, 0, A, 0)
    got.take(NOMINAL, T, B, 0)
    got.take(FEEDBACK, 0, np.zeros(N), 0)
    assert_array_equal(got.pop(0), A)
    assert got.missing(1) == [FEEDBACK]  # only its feedback torque is needed now
    got.take(FEEDBACK, T, np.ones(N), 1)
    assert_array_equal(got.pop(1), B + 1.0)


def test_real_time_waits_for_both_answers_to_sample_0():
    got = intake(lockstep=False)
    assert got.tick(0).action is Action.WAIT
    got.take(NOMINAL, 0, A, 0)
    assert got.tick(0).action is Action.WAIT
    got.take(FEEDBACK, 0, B, 0)
    tick = got.tick(0)
    assert tick.action is Action.BOTH and not tick.late and not tick.missing
    assert_array_equal(tick.tau, A + B)


def test_real_time_applies_a_nominal_torque_sent_ahead_at_its_own_sample():
    got = intake(lockstep=False)
    got.take(NOMINAL, 0, A, 0)
    assert got.take(NOMINAL, T, B, 0) is Filed.AHEAD
    got.take(FEEDBACK, 0, np.zeros(N), 0)
    assert got.holds(NOMINAL, 0) and got.holds(NOMINAL, T) and got.holds(FEEDBACK, 0)
    assert not got.holds(FEEDBACK, T) and not got.holds(NOMINAL, 2 * T)
    assert_array_equal(got.tick(0).tau, A)
    got.take(FEEDBACK, T, np.ones(N), 1)
    assert_array_equal(got.tick(1).tau, B + 1.0)
    assert got.holds(NOMINAL, T) and not got.holds(NOMINAL, 0)  # promoted: the latest


@pytest.mark.parametrize("lockstep", [True, False])
def test_holds_says_which_answers_are_in(lockstep):
    got = intake(lockstep)
    assert not got.holds(NOMINAL, 0) and not got.holds(FEEDBACK, 0)
    got.take(FEEDBACK, 0, A, 0)
    assert got.holds(FEEDBACK, 0) and not got.holds(NOMINAL, 0)


def test_real_time_starts_when_the_nominal_torque_ahead_overtakes_sample_0():
    got = intake(lockstep=False)
    assert got.take(NOMINAL, T, B, 0) is Filed.AHEAD  # reordered: u_n(1) first
    assert got.take(NOMINAL, 0, A, 0) is Filed.TAKEN
    got.take(FEEDBACK, 0, np.zeros(N), 0)
    assert_array_equal(got.tick(0).tau, A)
    got.take(FEEDBACK, T, np.zeros(N), 1)
    assert_array_equal(got.tick(1).tau, B)
    assert got.take(NOMINAL, 0, A, 2) is Filed.OUT_OF_ORDER  # a late copy of u_n(0)


def test_real_time_promotes_only_the_newest_torque_ahead_that_is_due():
    got = intake(lockstep=False)
    for j, effort in ((1, A), (2, B), (3, 2.0 * A)):
        got.take(NOMINAL, j * T, effort, 0)
    got.take(NOMINAL, 0, np.zeros(N), 0)
    got.take(FEEDBACK, 0, np.zeros(N), 0)
    got.tick(0)
    tick = got.tick(2)  # a tick missed: samples 1 and 2 are due, 2 is the newest
    assert_array_equal(tick.tau, B)
    assert tick.late == (FEEDBACK,)
    assert list(got.ahead) == [3 * T]


def test_real_time_counts_late_and_missing_torques():
    got = intake(lockstep=False)
    got.take(NOMINAL, 0, A, 0)
    got.take(FEEDBACK, 0, B, 0)
    got.tick(0)
    got.take(FEEDBACK, T, B, 1)
    tick = got.tick(1)
    assert tick.action is Action.BOTH and tick.late == (NOMINAL,) and not tick.missing
    assert_array_equal(tick.tau, A + B)  # the newest nominal torque, one sample old


def test_real_time_applies_the_nominal_torque_alone_without_fresh_feedback():
    got = intake(lockstep=False, watchdog_ns=2 * T)
    got.take(NOMINAL, 0, A, 0)
    got.take(FEEDBACK, 0, B, 0)
    got.tick(0)
    for k in (1, 2):  # feedback from sample 0 is fresh up to sample 2
        got.take(NOMINAL, k * T, A, k)
        assert got.tick(k).action is Action.BOTH
    got.take(NOMINAL, 3 * T, A, 3)
    tick = got.tick(3)
    assert tick.action is Action.NOMINAL_ONLY and tick.late == (FEEDBACK,)
    assert_array_equal(tick.tau, A)
    got.take(FEEDBACK, 4 * T, B, 4)
    got.take(NOMINAL, 4 * T, A, 4)
    assert got.tick(4).action is Action.BOTH


def test_real_time_brakes_without_fresh_nominal_torque_and_releases_when_it_returns():
    got = intake(lockstep=False, watchdog_ns=2 * T)
    got.take(NOMINAL, 0, A, 0)
    got.take(FEEDBACK, 0, B, 0)
    got.tick(0)
    for k in (1, 2):
        got.take(FEEDBACK, k * T, B, k)
        assert got.tick(k).action is Action.BOTH
    got.take(FEEDBACK, 3 * T, B, 3)
    first = got.tick(3)
    assert first.action is Action.BRAKE and first.braking_starts and first.tau is None
    again = got.tick(4)
    assert again.action is Action.BRAKE and not again.braking_starts
    got.take(NOMINAL, 5 * T, A, 5)
    back = got.tick(5)
    assert back.braking_ends and back.action is Action.BOTH  # du(3) is fresh up to sample 5
    assert_array_equal(back.tau, A + B)
    assert not got.tick(5).braking_ends


def test_a_zero_watchdog_needs_the_torques_of_the_sample_itself():
    got = intake(lockstep=False, watchdog_ns=0)
    got.take(NOMINAL, 0, A, 0)
    got.take(FEEDBACK, 0, B, 0)
    assert got.tick(0).action is Action.BOTH
    assert got.tick(1).action is Action.BRAKE


def test_plant_brake_holds_the_position_and_counts_the_sample():
    robot = load_robot(config_dir() / "puma560_3dof.urdf")
    plant = Plant(robot, PlantConfig(period=0.01, step=0.0025), np.deg2rad([0.0, 30.0, -60.0]))
    plant.step(np.zeros(N))
    q = plant.q.copy()
    assert np.any(plant.qd != 0.0)
    plant.brake()
    assert plant.k == 2
    assert_array_equal(plant.q, q)
    assert_array_equal(plant.qd, np.zeros(N))


def test_the_watchdog_comes_from_its_parameter_in_ns():
    from apc_plant_sim.intake import WATCHDOG_PARAMS

    values = {p.name: p.default for p in WATCHDOG_PARAMS}
    got = TorqueIntake.from_params(T, False, values)
    assert got.watchdog_ns == 50_000_000 and not got.lockstep
