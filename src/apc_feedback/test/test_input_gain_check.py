"""The identified input gain's check (``project_g``), on its own."""

import numpy as np
import pytest

from apc_feedback.input_gain_check import RELATIVE_GAIN_FLOOR, velocity_gain_physical

PRIOR = np.array([1.0, 2.0])


def test_a_gain_that_pushes_a_joint_the_wrong_way_is_refused_with_or_without_a_prior():
    assert velocity_gain_physical(np.array([1.0, 2.0]), None, None)
    assert not velocity_gain_physical(np.array([1.0, -1e-9]), None, None)
    assert not velocity_gain_physical(np.array([0.0, 2.0]), PRIOR, PRIOR.copy())


def test_an_entry_may_not_fall_under_the_floor_of_the_set_points_prior():
    floor = RELATIVE_GAIN_FLOOR * PRIOR
    before = PRIOR.copy()
    assert velocity_gain_physical(1.01 * floor, PRIOR, before)
    assert not velocity_gain_physical(np.array([0.99 * floor[0], 2.0]), PRIOR, before)


def test_an_entry_under_the_floor_may_climb_and_one_under_half_of_it_may_move_freely():
    floor = RELATIVE_GAIN_FLOOR * PRIOR
    # Under the floor (the set point moved): it may climb, not fall further.
    before = 0.8 * floor
    assert velocity_gain_physical(0.9 * floor, PRIOR, before)
    assert not velocity_gain_physical(0.7 * floor, PRIOR, before)
    # Under half of it (put there from outside): anything positive.
    before = 0.4 * floor
    assert velocity_gain_physical(0.1 * floor, PRIOR, before)


def test_a_step_judged_against_its_diagonal_before_needs_the_prior():
    with pytest.raises(ValueError, match="prior"):
        velocity_gain_physical(PRIOR, None, PRIOR)
