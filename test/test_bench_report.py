"""``bench/report.py``: ``results.md`` carries the wall-time table when ``results.json`` has the
``robot_clock`` part (the script run as a user runs it, on files of its own; the table itself is
:mod:`apc_lab.wall_clock`'s, tested with the package)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from apc_lab import wall_clock

REPORT = Path(__file__).resolve().parents[1] / "bench" / "report.py"


def _result(max_deg, final_deg, lost, handovers=0, failed=None) -> dict:
    return {
        "max_error_deg": max_deg,
        "final_error_deg": final_deg,
        "lost": lost,
        "failed": failed,
        "supervisor": {"supervisor.handovers": handovers, "supervisor.handbacks": handovers},
    }


def test_results_md_carries_the_table_when_results_json_has_the_part(tmp_path):
    runs = [_result([1.0, 0.25, 3.0], [0.1, 0.0, 0.4], False)]
    cell = {"arm": "puma3", "effects": "ideal", "rate_hz": 100.0, "law": "PID", "runs": runs}
    results = {"robot_clock": {"cells": [{**cell, "summary": wall_clock.aggregate_cell(runs)}]}}
    (tmp_path / "results.json").write_text(json.dumps(results))
    md = tmp_path / "results.md"
    done = subprocess.run(
        [sys.executable, str(REPORT), "--json", str(tmp_path / "results.json"), "--md", str(md)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    text = md.read_text()
    assert "## Robot path on wall time" in text
    assert "| puma3 | ideal | 100 | PID | 0/1 / 0 | 1.00 0.25 3.00 |" in text
