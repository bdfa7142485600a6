"""analyze: metrics read from a recording equal those of the same run computed offline."""

from __future__ import annotations

import json

import numpy as np
import pytest

from apc_lab.analyze import analyze_file, main
from apc_lab.experiment import RunSpec, run_in_process
from apc_lab.metrics import compute_metrics, tip_lever_arms
from apc_lab.scenario import build, paper_scenario, run_offline

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    spec = RunSpec(paper_scenario("c", hold_s=0.3), "computed_torque", name="ct_c")
    outcome = run_in_process(spec, tmp_path_factory.mktemp("runs"), progress=False)
    assert outcome.ok, outcome.message
    return spec, outcome.path


def test_metrics_from_the_recording_equal_the_offline_run(recording):
    spec, path = recording
    offline = run_offline(spec.scenario, "computed_torque")
    expected = compute_metrics(
        offline.joint_names,
        offline.q,
        offline.q_d,
        np.vstack([offline.applied[:-1], np.full((1, 3), np.nan)]),
        spec.scenario.move_end_sample,
        robot=build(spec.scenario).plant_robot,
    )
    got = analyze_file(path)
    for key, value in expected.as_dict().items():
        if isinstance(value, list) and value and isinstance(value[0], float):
            np.testing.assert_allclose(got[key], value, rtol=1e-12, err_msg=key)
    assert got["controller"] == "computed_torque" and got["samples"] == 131


def test_tip_lever_is_the_distance_from_each_axis_to_the_wrist():
    """At the stretched pose joint 2's lever is the full reach a2 + d4 (with the a3 offset)."""
    robot = build(paper_scenario("a")).plant_robot
    lever = tip_lever_arms(robot, np.deg2rad([[45.0, 0.0, -90.0]]))[0]
    assert lever[1] == pytest.approx(np.hypot(0.4318 + 0.4318, 0.0203), abs=1e-3)
    assert lever[2] == pytest.approx(np.hypot(0.4318, 0.0203), abs=1e-3)


def test_a_recording_carries_the_arms_urdf_and_its_tip_without_a_stored_scenario(
    recording, monkeypatch
):
    """The plant publishes its URDF on robot_description (transient local) and the recorder
    keeps it: a recording made by the separate nodes, with no run description stored, still
    gives the tip displacement, the same as with the scenario."""
    from apc_recording import runs as rec
    from apc_recording.runs import load_run

    _, path = recording
    assert load_run(path).robot_description.lstrip().startswith("<")
    with_scenario = analyze_file(path)
    monkeypatch.setattr(rec, "_custom_run", lambda path: {})  # as the separate nodes record
    bare = analyze_file(path)
    assert np.isfinite(bare["max_tip_mm"]).all()
    assert bare["max_tip_mm"] == pytest.approx(with_scenario["max_tip_mm"], rel=1e-9)


def test_cli_json_and_errors(recording, capsys, tmp_path):
    _, path = recording
    assert main(["--json", str(path)]) == 0
    out = json.loads(capsys.readouterr().out)
    run = out["runs"][0]
    assert run["joints"] == ["joint_1", "joint_2", "joint_3"]
    assert len(run["max_error_deg"]) == len(run["final_error_deg"]) == 3
    assert main([str(path)]) == 0
    assert "| ct_c | joint_3 |" in capsys.readouterr().out
    assert main([str(tmp_path / "missing.mcap")]) == 2
    assert "missing.mcap" in capsys.readouterr().err


def test_report_writes_markdown_and_figures(recording, tmp_path):
    _, path = recording
    assert main([str(path), "--report", str(tmp_path / "rep")]) == 0
    report = (tmp_path / "rep" / "report.md").read_text()
    assert "| ct_c | joint_1 |" in report
    for png in ("errors.png", "torques.png"):
        data = (tmp_path / "rep" / png).read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 10_000
