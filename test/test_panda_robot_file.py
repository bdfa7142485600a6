"""The shipped Panda robot file holds an unknown 5 lb payload, then tracks a move sent after
the hold, and tracks with every physical-arm effect on, through the robot interface (robot_sim
on MuJoCo, sim time, a few seconds each)."""

from __future__ import annotations

from apc_lab import robot_compare as rc


def test_the_panda_file_holds_then_tracks_a_move_after_the_hold(tmp_path, monkeypatch):
    # A hold of 1 s: long enough that a law identifying F and G on the hold's data winds up
    # (the recommended preset with P(0) = alpha I everywhere diverges after it); the 5 lb
    # payload the model does not know. Measured by bench/panda_holds.py.
    monkeypatch.setattr(rc, "HOLD_BEFORE_S", 1.0)
    case = rc.RobotCase("panda", "c", "ideal", rc.ROBOT_FILE_LAW)
    outcome = rc.run_case(case, tmp_path, timeout_s=60.0)
    assert outcome.ok, outcome.message
    assert rc.hold_error_deg(outcome.path) < 0.3  # measured 0.09
    metrics = rc.measure(outcome.path)
    assert max(metrics["max_error_deg"]) < 1.0  # measured 0.19
    assert max(metrics["final_error_deg"]) < 0.5  # measured 0.07


def test_the_panda_file_tracks_with_every_physical_arm_effect_on(tmp_path):
    """Friction, quantised positions differenced into velocity and the drive's one-cycle
    command delay (robot_sim's ``effects: panda``): the file runs the recommended preset as it
    is, its model prior following the set point (with the paper's prior the preset alone
    diverged in this case, 42 deg). Measured: max 0.20 deg, final 0.10 deg, the same in every
    run; computed torque 28.2 deg, PID 49.1 deg."""
    case = rc.RobotCase("panda", "a", "physical", rc.ROBOT_FILE_LAW)
    outcome = rc.run_case(case, tmp_path, timeout_s=60.0)
    assert outcome.ok, outcome.message
    metrics = rc.measure(outcome.path)
    assert max(metrics["max_error_deg"]) < 2.0
    assert max(metrics["final_error_deg"]) < 1.0
