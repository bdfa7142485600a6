"""Tests for apc_feedforward.trajectory (pure numpy, no ROS)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import PPoly

from apc_feedforward.four_three_four import FourThreeFour
from apc_feedforward.trajectory import (
    PiecewisePolynomial,
    Quintic,
    Rejoin,
    TrajectoryError,
    Waypoints,
)

# The paper's move ("COMPUTER SIMULATION" section): 1 s, midpoint (45, 0, 90) deg at 0.5 s.
Q0 = np.deg2rad([0.0, 45.0, 45.0])
QF = np.deg2rad([90.0, -45.0, 135.0])
Q_MID = np.deg2rad([45.0, 0.0, 90.0])
EPS = 1e-9  # s, for one-sided samples around a knot


@pytest.fixture
def paper() -> FourThreeFour:
    return FourThreeFour(Q0, QF)


@pytest.fixture
def quintic() -> Quintic:
    return Quintic(Q0, QF, 1.5)


@pytest.fixture
def waypoints() -> Waypoints:
    times = [0.4, 1.0, 1.5, 2.5]
    positions = [[0.2, 0.5, 0.0], [0.6, 0.4, 0.0], [0.7, -0.3, 0.5], [0.9, -0.2, 0.5]]
    return Waypoints(Q0, times, positions)


def _all(paper, quintic, waypoints):
    return [paper, quintic, waypoints]


def _segment(traj: PiecewisePolynomial, segment: int, t: float) -> tuple:
    """One segment's polynomial and its derivatives at ``t``, extrapolated outside the segment
    (not held): what each side of a knot tends to."""
    piece = PPoly(traj.poly.c[:, segment : segment + 1], traj.knot_times[segment : segment + 2])
    return piece(t), piece(t, 1), piece(t, 2)


def _assert_c2_at(traj: PiecewisePolynomial, knot_index: int, atol: float) -> None:
    """Adjacent segment polynomials agree at the knot, and so do one-sided samples."""
    tk = traj.knot_times[knot_index]
    left = _segment(traj, knot_index - 1, tk)
    right = _segment(traj, knot_index, tk)
    for a, b in zip(left, right, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=atol)
    before = traj.sample(tk - EPS)
    after = traj.sample(tk + EPS)
    # Over 2*EPS the change is bounded by the next derivative; 1e-6 is generous for all three.
    for a, b in zip(before, after, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


# ------------------------------------------------------------------ boundary values


@pytest.mark.parametrize("which", ["paper", "quintic", "waypoints"])
def test_boundary_values(which: str, request: pytest.FixtureRequest) -> None:
    traj = request.getfixturevalue(which)
    q, qd, qdd = traj.sample(0.0)
    np.testing.assert_allclose(q, Q0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(qd, 0.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(qdd, 0.0, rtol=0, atol=1e-15)
    # Approaching the end from inside: the polynomial reaches the final point at rest.
    q, qd, qdd = _segment(traj, traj.n_segments - 1, traj.duration)
    q_end = traj.sample(traj.duration)[0]
    np.testing.assert_allclose(q, q_end, rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd, 0.0, rtol=0, atol=1e-11)
    np.testing.assert_allclose(qdd, 0.0, rtol=0, atol=1e-9)


def test_end_positions(paper, quintic, waypoints) -> None:
    np.testing.assert_array_equal(paper.sample(paper.duration)[0], QF)
    np.testing.assert_array_equal(quintic.sample(quintic.duration)[0], QF)
    np.testing.assert_array_equal(
        waypoints.sample(waypoints.duration)[0], waypoints.knot_positions[-1]
    )
    assert paper.duration == 1.0
    assert quintic.duration == 1.5
    assert waypoints.duration == 2.5
    assert paper.n_joints == quintic.n_joints == waypoints.n_joints == 3


def test_hold_before_start_and_after_end(paper, quintic, waypoints) -> None:
    for traj in _all(paper, quintic, waypoints):
        q_end = traj.sample(traj.duration)[0]
        t = np.array([-1.0, -1e-12, traj.duration, traj.duration + 1e-12, traj.duration + 5.0])
        q, qd, qdd = traj.sample_many(t)
        np.testing.assert_array_equal(q[:2], np.vstack([Q0, Q0]))
        np.testing.assert_array_equal(q[2:], np.vstack([q_end] * 3))
        np.testing.assert_array_equal(qd, 0.0)
        np.testing.assert_array_equal(qdd, 0.0)


def test_quintic_nonzero_boundary_derivatives() -> None:
    qd0, qdd0, qdf, qddf = [0.5, -1.0], 2.0, [-0.3, 0.0], [1.0, -4.0]
    traj = Quintic([0.0, 1.0], [1.0, -1.0], 0.7, qd0=qd0, qdd0=qdd0, qdf=qdf, qddf=qddf)
    q, qd, qdd = _segment(traj, 0, 0.0)
    np.testing.assert_allclose(q, [0.0, 1.0], atol=1e-14)
    np.testing.assert_allclose(qd, qd0, atol=1e-14)
    np.testing.assert_allclose(qdd, [2.0, 2.0], atol=1e-13)
    q, qd, qdd = _segment(traj, 0, 0.7)
    np.testing.assert_allclose(q, [1.0, -1.0], atol=1e-13)
    np.testing.assert_allclose(qd, qdf, atol=1e-12)
    np.testing.assert_allclose(qdd, qddf, atol=1e-11)


# ------------------------------------------------------------------ 4-3-4


def test_paper_midpoint(paper) -> None:
    q, qd, _ = paper.sample(0.5)
    np.testing.assert_allclose(q, Q_MID, rtol=0, atol=1e-12)
    # Joint speed peaks there (the paper's remark), in the direction of travel.
    np.testing.assert_array_equal(np.sign(qd), np.sign(QF - Q0))


def test_knot_times(paper) -> None:
    np.testing.assert_allclose(paper.knot_times, [0.0, 0.2, 0.8, 1.0], rtol=0, atol=1e-15)
    traj = FourThreeFour(Q0, QF, segment_times=(0.3, 1.0, 0.5))
    np.testing.assert_allclose(traj.knot_times, [0.0, 0.3, 1.3, 1.8], rtol=0, atol=1e-15)
    assert traj.duration == pytest.approx(1.8)


@pytest.mark.parametrize("segment_times", [(0.2, 0.6, 0.2), (0.3, 1.0, 0.5), (2.0, 5.0, 3.0)])
def test_434_c2_at_knots(segment_times) -> None:
    traj = FourThreeFour(Q0, QF, segment_times=segment_times)
    for k in (1, 2):
        _assert_c2_at(traj, k, atol=1e-12)


def test_434_segment_degrees(paper) -> None:
    c = paper.poly.c  # (d + 1, 3, n), highest power first
    assert c.shape == (5, 3, 3)  # nothing above quartic
    np.testing.assert_array_equal(c[0, 1], 0.0)  # the middle segment is a cubic


def test_lift_off_and_set_down_hit_at_knots(paper) -> None:
    t1, t2 = paper.knot_times[1], paper.knot_times[2]
    np.testing.assert_allclose(paper.sample(t1)[0], Q0 + 0.1 * (QF - Q0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(paper.sample(t2)[0], Q0 + 0.9 * (QF - Q0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(paper.lift_off_position, Q0 + 0.1 * (QF - Q0), atol=1e-15)


def test_explicit_lift_off_array() -> None:
    lift = np.deg2rad([5.0, 40.0, 55.0])
    down = np.deg2rad([80.0, -30.0, 120.0])
    traj = FourThreeFour(Q0, QF, segment_times=(0.25, 0.5, 0.25), lift_off=lift, set_down=down)
    np.testing.assert_allclose(traj.sample(0.25)[0], lift, rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.sample(0.75)[0], down, rtol=0, atol=1e-12)
    for k in (1, 2):
        _assert_c2_at(traj, k, atol=1e-12)
    # Mixed: explicit lift-off, fractional set-down.
    mixed = FourThreeFour(Q0, QF, lift_off=lift, set_down=0.8)
    np.testing.assert_allclose(mixed.sample(0.8)[0], Q0 + 0.8 * (QF - Q0), atol=1e-12)


def test_434_is_linear_in_travel() -> None:
    # One system for all joints: a joint with zero travel stays put, and results scale.
    traj = FourThreeFour([0.0, 1.0, 0.0], [0.0, 1.0, 2.0])
    t = np.linspace(0.0, 1.0, 51)
    q, _, qdd = traj.sample_many(t)
    np.testing.assert_array_equal(q[:, 0], 0.0)
    np.testing.assert_allclose(q[:, 1], 1.0, atol=1e-15)
    ref = FourThreeFour([0.0], [1.0]).sample_many(t)
    np.testing.assert_allclose(q[:, 2], 2.0 * ref[0][:, 0], atol=1e-13)
    np.testing.assert_allclose(qdd[:, 2], 2.0 * ref[2][:, 0], atol=1e-11)


# ------------------------------------------------------------------ derivatives, sampling


@pytest.mark.parametrize("which", ["paper", "quintic", "waypoints"])
def test_derivatives_match_finite_differences(which: str, request: pytest.FixtureRequest) -> None:
    traj = request.getfixturevalue(which)
    h = 1e-5
    t = np.linspace(h, traj.duration - h, 997)  # avoids landing exactly on a knot
    q, qd, qdd = traj.sample_many(t)
    qp, qdp, _ = traj.sample_many(t + h)
    qm, qdm, _ = traj.sample_many(t - h)
    scale_v = np.abs(qd).max()
    scale_a = np.abs(qdd).max()
    np.testing.assert_allclose((qp - qm) / (2 * h), qd, rtol=0, atol=1e-6 * scale_v)
    np.testing.assert_allclose((qdp - qdm) / (2 * h), qdd, rtol=0, atol=1e-5 * scale_a)
    # And position second difference, tying qdd to q directly.
    np.testing.assert_allclose((qp - 2 * q + qm) / h**2, qdd, rtol=0, atol=1e-3 * scale_a)


def test_sample_at_period(paper) -> None:
    T = 0.01
    t, q, qd, qdd = paper.sample_at_period(T)
    assert t.shape == (101,)
    assert q.shape == qd.shape == qdd.shape == (101, 3)
    np.testing.assert_array_equal(t, np.arange(101) * T)
    for k in range(101):
        qk, qdk, qddk = paper.sample(k * T)
        np.testing.assert_array_equal(q[k], qk)
        np.testing.assert_array_equal(qd[k], qdk)
        np.testing.assert_array_equal(qdd[k], qddk)
    np.testing.assert_array_equal(q[-1], QF)
    t5, q5, _, _ = paper.sample_at_period(T, n_samples=5)
    np.testing.assert_array_equal(t5, np.arange(5) * T)
    np.testing.assert_array_equal(q5, q[:5])
    # Past the end the final point is held.
    _, q_long, qd_long, _ = paper.sample_at_period(T, n_samples=150)
    np.testing.assert_array_equal(q_long[101:], np.vstack([QF] * 49))
    np.testing.assert_array_equal(qd_long[101:], 0.0)


def test_sample_on_knot_uses_starting_segment(paper) -> None:
    tk = paper.knot_times[1]
    expected = _segment(paper, 1, tk)
    got = paper.sample(tk)
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_array_equal(a, b)


def test_sample_shapes(paper) -> None:
    q, qd, qdd = paper.sample(0.3)
    assert q.shape == qd.shape == qdd.shape == (3,)
    q, qd, qdd = paper.sample_many(np.array([0.9, 0.1, 0.5]))  # unsorted is fine
    assert q.shape == (3, 3)
    np.testing.assert_array_equal(q[2], paper.sample(0.5)[0])


# ------------------------------------------------------------------ waypoints


def test_waypoints_pass_every_point(waypoints) -> None:
    np.testing.assert_array_equal(waypoints.sample(0.0)[0], Q0)
    times = waypoints.knot_times[1:]
    positions = waypoints.knot_positions[1:]
    for tj, pj in zip(times, positions, strict=True):
        np.testing.assert_allclose(waypoints.sample(tj)[0], pj, rtol=0, atol=1e-12)


def test_waypoints_continuity(waypoints) -> None:
    for k in range(1, waypoints.n_segments):
        _assert_c2_at(waypoints, k, atol=1e-10)


def test_waypoint_velocity_heuristic(waypoints) -> None:
    V = waypoints.knot_velocities
    np.testing.assert_array_equal(V[0], 0.0)
    np.testing.assert_array_equal(V[-1], 0.0)
    # Joint 0 rises monotonically: mean of slopes, limited to twice the smaller one.
    P, t = waypoints.knot_positions, waypoints.knot_times
    s = np.diff(P, axis=0) / np.diff(t)[:, None]
    for j in range(1, V.shape[0] - 1):
        expected = min(0.5 * (s[j - 1, 0] + s[j, 0]), 2 * min(s[j - 1, 0], s[j, 0]))
        assert V[j, 0] == pytest.approx(expected)
    # Joint 1 falls, then turns around at waypoint 3 (-0.7 rad, then +0.1): zero velocity there.
    assert V[1, 1] < 0.0 and V[2, 1] < 0.0
    assert V[3, 1] == 0.0
    # Joint 2 falls, dwells (zero slope), rises, dwells: zero velocity at every interior point.
    np.testing.assert_array_equal(V[1:4, 2], 0.0)
    np.testing.assert_array_equal(waypoints.knot_accelerations, 0.0)


def test_waypoints_do_not_overshoot(waypoints) -> None:
    t = np.linspace(0.0, waypoints.duration, 5001)
    q = waypoints.sample_many(t)[0]
    P, knots = waypoints.knot_positions, waypoints.knot_times
    for j in range(waypoints.n_segments):
        inside = (t >= knots[j]) & (t <= knots[j + 1])
        lo = np.minimum(P[j], P[j + 1]) - 1e-12
        hi = np.maximum(P[j], P[j + 1]) + 1e-12
        assert np.all((q[inside] >= lo) & (q[inside] <= hi))


def test_waypoints_given_velocities_and_accelerations() -> None:
    times = [0.5, 1.0]
    positions = [[0.5, 0.0], [1.0, 1.0]]
    vel = [[1.2, 0.4], [0.0, 0.0]]
    acc = [[0.3, -2.0], [0.0, 0.0]]
    traj = Waypoints([0.0, 0.0], times, positions, velocities=vel, accelerations=acc)
    q, qd, qdd = traj.sample(0.5)
    np.testing.assert_allclose(q, positions[0], atol=1e-12)
    np.testing.assert_allclose(qd, vel[0], atol=1e-12)
    np.testing.assert_allclose(qdd, acc[0], atol=1e-10)
    _assert_c2_at(traj, 1, atol=1e-10)


def test_waypoints_single_point_is_a_rest_to_rest_quintic() -> None:
    traj = Waypoints(Q0, [1.5], [QF])
    ref = Quintic(Q0, QF, 1.5)
    t = np.linspace(-0.1, 1.6, 35)
    for a, b in zip(traj.sample_many(t), ref.sample_many(t), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13)


# ------------------------------------------------------------------ bad arguments


@pytest.mark.parametrize(
    ("make", "name"),
    [
        (lambda: FourThreeFour(Q0, QF, segment_times=(0.2, -0.6, 0.2)), "segment_times[1]"),
        (lambda: FourThreeFour(Q0, QF, segment_times=(0.2, 0.0, 0.2)), "segment_times[1]"),
        (lambda: FourThreeFour(Q0, QF, segment_times=(0.5, 0.5)), "segment_times"),
        (lambda: FourThreeFour(Q0, QF[:2]), "qf"),
        (lambda: FourThreeFour([0.0, np.nan, 0.0], QF), "q0"),
        (lambda: FourThreeFour(Q0, [0.0, np.inf, 0.0]), "qf"),
        (lambda: FourThreeFour(Q0, QF, lift_off=1.2), "lift_off"),
        (lambda: FourThreeFour(Q0, QF, lift_off=0.6, set_down=0.4), "lift_off"),
        (lambda: FourThreeFour(Q0, QF, set_down=[0.0, 1.0]), "set_down"),
        (lambda: FourThreeFour(Q0, QF, set_down=float("nan")), "set_down"),
        (lambda: FourThreeFour(np.zeros((3, 1)), QF), "q0"),
        (lambda: Quintic(Q0, QF, 0.0), "duration"),
        (lambda: Quintic(Q0, QF, float("inf")), "duration"),
        (lambda: Quintic(Q0, QF, 1.0, qd0=[1.0, 2.0]), "qd0"),
        (lambda: Quintic(Q0, QF, 1.0, qddf=np.nan), "qddf"),
        (lambda: Waypoints(Q0, [0.5, 0.5], np.zeros((2, 3))), "times"),
        (lambda: Waypoints(Q0, [0.5, 0.3], np.zeros((2, 3))), "times"),
        (lambda: Waypoints(Q0, [0.0, 1.0], np.zeros((2, 3))), "times"),
        (lambda: Waypoints(Q0, [0.5, 1.0], np.zeros((2, 2))), "positions"),
        (lambda: Waypoints(Q0, [0.5, 1.0], [[0, 0, 0], [0, np.nan, 0]]), "positions"),
        (lambda: Waypoints(Q0, [1.0], np.zeros((1, 3)), velocities=np.zeros((2, 3))), "velocities"),
        (lambda: Waypoints(Q0, [1.0], np.zeros((1, 3)), velocities=np.ones((1, 3))), "velocities"),
        (
            lambda: Waypoints(Q0, [1.0], np.zeros((1, 3)), accelerations=np.ones(3)),
            "accelerations",
        ),
    ],
)
def test_bad_arguments_name_the_argument(make, name: str) -> None:
    with pytest.raises(TrajectoryError) as info:
        make()
    assert str(info.value).startswith(name)
    assert isinstance(info.value, ValueError)


def test_bad_sampling_arguments(paper) -> None:
    for call, name in [
        (lambda: paper.sample(float("nan")), "t"),
        (lambda: paper.sample("soon"), "t"),
        (lambda: paper.sample_many(np.zeros((2, 2))), "t"),
        (lambda: paper.sample_at_period(0.0), "period"),
        (lambda: paper.sample_at_period(-0.01), "period"),
        (lambda: paper.sample_at_period(0.01, n_samples=0), "n_samples"),
        (lambda: paper.sample_at_period(0.01, n_samples=2.5), "n_samples"),
    ]:
        with pytest.raises(TrajectoryError) as info:
            call()
        assert str(info.value).startswith(f"{name}:")


def test_nonzero_end_velocity_can_be_allowed() -> None:
    traj = Waypoints([0.0], [1.0], [[1.0]], velocities=[[0.5]], allow_nonzero_end_velocity=True)
    np.testing.assert_allclose(_segment(traj, 0, 1.0)[1], [0.5], atol=1e-12)
    np.testing.assert_array_equal(traj.sample(1.0)[1], [0.0])  # held at rest afterwards


def test_feedforward_block_sampling_equals_sampling_each_time(paper: FourThreeFour) -> None:
    """Feedforward reads the plan in blocks; every set point is the bits of trajectory.sample,
    across block boundaries, before/after the motion, and after the plan changes mid-block."""
    import pinocchio as pin

    from apc_feedforward.nominal import BLOCK, Feedforward

    model = pin.buildSampleModelManipulator()
    n = model.nv
    start = np.zeros(n)
    first = Quintic(start, np.full(n, 0.5), 1.0)
    ff = Feedforward(model, first, 0.01, start_k=5)
    data = model.createData()
    for k in [*range(0, 2 * BLOCK + 7), 300, 3, 4]:  # jumps back and forth refill the block
        sp = ff.sample(k)
        q, qd, qdd = first.sample((k - 5) * 0.01)
        for got, want in ((sp.q, q), (sp.qd, qd), (sp.qdd, qdd)):
            np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(sp.u_n, pin.rnea(model, data, q, qd, qdd))
        with pytest.raises(ValueError, match="read-only"):
            sp.q[0] = 1.0
    second = Quintic(np.full(n, 0.5), start, 2.0)
    ff.sample(10)
    ff.set_trajectory(second, 12)
    for k in range(12, 40):
        np.testing.assert_array_equal(ff.sample(k).q, second.sample((k - 12) * 0.01)[0])


def test_rejoin_starts_at_the_state_and_ends_on_the_plan():
    """Rejoin: at 0 the given state, velocity and acceleration the derivatives of position
    (checked by differences), the base's own values once the offset has gone, its end held."""
    base = Quintic([0.0, 1.0], [1.0, -1.0], 2.0)
    q0, qd0 = np.array([0.3, 0.9]), np.array([1.0, -0.5])
    r = Rejoin(base, 0.5, q0, qd0, 0.4)
    assert r.duration == pytest.approx(1.5)
    q, qd, qdd = r.sample(0.0)
    np.testing.assert_allclose(q, q0, atol=1e-12)
    np.testing.assert_allclose(qd, qd0, atol=1e-12)
    np.testing.assert_allclose(qdd, base.sample(0.5)[2], atol=1e-9)
    t = np.linspace(0.0, 1.5, 3001)
    q, qd, qdd = r.sample_many(t)
    smooth = np.abs(t - 0.4) > 1e-3  # the jerk steps where the offset ends
    smooth[[0, -1]] = False
    np.testing.assert_allclose(np.gradient(q, t, axis=0)[smooth], qd[smooth], atol=2e-5)
    np.testing.assert_allclose(np.gradient(qd, t, axis=0)[smooth], qdd[smooth], atol=2e-3)
    after = t >= 0.4
    for mine, theirs in zip((q, qd, qdd), base.sample_many(t[after] + 0.5), strict=True):
        np.testing.assert_allclose(mine[after], theirs, atol=1e-12)
    np.testing.assert_array_equal(r.sample(5.0)[0], [1.0, -1.0])
    np.testing.assert_array_equal(r.sample(-1.0)[0], q0)
    short = Rejoin(base, 1.9, q0, qd0, 0.4)  # the offset outlasts the plan
    assert short.duration == pytest.approx(0.4)
    np.testing.assert_allclose(short.sample(0.4)[0], [1.0, -1.0], atol=1e-12)
