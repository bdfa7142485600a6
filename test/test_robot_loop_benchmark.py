"""``bench/robot_loop.py`` itself: a 1 s run of both layouts over DDS, through its command line.

Its analysis is :mod:`apc_lab.loop_timing`'s, tested on synthetic records with the package
(``src/apc_lab/test/test_loop_timing.py``); here the script starts ``robot_sim`` and
``robot_node`` as a user of the benchmark would and prints its figures as JSON on stdout.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from apc_lab.loop_timing import LAYOUTS

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.ros
def test_one_second_run_of_both_layouts_gives_the_figures():
    cmd = [sys.executable, str(REPO / "bench" / "robot_loop.py")]
    cmd += ["--seconds", "1", "--runs", "1", "--no-write"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout)["robot_loop"]
    for layout in LAYOUTS:
        r = out[layout]
        for key in (
            "late_fraction",
            "latency_us",
            "state_age_at_sample_us",
            "sample_to_arrival_us",
        ):
            assert r[key] is not None, (layout, key)
        # How many of the 1000 cycles a loaded machine keeps is the benchmark's figure, not a
        # pass mark: here the run only has to produce its figures.
        assert r["cycles"] > 0 and r["commands_matched"] > 0, r
        assert r["latency_us"]["n"] == r["commands_matched"]
    assert "settings" in out
