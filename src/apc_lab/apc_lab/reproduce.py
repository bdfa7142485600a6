"""Reproduce the paper's experiment through the real nodes, and go beyond it (``make run``).

Every run goes through plant, feedforward, feedback and recorder over DDS in lockstep
(:func:`apc_lab.experiment.run_in_process`) and is recorded to MCAP; the report is made
from the recordings only. Runs:

- **table2**: cases (a) no load, (b) 1.134 kg, (c) 2.268 kg (5 lb), each with +-10 % inertia
  error in the controllers, for computed torque (Kp = 100, Kv = 20) and adaptive control with
  P1(0) = 1500 I and P2(0) = 150000 I under both presets (``paper``, ``recommended``);
- **trajectory2**: the paper's second trajectory (same start, another end), case (c);
- **sweep**: payloads 0-5 lb in 1 lb steps, the worst maximum error of each controller;
- **pickup**: the 5 lb payload picked up at t = 0.5 s, and the samples needed to recover;
- **puma6**: the full six-joint PUMA 560 with a six-joint move and 5 lb;
- **panda**: Franka Panda from the ``example-robot-data`` package (fingers locked), 5 lb;
- **robot**: through the robot interface (ros2_control's, :mod:`apc_lab.robot_compare`):
  the 3-joint PUMA and the Panda on the simulated robot (MuJoCo), ideal and with every effect
  of a physical arm on, for computed torque, PID and the adaptive presets.

Writes ``<out>/<timestamp>/`` with the recordings, ``report.md``, PNG figures and
``summary.json``, and prints the Table 2 analogue next to the paper's numbers.

    python -m apc_lab.reproduce [--out runs] [--quick] [--only table2,pickup]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from apc_core.node_logs import node_logs_to
from apc_core.robot import PAPER_GOAL_DEG, PAPER_START_DEG, example_robot_urdf
from apc_lab import robot_compare, robot_report
from apc_lab.analyze import analyze_file
from apc_lab.experiment import Progress, RunSpec, run_in_process
from apc_lab.scenario import (
    CONFIG_DIR,
    PAPER_CASES,
    Scenario,
    paper_scenario,
    paper_settings,
    recommended_settings,
)

LB = 0.45359237
CASE_LABELS = {"a": "no load", "b": "1.134 kg (half)", "c": "2.268 kg (5 lb)"}
PAPER_KEYS = {"a": "a_no_load", "b": "b_half_load", "c": "c_max_load"}
GROUPS = ("table2", "trajectory2", "sweep", "pickup", "puma6", "panda", "robot")


@dataclass(frozen=True)
class Planned:
    """One run of the reproduction: its group, labels, and what to run."""

    group: str
    label: str
    spec: RunSpec
    case: str = ""


def controllers(alphas: Sequence[float], presets: Sequence[str]) -> list[tuple[str, str, Any]]:
    """(label, controller, settings) for computed torque and the adaptive variants."""
    out: list[tuple[str, str, Any]] = [("computed torque", "computed_torque", None)]
    makers = {"paper": paper_settings, "recommended": recommended_settings}
    for preset in presets:
        for alpha in alphas:
            tag = "P1" if alpha == 1500.0 else "P2" if alpha == 1.5e5 else f"alpha={alpha:g}"
            out.append((f"adaptive {preset} {tag}(0)", "adaptive", makers[preset](alpha)))
    return out


def plan(quick: bool = False, only: Sequence[str] = GROUPS) -> list[Planned]:
    """Every run of the reproduction (``quick``: fewer and shorter, for the test suite)."""
    runs: list[Planned] = []
    hold = 0.2 if quick else 0.5
    alphas = (1.5e5,) if quick else (1500.0, 1.5e5)

    def add(group: str, label: str, scenario: Scenario, controller: str, settings: Any,
            case: str = "") -> None:  # fmt: skip
        safe = label.replace(" ", "_").replace("(", "").replace(")", "").replace("/", "_")
        name = f"{group}_{case + '_' if case else ''}{safe}"
        runs.append(Planned(group, label, RunSpec(scenario, controller, settings, name=name), case))

    if "table2" in only:
        for case in PAPER_CASES:
            for label, controller, settings in controllers(alphas, ("paper", "recommended")):
                add("table2", label, paper_scenario(case, hold_s=hold), controller, settings, case)
    main = controllers((1.5e5,), ("paper", "recommended"))
    if "trajectory2" in only and not quick:
        # The paper's second trajectory: same start, another end. The paper does not give the
        # end; (-60, -30, 90) deg in its angles = (-60, 30, -90) deg here.
        scenario = paper_scenario("c", hold_s=hold, q_goal_deg=(-60.0, 30.0, -90.0))
        for label, controller, settings in main:
            add("trajectory2", label, scenario, controller, settings, "c")
    if "sweep" in only:
        pounds = (0, 2.5, 5) if quick else (0, 1, 2, 3, 4, 5)
        for lb in pounds:
            scenario = replace(paper_scenario("a", hold_s=0.0), payload_kg=lb * LB)
            for label, controller, settings in main:
                add("sweep", label, scenario, controller, settings, f"{lb:g}lb")
    if "pickup" in only:
        scenario = paper_scenario("c", hold_s=1.0, payload_at_s=0.5)
        for label, controller, settings in main:
            add("pickup", label, scenario, controller, settings, "c")
    if "puma6" in only and not quick:
        scenario = Scenario(
            urdf=str(CONFIG_DIR / "puma560.urdf"),
            payload_kg=PAPER_CASES["c"],
            payload_frame="wrist_center",
            inertia_error=(0.1, -0.1, 0.1, -0.1, 0.1, -0.1),
            q_start_deg=(*PAPER_START_DEG, 0.0, 0.0, 0.0),
            q_goal_deg=(*PAPER_GOAL_DEG, 60.0, -45.0, 90.0),
            hold_s=hold,
        )
        for label, controller, settings in main:
            add("puma6", label, scenario, controller, settings, "c")
    if "panda" in only and not quick:
        scenario = Scenario(
            urdf=str(example_robot_urdf("panda_description/urdf/panda.urdf")),
            lock_joints=("panda_finger_joint1", "panda_finger_joint2"),
            payload_kg=PAPER_CASES["c"],
            payload_frame="panda_hand",
            inertia_error=(0.1, -0.1, 0.1, -0.1, 0.1, -0.1, 0.1),
            q_start_deg=(0.0, -20.0, 0.0, -120.0, 0.0, 100.0, 45.0),
            q_goal_deg=(60.0, 15.0, 20.0, -80.0, 30.0, 130.0, 0.0),
            hold_s=hold,
        )
        for label, controller, settings in main:
            add("panda", label, scenario, controller, settings, "c")
    return runs


def execute(planned: Sequence[Planned], out: Path, progress: bool = True) -> dict[str, Any]:
    """Run each planned run through the nodes; return {name: outcome dict}."""
    outcomes: dict[str, Any] = {}
    bar = Progress(len(planned), "make run", progress)
    for i, p in enumerate(planned):
        bar.update(i, p.spec.name)
        outcome = run_in_process(p.spec, out, progress=False, timeout_s=300)
        outcomes[p.spec.name] = {
            "ok": outcome.ok,
            "message": outcome.message,
            "path": str(outcome.path),
            "wall_s": round(outcome.wall_s, 2),
        }
        if not outcome.ok:
            print(f"\n{p.spec.name}: FAILED ({outcome.message})", file=sys.stderr)
    bar.update(len(planned))
    bar.close()
    return outcomes


def _fmt(values: Sequence[float], digits: int = 3) -> str:
    return " / ".join(f"{v:.{digits}f}" for v in values)


def table2(planned: Sequence[Planned], metrics: dict[str, dict], paper: dict) -> str:
    """Markdown: per case and joint, each controller's max / final error next to the paper's."""
    rows = [p for p in planned if p.group == "table2"]
    labels = list(dict.fromkeys(p.label for p in rows))
    head = "| case | joint | " + " | ".join(f"{lab}: max / mm / final" for lab in labels)
    head += " | paper PD: max / mm / final | paper adaptive: max / mm / final |"
    lines = [head, "|" + "---|" * (len(labels) + 4)]
    for case in PAPER_CASES:
        by_label = {p.label: metrics[p.spec.name] for p in rows if p.case == case}
        for j in range(3):
            cells = []
            for lab in labels:
                m = by_label.get(lab)
                cells.append(
                    "failed"
                    if m is None
                    else _fmt(
                        [m["max_error_deg"][j], m["max_tip_mm"][j], m["final_error_deg"][j]], 3
                    )
                )
            pp = paper[PAPER_KEYS[case]][f"joint{j + 1}"]
            lines.append(
                f"| {case} | {j + 1} | "
                + " | ".join(cells)
                + f" | {pp[0]} / {pp[1]} / {pp[2]} | {pp[3]} / {pp[4]} / {pp[5]} |"
            )
    return "\n".join(lines)


def comparison_table(planned: Sequence[Planned], metrics: dict[str, dict], group: str) -> str:
    """Markdown: per controller, max / final error per joint and peak torque, for one group."""
    rows = [p for p in planned if p.group == group and p.spec.name in metrics]
    if not rows:
        return "(no runs)"
    joints = metrics[rows[0].spec.name]["joints"]
    lines = [
        "| controller | max error (deg) per joint | final error (deg) | peak torque (N m) |",
        "|---|---|---|---|",
    ]
    for p in rows:
        m = metrics[p.spec.name]
        lines.append(
            f"| {p.label} {p.case if p.group == 'sweep' else ''} | {_fmt(m['max_error_deg'])} "
            f"| {_fmt(m['final_error_deg'])} | {_fmt(m['peak_torque_nm'], 1)} |"
        )
    return f"joints: {', '.join(joints)}\n\n" + "\n".join(lines)


def acceptance(planned: Sequence[Planned], metrics: dict[str, dict], preset: str) -> dict:
    """Does ``preset`` beat computed torque on every joint in every case (Table 2 claim)?"""
    result: dict[str, Any] = {}
    rows = [p for p in planned if p.group == "table2"]
    for case in PAPER_CASES:
        ct = next((metrics[p.spec.name] for p in rows if p.case == case
                   and p.label == "computed torque" and p.spec.name in metrics), None)  # fmt: skip
        for p in rows:
            if p.case != case or not p.label.startswith(f"adaptive {preset}"):
                continue
            if ct is None or p.spec.name not in metrics:
                continue
            m = metrics[p.spec.name]
            max_ok = all(
                a < c for a, c in zip(m["max_error_deg"], ct["max_error_deg"], strict=True)
            )
            fin_ok = all(
                a < c for a, c in zip(m["final_error_deg"], ct["final_error_deg"], strict=True)
            )
            ratio = max(
                a / c for a, c in zip(m["peak_torque_nm"], ct["peak_torque_nm"], strict=True)
            )
            result[f"{case} {p.label}"] = {
                "smaller_max_error_every_joint": max_ok,
                "smaller_final_error_every_joint": fin_ok,
                "peak_torque_ratio_to_ct": round(ratio, 3),
                "max_error_deg": [round(v, 4) for v in m["max_error_deg"]],
                "final_error_deg": [round(v, 4) for v in m["final_error_deg"]],
                "computed_torque_final_error_deg": [round(v, 4) for v in ct["final_error_deg"]],
            }
    return result


def acceptance_table(acceptance_by_preset: dict[str, dict]) -> str:
    """Markdown of :func:`acceptance` for both presets."""
    lines = [
        "| run | max error < CT, every joint | final error < CT, every joint "
        "| peak torque / CT | max error (deg) |",
        "|---|---|---|---|---|",
    ]
    for results in acceptance_by_preset.values():
        for name, r in results.items():
            lines.append(
                f"| {name} | {'yes' if r['smaller_max_error_every_joint'] else 'no'} "
                f"| {'yes' if r['smaller_final_error_every_joint'] else 'no'} "
                f"| {r['peak_torque_ratio_to_ct']:.2f} | {_fmt(r['max_error_deg'])} |"
            )
    return "\n".join(lines)


def figures(
    planned: Sequence[Planned], outcomes: dict[str, Any], metrics: dict[str, dict], out: Path
) -> list[Path]:
    """The paper's Figures 3-9 and more, from the recordings (and their metrics)."""
    from apc_lab import plots, plots_beyond
    from apc_recording.runs import load_run

    made: list[Path] = []

    def runs_of(group: str, case: str | None = None) -> dict[str, Any]:
        return {
            p.label: p
            for p in planned
            if p.group == group and (case is None or p.case == case)
            and outcomes.get(p.spec.name, {}).get("ok")
        }  # fmt: skip

    def load(p: Planned) -> Any:
        return load_run(outcomes[p.spec.name]["path"])

    table = [p for p in planned if p.group == "table2" and outcomes.get(p.spec.name, {}).get("ok")]
    for preset in ("paper", "recommended"):
        label = next((p.label for p in table if p.label.startswith(f"adaptive {preset}")
                      and p.label.endswith("P2(0)")), None)  # fmt: skip
        if label is None:
            continue
        by_load = {CASE_LABELS[p.case]: load(p) for p in table if p.label == label}
        made.append(plots.errors_by_load(
            by_load, out / f"fig3-5_errors_by_load_{preset}.png",
            f"Figures 3-5: {label}, position error under the three loads",
        ))  # fmt: skip
    case_c = {p.label: load(p) for p in table if p.case == "c"}
    if case_c:
        for preset in ("paper", "recommended"):
            chosen = {k: v for k, v in case_c.items()
                      if k == "computed torque" or k.startswith(f"adaptive {preset}")}  # fmt: skip
            made.append(plots.controller_comparison(
                chosen, out / f"fig6-8_case_c_{preset}.png",
                f"Figures 6-8: case (c), computed torque vs adaptive ({preset} preset)",
            ))  # fmt: skip
            made.append(plots.applied_torques(
                chosen, out / f"fig9_torques_case_c_{preset}.png",
                f"Figure 9: case (c), applied torques ({preset} preset)",
            ))  # fmt: skip
        for k, run in case_c.items():
            if k.startswith("adaptive") and k.endswith("P2(0)"):
                preset = k.split()[1]
                made.append(plots_beyond.identified_parameters(
                    run, out / f"identified_parameters_case_c_{preset}.png",
                    f"Identified parameters, case (c), {k}",
                ))  # fmt: skip
    sweep: dict[str, list] = {}
    for p in planned:
        if p.group == "sweep" and p.spec.name in metrics:
            m = metrics[p.spec.name]
            sweep.setdefault(p.label, []).append((p.spec.scenario.payload_kg, m["max_error_deg"]))
    if sweep:
        made.append(plots_beyond.payload_sweep(
            sweep, out / "payload_sweep.png", "Maximum tracking error vs payload (0-5 lb)"
        ))  # fmt: skip
    pick = runs_of("pickup")
    if pick:
        made.append(plots.pickup(
            {k: load(p) for k, p in pick.items()}, 0.5, out / "pickup.png",
            "5 lb payload picked up at t = 0.5 s",
        ))  # fmt: skip
    for group, title in (("trajectory2", "second trajectory, case (c)"),
                         ("puma6", "six-joint PUMA 560, 5 lb"),
                         ("panda", "Franka Panda (example-robot-data), 5 lb")):  # fmt: skip
        runs = runs_of(group)
        if runs:
            made.append(plots.controller_comparison(
                {k: load(p) for k, p in runs.items()}, out / f"{group}.png", title,
                paper_signs=False,
            ))  # fmt: skip
    return made


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="reproduce", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="runs", help="parent directory of the run folder")
    parser.add_argument("--quick", action="store_true", help="fewer, shorter runs (tests)")
    parser.add_argument("--only", default=",".join(GROUPS), help="groups to run, comma-separated")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    only = [g for g in args.only.split(",") if g]
    unknown = set(only) - set(GROUPS)
    if unknown:
        print(f"reproduce: unknown group(s) {sorted(unknown)}; known: {GROUPS}", file=sys.stderr)
        return 2
    out = Path(args.out) / time.strftime("%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    planned = plan(args.quick, only)
    robot_cases = robot_compare.plan(args.quick) if "robot" in only else []
    with node_logs_to(out / "logs"):  # the nodes' log lines: a file there, not the console
        outcomes = execute(planned, out, progress=not args.quiet)
        robot_results = robot_compare.execute(robot_cases, out, progress=not args.quiet)
    metrics = {
        p.spec.name: analyze_file(outcomes[p.spec.name]["path"])
        for p in planned
        if outcomes[p.spec.name]["ok"]
    }
    paper = json.loads((CONFIG_DIR / "reference" / "paper.json").read_text())["table2"]
    summary: dict[str, Any] = {
        "out": str(out),
        "runs": [
            {
                "group": p.group,
                "label": p.label,
                "case": p.case,
                "name": p.spec.name,
                **outcomes[p.spec.name],
                "metrics": metrics.get(p.spec.name),
            }
            for p in planned
        ],
        "acceptance": {
            preset: acceptance(planned, metrics, preset) for preset in ("paper", "recommended")
        },
        "recovery_samples": {},
        "robot": robot_results,
    }
    made: list[Path] = []
    if not args.no_figures:
        made = figures(planned, outcomes, metrics, out)
        made += robot_report.figures(robot_cases, robot_results, out)
        from apc_lab.metrics import recovery_samples
        from apc_recording.runs import load_run

        for p in planned:
            if p.group == "pickup" and p.spec.name in metrics:
                run = load_run(outcomes[p.spec.name]["path"])
                summary["recovery_samples"][p.label] = recovery_samples(run, 0.5, 0.05)
    summary["wall_s"] = round(time.monotonic() - t0, 1)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    robot_text = robot_report.report_section(robot_cases, robot_results) if robot_cases else ""
    report = write_report(out, planned, metrics, paper, summary, made, robot_text)
    print(report.split("\n## ")[1] if "\n## " in report else report)
    print(f"\nreport: {out / 'report.md'} ({len(planned)} runs, {summary['wall_s']} s)")
    failed = [p.spec.name for p in planned if not outcomes[p.spec.name]["ok"]]
    failed += [name for name, result in robot_results.items() if not result["ok"]]
    return 1 if failed else 0


def write_report(
    out: Path,
    planned: Sequence[Planned],
    metrics: dict[str, dict],
    paper: dict,
    summary: dict,
    figures_made: Sequence[Path],
    robot_section: str = "",
) -> str:
    """``report.md``: the tables and figures of this reproduction."""
    parts = [
        "# apc: the paper's experiment, reproduced through the ROS nodes",
        f"Runs: {len(planned)} lockstep runs recorded in `{out}`; wall time {summary['wall_s']} s.",
        "## Table 2 analogue (max error deg / tip displacement mm / final error deg)\n\n"
        + table2(planned, metrics, paper),
        "## Does adaptive control beat computed torque? (every joint, every case)\n\n"
        + acceptance_table(summary["acceptance"]),
    ]
    for group, title in (
        ("trajectory2", "Second trajectory, case (c)"),
        ("sweep", "Payload sweep 0-5 lb (+-10 % inertia error)"),
        ("pickup", "Payload picked up at t = 0.5 s (5 lb)"),
        ("puma6", "Six-joint PUMA 560, 5 lb"),
        ("panda", "Franka Panda from example-robot-data, 5 lb"),
    ):
        if any(p.group == group for p in planned):
            parts.append(f"## {title}\n\n" + comparison_table(planned, metrics, group))
    if summary["recovery_samples"]:
        parts.append(
            "Samples after the pickup until every joint stays within 0.05 deg: "
            + ", ".join(f"{k}: {v}" for k, v in summary["recovery_samples"].items())
        )
    if robot_section:
        parts.append(
            "## Through the robot interface: ros2_control's, on MuJoCo, ideal and physical\n\n"
            f"{robot_compare.SUMMARY}\n\n{robot_section}"
        )
    if figures_made:
        parts.append("## Figures\n\n" + "\n".join(f"![{f.stem}]({f.name})" for f in figures_made))
    text = "\n\n".join(parts) + "\n"
    (out / "report.md").write_text(text)
    return text


if __name__ == "__main__":
    sys.exit(main())
