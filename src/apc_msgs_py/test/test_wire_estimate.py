"""The wire contract, the estimate (Float64MultiArray <-> F, G, w, trace_p, residual_norm and
the stamp): the layout and every field round trip, the stamp exact up to 2**53, and every
rejection raises WireError whose text names the field.
"""

from __future__ import annotations

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from wire_helpers import INF, NAN, _wire_round_trip

import apc_msgs_py as wire
from apc_msgs_py import WireError


@pytest.mark.parametrize("n", [3, 6, 7])
def test_estimate_round_trip_every_field(n):
    p, m = 2 * n, n
    rng = np.random.default_rng(n)
    F, G, w = rng.normal(size=(p, p)), rng.normal(size=(p, m)), rng.normal(size=p)
    stamp = wire.sample_stamp_ns(360_000, 10_000_000)
    msg = wire.estimate_to_msg(F, G, w, 12.5, 0.25, stamp_ns=stamp)
    d0, d1 = msg.layout.dim
    assert (d0.label, d0.size, d0.stride) == ("theta_rows", p, p * (3 * n + 1))
    assert (d1.label, d1.size, d1.stride) == ("theta_cols", 3 * n + 1, 3 * n + 1)
    assert msg.layout.data_offset == 0
    assert len(msg.data) == p * (3 * n + 1) + 3
    theta = np.hstack([F, G, w[:, None]])
    np.testing.assert_array_equal(np.array(msg.data[: p * (3 * n + 1)]), theta.ravel())
    assert list(msg.data[-3:]) == [12.5, 0.25, float(stamp)]
    est = wire.msg_to_estimate(_wire_round_trip(msg))
    assert est.stamp_ns == stamp
    np.testing.assert_array_equal(est.F, F)
    np.testing.assert_array_equal(est.G, G)
    np.testing.assert_array_equal(est.w, w)
    np.testing.assert_array_equal(est.theta_t, theta)
    assert (est.trace_p, est.residual_norm) == (12.5, 0.25)
    refilled = wire.estimate_to_msg(F, G, w, 1.0, 2.0, stamp_ns=stamp + 1, msg=msg)
    assert refilled is msg and wire.msg_to_estimate(msg).stamp_ns == stamp + 1


def test_estimate_stamp_is_exact_up_to_2_pow_53():
    F, G, w = np.eye(2), np.ones((2, 1)), np.zeros(2)
    assert wire.msg_to_estimate(wire.estimate_to_msg(F, G, w, 0, 0, stamp_ns=2**53)).stamp_ns == (
        2**53
    )
    with pytest.raises(WireError, match=r"^stamp_ns: .*2\*\*53"):
        wire.estimate_to_msg(F, G, w, 0, 0, stamp_ns=2**53 + 1)
    with pytest.raises(TypeError):
        wire.estimate_to_msg(F, G, w, 0, 0)  # the sample time is required


def _estimate_msg() -> Float64MultiArray:
    return wire.estimate_to_msg(np.eye(4), np.ones((4, 2)), np.zeros(4), 1.0, 2.0, stamp_ns=10)


def _set_data(index, value):
    def apply(msg):
        data = list(msg.data)
        data[index] = value
        msg.data = data
        return msg

    return apply


ESTIMATE_REJECTIONS = {
    "labels": (
        lambda m: setattr(m.layout.dim[0], "label", "rows") or m,
        r"^layout\.dim: labels \('rows'",
    ),
    "one dim": (lambda m: setattr(m.layout, "dim", m.layout.dim[:1]) or m, r"^layout\.dim: expe"),
    "strides": (lambda m: setattr(m.layout.dim[1], "stride", 1) or m, r"^layout\.dim: strides"),
    "offset": (lambda m: setattr(m.layout, "data_offset", 1) or m, r"^layout\.data_offset: 1"),
    "short data": (
        lambda m: setattr(m, "data", list(m.data)[:-1]) or m,
        r"^data: length 30, expected 31",
    ),
    "nan theta": (_set_data(3, NAN), r"^data: NaN at index 3"),
    "inf trace": (_set_data(-3, INF), r"^data \(trace_p\): Inf"),
    "fractional stamp": (_set_data(-1, 1.5), r"^data \(stamp_ns\): 1\.5"),
    "empty": (lambda m: Float64MultiArray(), r"^layout\.dim: expected 2"),
    "bad sizes": (
        lambda m: Float64MultiArray(
            layout=_layout(4, 5),
            data=[0.0] * 23,
        ),
        r"^layout\.dim: sizes \(4, 5\)",
    ),
}


def _layout(rows, cols):
    from std_msgs.msg import MultiArrayLayout

    return MultiArrayLayout(
        dim=[
            MultiArrayDimension(label="theta_rows", size=rows, stride=rows * cols),
            MultiArrayDimension(label="theta_cols", size=cols, stride=cols),
        ]
    )


@pytest.mark.parametrize("case", list(ESTIMATE_REJECTIONS))
def test_estimate_rejections_name_the_field(case):
    mutate, pattern = ESTIMATE_REJECTIONS[case]
    with pytest.raises(WireError, match=pattern):
        wire.msg_to_estimate(mutate(_estimate_msg()))


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        ((np.ones((2, 3)), np.ones((2, 1)), np.zeros(2)), r"^F: shape \(2, 3\)"),
        ((np.eye(2), np.ones((3, 1)), np.zeros(2)), r"^G: shape \(3, 1\)"),
        ((np.eye(2), np.ones((2, 1)), np.zeros(3)), r"^w: shape \(3,\)"),
        ((np.eye(2) * NAN, np.ones((2, 1)), np.zeros(2)), r"^F: NaN"),
        ((np.eye(2), np.ones((2, 1)) * INF, np.zeros(2)), r"^G: Inf"),
    ],
)
def test_estimate_to_msg_refuses_garbage(args, pattern):
    with pytest.raises(WireError, match=pattern):
        wire.estimate_to_msg(*args, 1.0, 1.0, stamp_ns=0)
    with pytest.raises(WireError, match=r"^residual_norm: NaN"):
        wire.estimate_to_msg(np.eye(2), np.ones((2, 1)), np.zeros(2), 1.0, NAN, stamp_ns=0)
