"""The watchdog's hold torque, told commands, never a clock."""

from __future__ import annotations

import numpy as np
import pytest

from apc_feedback.hold_torque import HOLD_MEAN_S, HoldTorque

GRAVITY = np.array([10.0, -3.0])


def test_gravity_alone_before_a_command_and_after_a_reset():
    hold = HoldTorque(0.01)
    assert hold.torque(GRAVITY).tolist() == GRAVITY.tolist()
    hold.sent(GRAVITY + 2.0, GRAVITY)
    assert hold.torque(GRAVITY).tolist() == (GRAVITY + 2.0).tolist()
    hold.reset()
    assert hold.torque(GRAVITY).tolist() == GRAVITY.tolist()


def test_the_added_torque_is_averaged_over_its_time_constant():
    """A step in what the controllers add reaches 1 - 1/e of it after HOLD_MEAN_S (to the
    discrete average's accuracy); a non-finite command teaches nothing."""
    period = 0.001
    hold = HoldTorque(period)
    hold.sent(GRAVITY, GRAVITY)  # nothing added
    for _ in range(round(HOLD_MEAN_S / period)):
        hold.sent(GRAVITY + np.array([1.0, -1.0]), GRAVITY)
    added = hold.torque(np.zeros(2))
    assert added == pytest.approx([1.0 - np.exp(-1.0), np.exp(-1.0) - 1.0], abs=2e-3)
    hold.sent(np.array([np.nan, 0.0]), GRAVITY)
    assert hold.torque(np.zeros(2)).tolist() == added.tolist()
    with pytest.raises(ValueError, match="period"):
        HoldTorque(0.0)
