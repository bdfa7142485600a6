"""``bench/report.py``: ``bench/results.md`` carries the wall-time table when
``results.json`` has the ``robot_clock`` part.

report.py is a bench script (it writes ``bench/results.md`` from ``bench/results.json``; its
command line takes no other paths), so it is imported from ``bench/``; the table itself is
:mod:`apc_lab.wall_clock`'s, tested with the package.
"""

from __future__ import annotations

import sys
from pathlib import Path

from apc_lab import wall_clock

BENCH = Path(__file__).resolve().parents[1] / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))


def _result(max_deg, final_deg, lost, handovers=0, failed=None) -> dict:
    return {
        "max_error_deg": max_deg,
        "final_error_deg": final_deg,
        "lost": lost,
        "failed": failed,
        "supervisor": {"supervisor.handovers": handovers, "supervisor.handbacks": handovers},
    }


def test_results_md_carries_the_table_when_results_json_has_the_part():
    import report  # bench/report.py

    runs = [_result([1.0, 0.25, 3.0], [0.1, 0.0, 0.4], False)]
    cell = {"arm": "puma3", "effects": "ideal", "rate_hz": 100.0, "law": "PID", "runs": runs}
    text = report.markdown(
        {"robot_clock": {"cells": [{**cell, "summary": wall_clock.aggregate_cell(runs)}]}}
    )
    assert "## Robot path on wall time" in text
    assert "| puma3 | ideal | 100 | PID | 0/1 / 0 | 1.00 0.25 3.00 |" in text
    assert "Robot path on wall time" not in report.markdown({})
