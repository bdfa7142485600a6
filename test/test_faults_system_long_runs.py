"""Long runs, offline: moves, holds and payload changes stay bounded with the RLS guard, and
the printed, unguarded RLS winds up during a long hold (:mod:`apc_lab.long_run`).

What is measured is printed (``pytest -s``) and quoted in docs/reliability.md. (Faults of the
node processes: ``test_faults_system.py``; a lossy network: ``test_faults_system_network.py``.)
"""

from __future__ import annotations

import pytest
from support.report import report

from apc_lab.long_run import CONFIGS, POSES_DEG, Schedule, run_long

T = 0.010  # the sampling period (s)


@pytest.mark.slow
def test_long_run_stays_bounded():
    """150 s of moves, holds (up to 20 s) and payload changes, offline (apc_lab.long_run).

    With the guard (the default): every sample finite, trace(P) <= trace(P(0)), no refused
    update, errors bounded. The printed Q = 0.1 I cannot hold a payload against gravity (README:
    the error builds up over a hold), so its bound is loose; a position-weighted Q holds it within
    a few degrees. Without the guard, a 20 s hold without excitation winds trace(P) up like
    rho^-k, past 1e18.
    """
    seconds = 150.0
    bounds_deg = {"guarded": 100.0, "guarded_qpos": 6.0}  # measured: ~80 and ~2.8 (see README)
    for name, bound in bounds_deg.items():
        r = run_long(CONFIGS[name], seconds, segment_s=60.0)
        report(
            f"long run {name} ({seconds:g} s)",
            wall_s=r["wall_s"],
            moves=r["moves"],
            payload_changes=r["payload_changes"],
            max_trace_p=r["max_trace_p"],
            rejected=r["rejected_updates"],
            max_error_deg=r["max_error_deg"],
        )
        assert r["finite"] and r["diverged_at_s"] is None, name
        assert r["samples"] == round(seconds / T) + 1
        assert r["moves"] >= 20 and r["payload_changes"] >= 5
        assert r["max_trace_p"] <= r["trace_p0"] * (1 + 1e-9), name
        assert r["rejected_updates"] == 0, name
        worst = max(max(r["max_error_deg"]["move"]), max(r["max_error_deg"]["hold"]))
        assert worst <= bound, (name, r["max_error_deg"])

    # The printed RLS on the same schedule: P winds up and loses definiteness, so updates are
    # refused. Whether the arm is then lost within these 150 s depends on rounding, which
    # differs between x86-64 machines running the same wheels (lost on one, a 1.1 deg worst
    # hold on another), so only the wind-up is asserted; the error is reported.
    r = run_long(CONFIGS["paper_qpos"], seconds, segment_s=60.0)
    report(
        "long run paper_qpos (no guard)",
        diverged_at_s=r["diverged_at_s"],
        rejected=r["rejected_updates"],
        max_trace_p=r["max_trace_p"],
        max_error_deg=r["max_error_deg"],
    )
    assert r["rejected_updates"] > 0 and r["max_trace_p"] > 1e12

    # One move and a 20 s hold without payload (no excitation), with and without the guard.
    hold = Schedule(poses_deg=POSES_DEG[:2], holds_s=(20.0,), payloads_kg=(0.0,))
    unguarded = run_long(CONFIGS["paper"], 20.9, schedule=hold, segment_s=5.0)
    guarded = run_long(CONFIGS["guarded"], 20.9, schedule=hold, segment_s=5.0)
    trace_by_5s = [s["max_trace_p"] for s in unguarded["segments"]]
    report(
        "20 s hold, trace(P) per 5 s",
        unguarded=trace_by_5s,
        unguarded_rejected=unguarded["rejected_updates"],
        guarded_max=guarded["max_trace_p"],
        guarded_rejected=guarded["rejected_updates"],
    )
    # trace(P) winds up past 1e18 whatever the rounding (measured 1.9e20-3.8e20 with alpha
    # perturbed by 0, +-1e-12, 1e-9); whether P then loses definiteness, so that updates are
    # refused, depends on the rounding (0 or ~780 refused updates in the same four runs).
    assert unguarded["max_trace_p"] > 1e18
    assert trace_by_5s[1] > 1e3 * trace_by_5s[0]  # grows like rho^-k (0.95^-500 = 1e11)
    assert guarded["max_trace_p"] <= guarded["trace_p0"] * (1 + 1e-9)
    assert guarded["rejected_updates"] == 0
    # Either way the last good estimate keeps the arm where it is while nothing moves.
    for r in (unguarded, guarded):
        assert r["finite"] and max(r["max_error_deg"]["hold"]) < 1.0, r["max_error_deg"]


@pytest.mark.slow
def test_five_minutes_with_the_recommended_preset_stays_bounded():
    """Five minutes of simulated time (30,000 samples) of moves, holds up to 20 s and payload
    changes (0-5 lb, picked up at the start of moves), offline, with the recommended preset:
    every sample finite, trace(P) never above trace(P(0)), no refused RLS update, tracking
    error bounded. The schedule repeats every 18 moves (six holds against three payloads held
    for three moves each, about 105 s), so five minutes run every hold with every payload
    almost three times. The whole hour takes 2-4 minutes, too long for the suite:
    ``bench/long_run.py --config recommended`` runs it (measured: 618 moves, 205 payload steps,
    worst 0.30 deg during a move, 0.06 deg holding).
    """
    r = run_long(CONFIGS["recommended"], 300.0, segment_s=100.0)
    report(
        "five minutes, recommended",
        wall_s=r["wall_s"],
        moves=r["moves"],
        payload_changes=r["payload_changes"],
        max_trace_p=r["max_trace_p"],
        rejected=r["rejected_updates"],
        max_error_deg=r["max_error_deg"],
    )
    assert r["samples"] == 30_001
    assert r["moves"] >= 50 and r["payload_changes"] >= 15
    assert r["finite"] and r["diverged_at_s"] is None
    assert r["max_trace_p"] <= r["trace_p0"] * (1 + 1e-9)
    assert r["rejected_updates"] == 0
    assert max(max(r["max_error_deg"]["move"]), max(r["max_error_deg"]["hold"])) < 1.0
