"""The robot path on wall time (``bench/robot_clock.py``'s analysis) on synthetic runs: errors,
the loss rule, the cells, the table and the processes' parameters (the benchmark itself runs on
wall time: not here)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from apc_lab import wall_clock
from apc_plant_sim.effects import puma560_effects

T_NS = 10_000_000  # 10 ms sample grid
K0 = 1_000  # the first sample's index: stamps are kT on the driver's (system) clock


def _run(
    errors_deg: dict[int, list[float]], moving: range, samples: range
) -> tuple[dict, dict, dict]:
    """Two joints at 0.3 rad planned; sample k measured off by ``errors_deg[k]`` (deg);
    set points move (velocity 1 rad/s) at the samples in ``moving``."""
    q, q_d, qd_d = {}, {}, {}
    for k in samples:
        stamp = (K0 + k) * T_NS
        q_d[stamp] = [0.3, -0.3]
        qd_d[stamp] = [1.0, 0.0] if k in moving else [0.0, 0.0]
        off = np.deg2rad(errors_deg.get(k, [0.0, 0.0]))
        q[stamp] = [0.3 + off[0], -0.3 - off[1]]
    return q, q_d, qd_d


def test_errors_span_the_move_from_the_sample_before_it_to_its_planned_end():
    # Hold 0-4, move 5-14 (0.1 s from sample 4), hold after to 19.
    errors = {2: [3.0, 0.0], 4: [0.5, 0.25], 9: [2.0, 1.0], 14: [0.1, 0.2], 18: [4.0, 0.0]}
    q, q_d, qd_d = _run(errors, range(5, 14), range(20))
    out = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert out["started"] and out["completed"] and out["samples"] == 20
    # Sample 2 (before the move) and 18 (after its end) are outside the move's window ...
    assert out["max_error_deg"] == pytest.approx([2.0, 1.0])
    assert out["final_error_deg"] == pytest.approx([0.1, 0.2])  # sample 14 = 4 + 10
    # ... but not outside the run's.
    assert out["run_max_error_deg"] == pytest.approx([4.0, 1.0])
    assert not wall_clock.is_lost(out) and out["beyond_limit_at_s"] is None
    assert wall_clock.run_errors(q, q_d, qd_d, T_NS, 0.1, limit_deg=2.5)[
        "beyond_limit_at_s"
    ] == pytest.approx(-0.02)  # sample 2, in the hold before the move


def test_a_run_is_lost_beyond_ten_degrees_anywhere_or_when_its_move_end_is_never_sampled():
    q, q_d, qd_d = _run({17: [0.0, 10.5]}, range(5, 14), range(20))
    after_the_move = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert after_the_move["max_error_deg"] == pytest.approx([0.0, 0.0])
    assert wall_clock.is_lost(after_the_move)
    assert after_the_move["beyond_limit_at_s"] == pytest.approx(0.13)  # sample 17 - 4

    q, q_d, qd_d = _run({}, range(5, 14), range(12))  # samples stop before the move's end
    cut = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert cut["started"] and not cut["completed"] and cut["final_error_deg"] is None
    assert wall_clock.is_lost(cut)

    q, q_d, qd_d = _run({}, range(0), range(12))  # the goal never arrived
    still = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert not still["started"] and wall_clock.is_lost(still)

    assert wall_clock.is_lost(wall_clock.run_errors({}, {}, {}, T_NS, move_s=0.1))


def test_a_non_finite_position_is_an_infinite_error_and_loses_the_run():
    q, q_d, qd_d = _run({}, range(5, 14), range(20))
    q[(K0 + 16) * T_NS] = [math.nan, -0.3]
    out = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert out["run_max_error_deg"][0] == math.inf and wall_clock.is_lost(out)


def test_exactly_ten_degrees_is_not_lost():
    q, q_d, qd_d = _run({9: [10.0, 0.0]}, range(5, 14), range(20))
    out = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert out["max_error_deg"][0] == pytest.approx(10.0)
    assert not wall_clock.is_lost({**out, "run_max_error_deg": [10.0, 0.0]})
    assert wall_clock.is_lost({**out, "run_max_error_deg": [10.001, 0.0]})


def test_supervisor_counts_read_every_integer_supervisor_key_and_default_to_zero():
    assert wall_clock.supervisor_counts({"samples_taken": "250", "watchdog": "0"}) == {
        "supervisor.handovers": 0,
        "supervisor.handbacks": 0,
    }
    values = {
        "supervisor.handovers": "2",
        "supervisor.tracking_error": "1",
        "supervisor.active_law": "pid",  # a state, not a counter
        "missed_samples": "3",
    }
    assert wall_clock.supervisor_counts(values) == {
        "supervisor.handovers": 2,
        "supervisor.handbacks": 0,
        "supervisor.tracking_error": 1,
    }


def _result(max_deg, final_deg, lost, handovers=0, failed=None) -> dict:
    return {
        "max_error_deg": max_deg,
        "final_error_deg": final_deg,
        "lost": lost,
        "failed": failed,
        "supervisor": {"supervisor.handovers": handovers, "supervisor.handbacks": handovers},
    }


def test_a_cell_takes_the_worst_joint_over_runs_counts_lost_and_ignores_failed_runs():
    runs = [
        {**_result([1.0, 0.2, 3.0], [0.1, 0.0, 0.4], False), "robot_node_counters": {"stale": 2}},
        {
            **_result([0.5, 0.9, 12.0], [0.3, 0.0, 0.1], True, handovers=1),
            "robot_node_counters": {"missed_samples": 1, "stale": 1, "samples_taken": 300},
        },
        _result([0.7, 0.1, 2.0], None, True),  # move not finished: no final error
        {"failed": "timed out after 60 s waiting for robot_node's topics", "lost": None},
    ]
    cell = wall_clock.aggregate_cell(runs)
    assert cell["runs"] == 4 and cell["failed"] == 1 and cell["lost"] == 2
    assert cell["worst_max_error_deg"] == pytest.approx([1.0, 0.9, 12.0])
    assert cell["worst_final_error_deg"] == pytest.approx([0.3, 0.0, 0.4])
    assert cell["supervisor"] == {"supervisor.handovers": 1, "supervisor.handbacks": 1}
    assert cell["timing_faults"] == {
        "missed_samples": 1,
        "missed_setpoint": 0,
        "stale": 3,
        "watchdog": 0,
    }
    assert cell["other_cores_max"] is None  # no run said how busy the machine was
    assert cell["steal_cores_max"] is None
    runs[0]["machine_load"] = {"other_cores": 0.3, "steal_cores": 0.6}
    runs[1]["machine_load"] = {"other_cores": 0.9, "steal_cores": 0.1}
    loaded = wall_clock.aggregate_cell(runs)
    assert loaded["other_cores_max"] == 0.9 and loaded["steal_cores_max"] == 0.6

    nothing = wall_clock.aggregate_cell([runs[3]])
    assert nothing["worst_max_error_deg"] is None and nothing["lost"] == 0


def test_the_table_names_the_machine_the_clock_and_each_cell():
    runs = [
        _result([1.0, 0.25, 3.0], [0.1, 0.0, 0.4], False, handovers=2),
        {"failed": "robot_node refused to activate", "lost": None},
    ]
    result = {
        "machine": {"cpu": "Test CPU 9000", "cores": 2},
        "machine_load": {"other_cores": 0.4, "steal_cores": 0.05},
        "load_average_before": [1.0, 1.0, 1.0],
        "load_average_after": [1.5, 1.0, 1.0],
        "cells": [
            {
                "arm": "puma3",
                "effects": "physical",
                "rate_hz": 250.0,
                "law": "adaptive recommended",
                "summary": wall_clock.aggregate_cell(runs),
                "runs": runs,
            }
        ],
    }
    text = wall_clock.markdown(result)
    assert "Wall time" in text and "Test CPU 9000, 2 cores" in text and "0.4 cores" in text
    assert "the hypervisor took 0.05 (steal" in text
    row = "| puma3 | physical | 250 | adaptive recommended | 0/2 / 1 | 1.00 0.25 3.00 "
    assert row + "| 0.10 0.00 0.40 | 2 / 2 | - | 0 / 0 / 0 / 0 | - / - |" in text
    assert "puma3 physical 250 Hz adaptive recommended run 2: robot_node refused" in text


def test_the_plan_covers_every_rate_arm_effect_and_law():
    cells = wall_clock.plan(
        wall_clock.ARMS, wall_clock.EFFECTS, wall_clock.RATES_HZ, tuple(wall_clock.LAWS)
    )
    # three laws everywhere; the robot file's own law adds none: both files run the preset
    assert len(cells) == len(set(cells)) == 4 * 2 * 2 * 3
    assert {c[2] for c in cells} == {100.0, 250.0, 500.0, 1000.0}
    assert not any(c[3] == wall_clock.ROBOT_FILE_LAW for c in cells)


def test_every_robot_file_runs_the_recommended_preset_as_it_is():
    """One preset for every arm: no robot file sets an ``adaptive.*`` value of its own."""
    from apc_lab import robot_compare as rc

    for arm in wall_clock.ARMS:
        assert wall_clock.robot_file_overrides(arm) == {}
        assert rc.robot_file_law(arm) == rc.LAWS["adaptive recommended"]


def test_the_adaptive_law_runs_the_preset_not_the_robot_files_per_arm_override(
    tmp_path, monkeypatch
):
    """A robot file with an ``adaptive.*`` value of its own (a user's): the benchmark's
    ``adaptive recommended`` puts it back on the preset; the robot file's law keeps it."""
    import yaml

    from apc_feedback.presets import PRESETS
    from apc_lab import robot_compare as rc
    from apc_lab.experiment import law_parameters
    from apc_lab.scenario import CONFIG_DIR

    params = yaml.safe_load((CONFIG_DIR / rc.ROBOT_FILES["panda"]).read_text())
    params["robot_node"]["ros__parameters"]["adaptive.q_velocity"] = 10.0
    own = tmp_path / "panda_own.yaml"
    own.write_text(yaml.safe_dump(params))
    monkeypatch.setitem(rc.ROBOT_FILES, "panda", str(own))
    preset = law_parameters("adaptive", PRESETS["recommended"]())["adaptive.q_velocity"]
    assert preset != 10.0  # the file's own value
    args = wall_clock.controller_arguments("panda", "adaptive recommended", "physical")
    assert f"robot_node:adaptive.q_velocity:={preset!r}" in args
    assert 'robot_node:controller:="adaptive"' in args
    assert "robot_node:autostart:=false" in args and "robot_node:path_tolerance:=[0.0]" in args
    shipped = wall_clock.controller_arguments("panda", wall_clock.ROBOT_FILE_LAW, "physical")
    assert not any("adaptive." in a for a in shipped)  # the file's own values stand
    pid = wall_clock.controller_arguments("panda", "PID", "physical")
    assert 'robot_node:controller:="pid"' in pid
    assert not any("adaptive." in a for a in pid)
    assert not any("armature" in a for a in pid)  # the Panda's drives add none


def test_a_physical_arm_s_rotor_inertia_is_told_to_every_law():
    """The physical PUMA's drives add G^2 Jm at each joint (robot_sim's ``puma560``); every
    law's controllers are told it, as its user configures a geared arm; the ideal arm none."""
    rotor = [round(v, 3) for v in puma560_effects().armature_kgm2]
    for law in ("computed torque", "PID", "adaptive recommended"):
        args = wall_clock.controller_arguments("puma3", law, "physical")
        told = [a for a in args if a.startswith("robot_node:armature:=")]
        assert len(told) == 1, args
        assert [round(v, 3) for v in json.loads(told[0].split(":=", 1)[1])] == rotor
        assert not any(
            "armature" in a for a in wall_clock.controller_arguments("puma3", law, "ideal")
        )


def test_robot_sim_runs_case_c_on_wall_time_at_the_cells_rate():
    puma = wall_clock.robot_sim_parameters("puma3", "physical", 250.0)
    assert puma["state_rate"] == 250.0 and puma["sim_time"] is False
    assert puma["engine"] == "mujoco" and puma["effects"] == "puma560"
    assert puma["payload.mass_kg"] == pytest.approx(5 * 0.45359237)  # 5 lb
    assert puma["payload.frame"] == "wrist_center" and puma["payload.at_s"] == 0.0
    panda = wall_clock.robot_sim_parameters("panda", "ideal", 1000.0)
    assert panda["effects"] == "ideal" and panda["state_rate"] == 1000.0
    assert panda["sim_cycles_per_command"] == 10
    # the ideal arm's driver publishes positions only, as the offline grid's; a drive its own
    assert panda["publish_velocity"] is False and puma["publish_velocity"] is True
    # a physical arm's drive velocity on request (one that measures it); the ideal arm's none
    assert "velocity_source" not in puma
    measured = wall_clock.robot_sim_parameters("panda", "physical", 250.0, "exact")
    assert measured["velocity_source"] == "exact" and measured["effects"] == "panda"
    ideal = wall_clock.robot_sim_parameters("panda", "ideal", 250.0, "exact")
    assert "velocity_source" not in ideal and ideal["publish_velocity"] is False


def test_a_missed_sample_at_the_moves_end_leaves_the_final_error_at_the_one_before():
    q, q_d, qd_d = _run({13: [0.5, 0.0], 14: [9.0, 0.0]}, range(5, 14), range(20))
    for table in (q, q_d, qd_d):
        del table[(K0 + 14) * T_NS]
    out = wall_clock.run_errors(q, q_d, qd_d, T_NS, move_s=0.1)
    assert out["completed"] and out["final_error_deg"] == pytest.approx([0.5, 0.0])
