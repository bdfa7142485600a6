"""The feedforward's plan and lookahead (apc_feedforward.goals), no ROS graph: the first move
from the measured position, queued goals from the end of the current motion, the queue bound,
the checks of a goal (limits, speed), the hold after a plan that cannot be published, and
which samples answer which joint state (ahead, resend, stale)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import apc_msgs_py as wire
from apc_core.config_files import config_dir
from apc_core.robot import load_robot
from apc_feedforward.four_three_four import FourThreeFour
from apc_feedforward.goals import MAX_QUEUED_GOALS, GoalQueue, Lookahead
from apc_feedforward.nominal import Feedforward, Setpoint
from apc_feedforward.trajectory import TrajectoryError, Waypoints

URDF = config_dir() / "puma560_3dof.urdf"
T = 0.01
MOVE = dict(segment_times=(0.2, 0.6, 0.2), lift_off=0.1, set_down=0.9)
Q0 = np.deg2rad([10.0, 20.0, -30.0])


@pytest.fixture(scope="module")
def robot():
    return load_robot(URDF)


def queue(robot, first_goal=None) -> GoalQueue:
    return GoalQueue(
        robot.model, T, robot.joint_names, robot.position_limits, first_goal=first_goal, move=MOVE
    )


def goal(times_s, positions, velocities=None) -> wire.TrajectoryGoal:
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    vel = None if velocities is None else np.atleast_2d(np.asarray(velocities, dtype=float))
    return wire.TrajectoryGoal(np.asarray(times_s, dtype=float), positions, vel, None)


def keep(sp: Setpoint) -> Setpoint:
    return sp


def test_the_first_sample_holds_the_measured_position_without_a_first_goal(robot):
    q = queue(robot)
    out = q.sample(5, Q0, keep)
    assert out.rendered is out.setpoint and out.setpoint.k == 5
    assert_array_equal(out.setpoint.q, Q0)
    assert_array_equal(out.setpoint.qd, np.zeros(3))
    # Later samples hold it; another measured position does not move the plan.
    assert_array_equal(q.sample(50, Q0 + 1.0, keep).setpoint.q, Q0)


def test_the_first_move_starts_at_the_first_measured_position_and_sample(robot):
    target = Q0 + 0.2
    q = queue(robot, first_goal=target)
    reference = Feedforward(robot.model, FourThreeFour(Q0, target, **MOVE), T, 3)
    for k in (3, 10, 60, 103, 200):
        got = q.sample(k, Q0, keep).setpoint
        want = reference.sample(k)
        assert_array_equal(got.q, want.q)
        assert_array_equal(got.u_n, want.u_n)
    assert_array_equal(q.sample(500, Q0, keep).setpoint.q, target)  # held after the move


def test_a_queued_goal_starts_where_and_when_the_current_motion_ends(robot):
    target, next_q = Q0 + 0.2, Q0 + 0.3
    q = queue(robot, first_goal=target)
    q.sample(0, Q0, keep)
    q.add(goal([0.5], [next_q]))
    end = q.feedforward.end_k()
    assert end == 100
    for k in range(1, end):
        out = q.sample(k, Q0, keep)
        assert not out.started
    out = q.sample(end, Q0, keep)
    assert out.started == [0.5] and not q.queued
    plan = Waypoints(target, np.array([0.5]), np.atleast_2d(next_q))
    for k in (end, end + 20, end + 50):
        assert_array_equal(q.sample(k, Q0, keep).setpoint.q, plan.sample((k - end) * T)[0])


def test_goals_queued_before_the_first_sample_start_in_order(robot):
    q = queue(robot)
    q.add(goal([0.1], [Q0 + 0.01]))
    q.add(goal([0.1], [Q0 + 0.02]))
    assert len(q.queued) == 2
    # The hold of the first sample lasts one period; the goals follow one after the other.
    started = [k for k in range(40) if q.sample(k, Q0, keep).started]
    assert started == [1, 11]
    assert_array_equal(q.sample(40, Q0, keep).setpoint.q, Q0 + 0.02)


def test_the_queue_is_bounded(robot):
    q = queue(robot)
    for _ in range(MAX_QUEUED_GOALS):
        q.add(goal([0.1], [Q0]))
    with pytest.raises(wire.WireError, match="goals already queued"):
        q.add(goal([0.1], [Q0]))
    assert len(q.queued) == MAX_QUEUED_GOALS


def test_a_goal_outside_the_joint_limits_is_refused_naming_the_joint(robot):
    upper = robot.position_limits[1]
    q = queue(robot)
    outside = Q0.copy()
    outside[1] = upper[1] + 0.1
    with pytest.raises(wire.WireError, match=rf"points\[1\].positions: .*{robot.joint_names[1]}"):
        q.add(goal([0.1, 0.2], [Q0, outside]))
    assert not q.queued


def test_a_goal_too_fast_for_the_wire_is_refused_when_it_arrives(robot):
    q = queue(robot)
    with pytest.raises(TrajectoryError, match="too fast"):
        q.add(goal([0.05, 0.1], [Q0 + 0.1, Q0 + 0.2], velocities=[[2e6] * 3, [0.0] * 3]))
    assert not q.queued


def test_a_goal_too_fast_from_its_actual_start_is_refused_when_it_starts(robot):
    far = Q0 + 1e5  # the first move ends 1e5 rad away (nothing checks a first goal's range)
    q = queue(robot, first_goal=far)
    q.sample(0, Q0, keep)
    # Checked from its own first point it does not move; from `far` it is 1e5 rad in 20 ms.
    q.add(goal([0.02], [Q0]))
    out = q.sample(100, Q0, keep)
    assert len(out.refused) == 1 and isinstance(out.refused[0], TrajectoryError)
    assert not out.started and not q.queued
    assert_array_equal(out.setpoint.q, far)


def test_a_set_point_the_wire_refuses_drops_the_plan_for_a_hold_of_the_last_one(robot):
    q = queue(robot, first_goal=Q0 + 0.2)
    last = q.sample(0, Q0, keep).setpoint
    for k in range(1, 40):
        last = q.sample(k, Q0, keep).setpoint

    def refuse_moving(sp: Setpoint) -> Setpoint:
        if np.any(sp.qd != 0.0):
            raise wire.WireError("points[0].velocities: too big")
        return sp

    out = q.sample(40, Q0, refuse_moving)
    assert isinstance(out.plan_error, wire.WireError) and out.failed is None
    assert_array_equal(out.setpoint.q, last.q)
    assert_array_equal(out.setpoint.qd, np.zeros(3))
    assert_array_equal(q.sample(41, Q0, keep).setpoint.q, last.q)


def test_nothing_is_rendered_when_even_the_hold_is_refused(robot):
    def refuse(sp: Setpoint) -> Setpoint:
        raise wire.WireError("refused")

    q = queue(robot)
    out = q.sample(0, Q0, refuse)
    assert out.plan_error is not None and out.failed is not None
    assert out.rendered is None and out.setpoint is None
    # The next sample renders again (the hold starts at the measured position).
    assert_array_equal(q.sample(1, Q0, keep).setpoint.q, Q0)


def _setpoint(k: int) -> Setpoint:
    z = np.zeros(3)
    return Setpoint(k=k, t=0.0, q=z, qd=z, qdd=z, u_n=z)


def _answer(look: Lookahead, k: int, period_ns: int = 10) -> list[int]:
    due = look.due(k * period_ns, k)
    assert due.resend is None
    for j in due.samples:
        look.sent(_setpoint(j))
    look.answered(k)
    return list(due.samples)


def test_lookahead_answers_each_state_with_the_samples_not_sent_yet():
    look = Lookahead(2)
    assert _answer(look, 0) == [0, 1, 2]
    assert _answer(look, 1) == [3]
    assert _answer(look, 4) == [4, 5, 6]  # a gap: from the state's own sample on


def test_lookahead_zero_answers_a_state_with_its_own_sample():
    look = Lookahead(0)
    assert [_answer(look, k) for k in range(3)] == [[0], [1], [2]]


def test_lookahead_starts_at_the_first_state_it_sees():
    assert _answer(Lookahead(1), 7) == [7, 8]


def test_a_resent_state_gets_everything_sent_for_it_again():
    look = Lookahead(1)
    _answer(look, 0)
    _answer(look, 1)
    due = look.due(10, 1)
    assert due.resend is not None and [sp.k for sp in due.resend] == [1, 2]
    assert list(due.samples) == []
    assert _answer(look, 2) == [3]


def test_a_sample_not_sent_is_computed_again_at_the_next_state():
    look = Lookahead(1)
    look.due(0, 0)
    look.sent(_setpoint(0))  # sample 1 failed and was not sent
    look.answered(0)
    assert list(look.due(10, 1).samples) == [1, 2]


def test_a_stale_state_is_refused_and_changes_nothing():
    look = Lookahead(1)
    _answer(look, 0)
    _answer(look, 3)
    with pytest.raises(wire.WireError, match="stale"):
        look.due(20, 2)
    assert _answer(look, 4) == [5]


def test_a_restart_drops_plan_and_goals_and_holds_the_position_measured_then(robot):
    """Robot mode's start: activation, a watchdog recovery, an aborted goal."""
    target = Q0 + 0.2
    q = queue(robot, first_goal=target)
    q.sample(0, Q0, keep)  # the first move under way
    q.add(goal([0.5], [Q0 - 0.1]))
    assert q.restart() == 1 and not q.queued
    elsewhere = Q0 + 0.05
    out = q.sample(40, elsewhere, keep)
    assert_array_equal(out.setpoint.q, elsewhere)  # held, the first move not started again
    assert_array_equal(out.setpoint.qd, np.zeros(3))
    assert_array_equal(q.sample(200, Q0, keep).setpoint.q, elsewhere)
    # before any plan (the first activation) the first move is kept
    fresh = queue(robot, first_goal=target)
    fresh.restart()
    assert fresh.first_goal is not None


def test_a_stop_brings_a_moving_arm_to_rest_within_its_deceleration(robot):
    """Robot mode's start after a fault: from the measured state the set point slows
    monotonically to rest ``duration`` later, half the distance the velocity would cover on,
    at most 1.5 |v| / duration rad/s^2; then it holds there."""
    q = queue(robot, first_goal=Q0 + 0.2)
    q.sample(0, Q0, keep)
    q.restart()
    velocity = np.array([1.5, -0.8, 0.0])
    q.stop(30, Q0, velocity, 0.2)
    points = [q.sample(k, Q0 + 1.0, keep).setpoint for k in range(30, 55)]
    assert_array_equal(points[0].q, Q0)
    np.testing.assert_allclose(points[0].qd, velocity, atol=1e-12)
    rest = Q0 + 0.1 * velocity
    np.testing.assert_allclose(points[20].q, rest, atol=1e-12)
    assert_array_equal(points[20].qd, np.zeros(3))
    assert_array_equal(points[-1].q, points[20].q)
    speeds = np.abs([p.qd for p in points])
    assert np.all(np.diff(speeds, axis=0) <= 1e-12)  # never speeds up, never reverses
    assert np.max(np.abs([p.qdd for p in points]), axis=0) == pytest.approx(
        1.5 * np.abs(velocity) / 0.2, rel=0.01
    )
    # its 20 samples are a stop's (no goal's: robot mode holds them to no path tolerance)
    assert [q.stopping(k) for k in (29, 30, 49, 50)] == [False, True, True, False]
    q.rejoin(40, Q0, np.zeros(3), 0.5)
    assert not q.stopping(40)  # a hand-back's rejoin is the plan again
    q.stop(60, Q0, velocity, 0.2)
    q.restart()
    assert not q.stopping(60)


def test_a_stop_rests_inside_the_joint_limits(robot):
    lower, upper = robot.position_limits
    q = queue(robot)
    start = upper - 0.01
    q.stop(0, start, np.full(3, 2.0), 0.2)
    q_rest = q.sample(40, start, keep).setpoint.q
    assert np.all(q_rest <= upper) and np.all(q_rest > start)
    assert np.all(lower <= q_rest)


def test_a_hold_is_rejoined_from_where_the_arm_is(robot):
    """Robot mode's hand-back from a fallback during a hold: the set point starts where the arm
    sagged to and reaches the hold at rest after ``duration``."""
    q = queue(robot)
    assert not q.rejoin(0, Q0, np.zeros(3), 0.5)  # no plan before the first sample
    q.sample(0, Q0, keep)  # holding Q0
    sagged = Q0 + np.deg2rad([0.0, -1.0, -3.9])
    assert q.rejoin(50, sagged, np.zeros(3), 0.5)
    start, end = q.sample(50, Q0, keep).setpoint, q.sample(100, Q0, keep).setpoint
    np.testing.assert_allclose(start.q, sagged, atol=1e-12)
    np.testing.assert_allclose(end.q, Q0, atol=1e-12)
    assert_array_equal(start.qd, np.zeros(3))
    assert_array_equal(end.qd, np.zeros(3))
    assert_array_equal(q.sample(130, Q0, keep).setpoint.q, end.q)


def test_a_motion_is_rejoined_on_its_own_timing(robot):
    """A hand-back during a move: the set point starts at the measured state and meets the plan
    after ``duration`` on the plan's timing (the move is not restarted); a goal queued behind it
    starts when the move and the rejoin have both ended, from the move's end."""
    target = Q0 + np.deg2rad([30.0, -20.0, 10.0])
    plain, q = queue(robot, first_goal=target), queue(robot, first_goal=target)
    for k in range(41):
        plain.sample(k, Q0, keep)
        q.sample(k, Q0, keep)
    back = Q0 - 0.1
    q.add(goal([0.5], [back]))
    ref = plain.sample(40, Q0, keep).setpoint  # mid-move: 0.4 s of 1 s
    assert np.all(ref.qd != 0.0)
    off_q, off_qd = ref.q + np.deg2rad([2.0, -1.0, 0.5]), ref.qd + 0.1
    assert q.rejoin(40, off_q, off_qd, 0.3)
    first, near = q.sample(41, Q0, keep).setpoint, plain.sample(41, Q0, keep).setpoint
    np.testing.assert_allclose(first.q, off_q + T * off_qd, atol=1e-4)  # from the state
    np.testing.assert_allclose(first.q - near.q, off_q - ref.q + T * 0.1, atol=1e-4)
    assert first.t == pytest.approx(T)
    for k in range(70, 100):  # after duration: the plan's own set points
        a, b = q.sample(k, Q0, keep).setpoint, plain.sample(k, Q0, keep).setpoint
        np.testing.assert_allclose(a.q, b.q, atol=1e-12)
        np.testing.assert_allclose(a.qd, b.qd, atol=1e-12)
        np.testing.assert_allclose(a.u_n, b.u_n, atol=1e-9)
    assert plain.feedforward.end_k() == 100
    assert q.feedforward.end_k() == 100  # the rejoin ended before the move
    assert_array_equal(q.sample(100, Q0, keep).setpoint.q, target)  # the goal starts there
    np.testing.assert_allclose(q.sample(150, Q0, keep).setpoint.q, back, atol=1e-12)


def test_rejoins_do_not_pile_up(robot):
    """A rejoin of a rejoin that has ended rejoins the plan beneath it (hand-backs over an hour
    do not nest without bound)."""
    q = queue(robot)
    q.sample(0, Q0, keep)
    for k in (100, 200, 300):
        assert q.rejoin(k, Q0 + 0.01, np.zeros(3), 0.5)
        q.sample(k + 1, Q0, keep)
    base = q.feedforward.trajectory._base
    assert not isinstance(base, type(q.feedforward.trajectory))


def test_the_nominal_torque_of_when_a_command_acts_is_the_plans_that_much_later(robot):
    """``acting_later``: the torque of the plan's sample that many samples later, with the set
    point's own position, velocity and acceleration; none later, no change; never earlier."""
    target = np.deg2rad([60.0, -10.0, 20.0])
    plan = Feedforward(robot.model, FourThreeFour(Q0, target, **MOVE), T, 0)
    sp = plan.sample(30)
    assert plan.acting_later(sp, 0) is sp
    two = plan.acting_later(sp, 2)
    assert_array_equal(two.u_n, plan.sample(32).u_n)
    assert not np.allclose(two.u_n, sp.u_n)  # mid-move the torque changes
    assert two.k == 30 and two.t == sp.t
    for name in ("q", "qd", "qdd"):
        assert_array_equal(getattr(two, name), getattr(sp, name))
    with pytest.raises(ValueError, match="samples"):
        plan.acting_later(sp, -1)


def test_the_torque_of_when_a_command_acts_past_a_moves_end_is_the_next_goals(robot):
    """``GoalQueue.acting_later`` past the current motion's end: with a goal queued, the
    torque of that goal's plan as :meth:`GoalQueue.sample` starts it there, not the finished
    move's rest; none queued, the rest at the move's end. The goal is planned once: the
    sample that starts it takes the plan looked ahead at."""
    target, next_q = Q0 + 0.2, Q0 + 0.3
    q = queue(robot, first_goal=target)
    q.sample(0, Q0, keep)
    end = q.feedforward.end_k()
    sp = q.sample(end - 1, Q0, keep).setpoint
    rest = q.acting_later(sp, 2).u_n
    assert_array_equal(rest, q.feedforward.sample(end + 1).u_n)
    q.add(goal([0.5], [next_q]))
    planned = []
    plan_goal = q._plan
    q._plan = lambda start, g: planned.append(g) or plan_goal(start, g)
    ahead = q.acting_later(sp, 2)
    assert ahead.k == end - 1 and ahead.q is sp.q
    assert np.abs(ahead.u_n - rest).max() > 1.0  # the next goal accelerates from the start
    assert_array_equal(ahead.u_n, q.acting_later(sp, 2).u_n)  # its plan kept, not redone
    assert len(q.queued) == 1  # looking ahead starts nothing
    for k in range(end, end + 2):
        q.sample(k, Q0, keep)
    assert_array_equal(ahead.u_n, q.sample(end + 1, Q0, keep).setpoint.u_n)
    assert len(planned) == 1


def test_a_queue_with_interval_middle_builds_every_plan_so(robot):
    """The first move, a queued goal looked ahead at, a stop and a carried model all take
    their nominal torque at the middle of a command's interval when the queue is built so,
    and only then."""
    q = GoalQueue(
        robot.model,
        T,
        robot.joint_names,
        robot.position_limits,
        first_goal=Q0 + 0.2,
        move=MOVE,
        interval_middle=True,
    )
    q.sample(0, Q0, keep)
    assert q.feedforward.interval_middle
    q.add(goal([0.5], [Q0 + 0.3]))
    end = q.feedforward.end_k()
    q.acting_later(q.sample(end - 1, Q0, keep).setpoint, 2)
    assert q._next_plan is not None and q._next_plan[3].interval_middle
    q.stop(end, Q0, np.full(3, 0.1), 0.2)
    assert q.feedforward.interval_middle
    q.restart()
    q.sample(end + 100, Q0, keep)
    q.carry(robot.model, end + 101)
    assert q.feedforward.interval_middle
    assert not queue(robot).interval_middle
