"""Per-sample compute, pure Python, for n = 3, 6, 7, 12 and 24 joints (no ROS).

For each arm (the PUMA 560 URDFs for n = 3 and 6, random serial chains built in Pinocchio for
the others; see ``benchlib.arm``) it times, over many repetitions of a batch of calls on
varied inputs, per call in microseconds:

- ``rls_update_us``     ``Rls.update(z, dx)`` (Eqs. 26, 29-31 with the trace guard)
- ``gain_us``           what ``AdaptiveFeedback`` does for Eq. 35: ``OneStepControl`` on the
                        identifier's Θᵀ view (preallocated, Cholesky solve)
- ``feedback_step_us``  ``AdaptiveFeedback.update`` (RLS + gain + bookkeeping), the whole
                        per-sample feedback, with the paper's settings
- ``recommended_step_us`` the same with the recommended preset (3-step receding horizon over
                        the model with two input lags and the integral, the RLS over them)
- ``rnea_us``           ``nominal_torque`` (Pinocchio RNEA + the finiteness check + copy),
                        the feedforward's per-sample cost; ``pin_rnea_us`` is the bare call
- ``plant_period_us``   ``Plant.step``: one period T = 10 ms, 4 RK4 steps of ABA (the default);
                        ``plant_period_crba_us`` the same with ``forward_dynamics="crba"``
                        (CRBA + nonlinear effects + solve, checked equal to rounding);
                        ``plant_acceleration_crba_us`` is one of the latter's 16 evaluations
                        and ``aba_us`` Pinocchio's ABA for the same acceleration

and fits the growth exponent in n (``time ~ c n^k`` over n = 3..24) next to Table 1's operation
counts (``config/reference/paper.json``, ``compute_cost_table1``).

    .venv/bin/python bench/compute.py [--quick] [--no-write]
"""

from __future__ import annotations

import argparse
import gc
import itertools
import json
import re
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import benchlib
import numpy as np

JOINTS = (3, 6, 7, 12, 24)


# ---------------------------------------------------------------------------------- Table 1
def _poly(expr: str, n: int) -> float:
    """Evaluate a Table 1 cell such as ``"30n^2 + 5n + 1"`` at ``n``."""
    total = 0.0
    for sign, coef, var, power in re.findall(r"([+-]?)\s*(\d*)\s*(n?)(?:\^(\d+))?", expr):
        if not coef and not var:
            continue
        value = float(coef or 1) * (n ** int(power or 1) if var else 1)
        total += -value if sign == "-" else value
    return total


def table1() -> dict[str, Any]:
    data = json.loads((benchlib.CONFIG / "reference" / "paper.json").read_text())
    return data["compute_cost_table1"]


def table1_ops(row: dict[str, str], n: int) -> float:
    """Multiplications plus additions of one Table 1 row at ``n``."""
    return _poly(row["mul"], n) + _poly(row["add"], n)


# ---------------------------------------------------------------------------------- timing
def calibrate(fn: Callable[[int], Any], target_s: float, k: int = 256) -> int:
    """Warm ``fn`` up and return the batch size that takes about ``target_s``."""
    for i in range(min(k, 32)):  # first-call effects, caches
        fn(i)
    t0 = time.perf_counter()
    calls = 0
    while time.perf_counter() - t0 < 0.005:
        fn(calls % k)
        calls += 1
    return max(3, min(2000, int(target_s * calls / (time.perf_counter() - t0))))


def time_interleaved(
    ops: dict[tuple[int, str], Callable[[int], Any]],
    reps: int,
    target_s: float = 0.002,
    k: int = 256,
) -> dict[tuple[int, str], tuple[list[float], int]]:
    """Per-call seconds of every operation: ``reps`` rounds, each timing one batch of every
    operation in turn, so that a change of machine load hits all of them alike.

    Batches are sized to take ~``target_s``; inputs cycle through ``k`` samples. The garbage
    collector stays on (as in a node); the median over rounds is robust to its pauses.
    """
    batches = {key: calibrate(fn, target_s, k) for key, fn in ops.items()}
    times: dict[tuple[int, str], list[float]] = {key: [] for key in ops}
    start = 0
    for _ in range(reps):
        for key, fn in ops.items():
            batch = batches[key]
            t0 = time.perf_counter()
            for i in range(start, start + batch):
                fn(i % k)
            times[key].append((time.perf_counter() - t0) / batch)
        start += 7
    return {key: (times[key], batches[key]) for key in ops}


class Inputs:
    """``k`` varied samples of a slow motion with small tracking errors, for ``n`` joints."""

    def __init__(self, robot: Any, k: int = 256, seed: int = 1) -> None:
        import pinocchio as pin

        rng = np.random.default_rng(seed)
        n = robot.n_joints
        t = np.arange(k)[:, None] * 0.01
        amp, freq = rng.uniform(0.2, 0.8, n), rng.uniform(0.2, 1.0, n)
        w = 2 * np.pi * freq
        self.q_d = amp * np.sin(w * t)
        self.qd_d = amp * w * np.cos(w * t)
        self.qdd_d = -amp * w**2 * np.sin(w * t)
        self.q = self.q_d + 1e-3 * rng.standard_normal((k, n))
        self.qd = self.qd_d + 1e-2 * rng.standard_normal((k, n))
        data = robot.model.createData()
        self.u_n = np.array(
            [
                pin.rnea(robot.model, data, self.q_d[i], self.qd_d[i], self.qdd_d[i])
                for i in range(k)
            ]
        )
        self.applied = self.u_n + rng.standard_normal((k, n))
        self.k = k


def setup_arm(n: int) -> tuple[dict[str, Any], dict[str, Callable[[int], Any]]]:
    """The arm's description and checks, and the operations to time: ``fn(i)`` on input i."""
    import pinocchio as pin

    from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
    from apc_feedback.optimal import OneStepControl
    from apc_feedback.rls import Rls
    from apc_feedforward.nominal import nominal_torque
    from apc_plant_sim.plant import Plant, PlantConfig

    robot, label = benchlib.arm(n)
    model = robot.model
    x = Inputs(robot)
    k = x.k
    config = AdaptiveConfig()
    out: dict[str, Any] = {"arm": label}
    ops: dict[str, Callable[[int], Any]] = {}

    # Feedback total: AdaptiveFeedback.update (its first call, Eq. 33, is excluded).
    law = AdaptiveFeedback(model, config)
    law.update(0, x.q[0], x.qd[0], x.q_d[0], x.qd_d[0], x.qdd_d[0], x.u_n[0], None)

    sample = itertools.count(1)  # consecutive sample numbers: every call identifies

    def feedback(i: int) -> None:
        k = next(sample)
        law.update(k, x.q[i], x.qd[i], x.q_d[i], x.qd_d[i], x.qdd_d[i], x.u_n[i], x.applied[i])

    ops["feedback_step_us"] = feedback

    # The recommended preset's step (what robot mode and the commands run by default).
    from apc_feedback.presets import recommended_settings

    recommended = AdaptiveFeedback(
        model, AdaptiveConfig.from_dict({**recommended_settings(), "period": 0.01})
    )
    recommended.update(0, x.q[0], x.qd[0], x.q_d[0], x.qd_d[0], x.qdd_d[0], x.u_n[0], None)
    recommended_sample = itertools.count(1)

    def recommended_step(i: int) -> None:
        k = next(recommended_sample)
        recommended.update(
            k, x.q[i], x.qd[i], x.q_d[i], x.qd_d[i], x.qdd_d[i], x.u_n[i], x.applied[i]
        )

    ops["recommended_step_us"] = recommended_step

    # RLS alone, on regressors like the law's.
    rls = law.rls
    dxs = [np.r_[x.q[i] - x.q_d[i], x.qd[i] - x.qd_d[i]] for i in range(k)]
    zs = [Rls.regressor(dxs[i - 1], x.applied[i - 1] - x.u_n[i - 1]) for i in range(k)]

    def rls_update(i: int) -> None:
        rls.update(zs[i], dxs[i])

    ops["rls_update_us"] = rls_update

    # Gain (Eq. 35) as the law computes it: on the identifier's Θᵀ view, no copies.
    one_step = OneStepControl(np.diag(law.Q), law.R, config.control_form)

    def gain(i: int) -> None:
        one_step(rls.model_view(), dxs[i])

    ops["gain_us"] = gain

    # Feedforward: nominal torque by RNEA.
    data = model.createData()

    def rnea(i: int) -> None:
        nominal_torque(model, data, x.q_d[i], x.qd_d[i], x.qdd_d[i])

    def bare_rnea(i: int) -> None:
        pin.rnea(model, data, x.q_d[i], x.qd_d[i], x.qdd_d[i])

    ops["rnea_us"] = rnea
    ops["pin_rnea_us"] = bare_rnea

    # Plant: one period (4 RK4 steps), reset to the sample's state so it never runs away.
    plant = Plant(robot, PlantConfig(period=0.010, step=0.0025), x.q_d[0])
    crba_plant = Plant(robot, PlantConfig(forward_dynamics="crba"), x.q_d[0])
    gravity = [pin.rnea(model, data, x.q_d[i], 0 * x.q_d[i], 0 * x.q_d[i]) for i in range(k)]

    def period_of(p: Plant) -> Callable[[int], None]:
        def period(i: int) -> None:
            p.q, p.qd = x.q_d[i], x.qd_d[i]
            p.step(gravity[i])

        return period

    ops["plant_period_us"] = period_of(plant)
    ops["plant_period_crba_us"] = period_of(crba_plant)
    steps = []
    for p in (plant, crba_plant):
        p.q, p.qd = x.q_d[1], x.qd_d[1]
        steps.append(p.step(gravity[1]))
    out["aba_matches_crba_abs_err"] = float(
        f"{max(np.abs(steps[0].q - steps[1].q).max(), np.abs(steps[0].qd - steps[1].qd).max()):.2g}"
    )

    def acceleration(i: int) -> None:
        crba_plant.acceleration(x.q_d[i], x.qd_d[i], gravity[i])

    def aba(i: int) -> None:
        pin.aba(model, data, x.q_d[i], x.qd_d[i], gravity[i])

    ops["plant_acceleration_crba_us"] = acceleration
    ops["aba_us"] = aba

    return out, ops


def fit(per_n: dict[int, dict[str, Any]], ns: Sequence[int]) -> dict[str, Any]:
    """Growth exponents of the measured times and of Table 1's operation counts over ``ns``."""
    t1 = table1()
    rows = {
        "rnea_us": ("newton_euler",),
        "pin_rnea_us": ("newton_euler",),
        "rls_update_us": ("rls",),
        "gain_us": ("control",),
        "feedback_step_us": ("rls", "control"),
        "plant_period_us": (),
        "plant_period_crba_us": (),
    }
    out: dict[str, Any] = {}
    for key, table_rows in rows.items():
        times = [per_n[n][key]["median"] for n in ns]
        entry: dict[str, Any] = {"measured_exponent": benchlib.growth_exponent(ns, times)}
        top = [n for n in ns if n >= 12]
        if len(top) >= 2:  # the local slope where fixed per-call costs matter least
            entry["measured_exponent_n12_24"] = benchlib.growth_exponent(
                top, [per_n[n][key]["median"] for n in top]
            )
        if table_rows:
            ops = [sum(table1_ops(t1[r], n) for r in table_rows) for n in ns]
            entry["table1_rows"] = list(table_rows)
            entry["table1_ops"] = {str(n): int(o) for n, o in zip(ns, ops, strict=True)}
            entry["table1_exponent"] = benchlib.growth_exponent(ns, ops)
            entry["ns_per_table1_op"] = {
                str(n): round(1e3 * t / o, 2) for n, t, o in zip(ns, times, ops, strict=True)
            }
        out[key] = entry
    return out


def paper_comparison(per_n: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """One set point at n = 3 (feedforward RNEA + feedback) against the PDP-11/45's 7.5 ms."""
    t1 = table1()
    pdp_ms = float(t1["pdp11_45_ms_per_setpoint_n3"])
    ours_us = per_n[3]["rnea_us"]["median"] + per_n[3]["feedback_step_us"]["median"]
    ops = sum(table1_ops(t1[r], 3) for r in ("newton_euler", "rls", "control"))
    return {
        "paper_pdp11_45_ms_per_setpoint_n3": pdp_ms,
        "ours_us_per_setpoint_n3": round(ours_us, 1),
        "speedup": round(1e3 * pdp_ms / ours_us),
        "table1_ops_n3": int(ops),
        "pdp11_us_per_op": round(1e3 * pdp_ms / ops, 2),
        "ours_ns_per_op": round(1e3 * ours_us / ops, 1),
        "note": "ours = rnea_us + feedback_step_us medians at n = 3 (plant excluded)",
    }


def run(quick: bool = False, joints: Sequence[int] = JOINTS) -> dict[str, Any]:
    reps = 30 if quick else 100
    per_n: dict[int, dict[str, Any]] = {}
    ops: dict[tuple[int, str], Callable[[int], Any]] = {}
    for n in joints:
        per_n[n], arm_ops = setup_arm(n)
        ops.update({(n, key): fn for key, fn in arm_ops.items()})
    gc.collect()
    t0 = time.monotonic()
    timed = time_interleaved(ops, reps)
    for (n, key), (values, batch) in timed.items():
        per_n[n][key] = {**benchlib.stats(1e6 * np.asarray(values), 3), "calls_per_rep": batch}
    for n in joints:
        benchlib.progress(
            f"compute n={n}: feedback {per_n[n]['feedback_step_us']['median']:.1f} us "
            f"(recommended preset {per_n[n]['recommended_step_us']['median']:.1f} us), "
            f"rnea {per_n[n]['rnea_us']['median']:.2f} us, plant period "
            f"{per_n[n]['plant_period_us']['median']:.0f} us"
        )
    benchlib.progress(f"compute: {len(ops)} operations x {reps} rounds in "
                      f"{time.monotonic() - t0:.1f} s")  # fmt: skip
    keys = [k for k, v in per_n[joints[0]].items() if isinstance(v, dict)]
    result: dict[str, Any] = {
        key: {str(n): per_n[n][key] for n in joints} for key in keys
    }  # feedback_step_us: {"3": {...}, ...}
    result["compute_arms"] = {str(n): per_n[n]["arm"] for n in joints}
    result["aba_matches_crba_abs_err"] = {
        str(n): per_n[n]["aba_matches_crba_abs_err"] for n in joints
    }
    if len(joints) >= 2:
        result["growth_exponent"] = fit(per_n, joints)
    if 3 in per_n:
        result["paper_comparison"] = paper_comparison(per_n)
    result["compute_settings"] = {
        "repetitions": reps,
        "unit": "microseconds per call; median over repetitions of a batch (calls_per_rep)",
        "feedback_config": "AdaptiveConfig() defaults (paper weights, exact Eq. 35, trace guard)",
    }
    return result


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--joints", type=int, nargs="+", default=list(JOINTS))
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    benchlib.emit(run(args.quick, tuple(args.joints)), "compute", t0, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
