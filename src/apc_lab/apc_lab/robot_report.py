"""The robot comparison's report (:mod:`apc_lab.robot_compare`'s runs): tables per arm,
the law with the smallest error per joint, whether a law beats the baselines, the figures."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from apc_lab.robot_compare import (
    BASELINES,
    CASES,
    DRIVER_RATE_HZ,
    EFFECTS,
    ROBOT_FILE_LAW,
    RobotCase,
    load,
)


def _cell(metrics: Mapping[str, Any] | None, j: int) -> str:
    if metrics is None:
        return "failed"
    return f"{metrics['max_error_deg'][j]:.3f} / {metrics['final_error_deg'][j]:.3f}"


def _metrics(results: Mapping[str, dict], case: RobotCase) -> dict[str, Any] | None:
    entry = results.get(case.name)
    return entry.get("metrics") if entry and entry.get("ok") else None


def comparison_table(
    cases: Sequence[RobotCase], results: Mapping[str, dict], arm: str, timing: str = "sim"
) -> str:
    """Markdown: per effect setting, case and joint, each law's max / final error (deg)."""
    rows = [c for c in cases if c.arm == arm and c.timing == timing]
    laws = list(dict.fromkeys(c.law for c in rows))
    lines = [
        "| arm | case | joint | " + " | ".join(f"{law}: max / final" for law in laws) + " |",
        "|---|---|---|" + "---|" * len(laws),
    ]
    for effects in EFFECTS:
        for case_name in CASES:
            group = {c.law: c for c in rows if c.effects == effects and c.case == case_name}
            if not group:
                continue
            measured = [m for c in group.values() if (m := _metrics(results, c)) is not None]
            joints = measured[0]["joints"] if measured else []
            for j, joint in enumerate(joints):
                cells = [_cell(_metrics(results, group[law]), j) if law in group else "-"
                         for law in laws]  # fmt: skip
                lines.append(f"| {effects} | {case_name} | {joint} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def beats_baselines(
    cases: Sequence[RobotCase], results: Mapping[str, dict], law: str
) -> dict[str, Any]:
    """Per (arm, effects, case, timing): does ``law`` have a smaller max and final error than
    every baseline on every joint? With the joints where it does not."""
    out: dict[str, Any] = {}
    for c in cases:
        if c.law != law:
            continue
        mine = _metrics(results, c)
        losses: list[str] = []
        for base in BASELINES:
            other = _metrics(results, replace(c, law=base))
            if mine is None or other is None:
                losses.append(f"{base}: no run")
                continue
            for key in ("max_error_deg", "final_error_deg"):
                pairs = zip(mine[key], other[key], strict=True)
                worse = [mine["joints"][j] for j, (a, b) in enumerate(pairs) if not a < b]
                where = "every joint" if len(worse) == len(mine["joints"]) else ", ".join(worse)
                if worse:
                    losses.append(f"{key.split('_')[0]} vs {base} on {where}")
        out[f"{c.arm} {c.effects} {c.case} {c.timing}"] = {"beats": not losses, "where_not": losses}
    return out


def winners(cases: Sequence[RobotCase], results: Mapping[str, dict], key: str) -> str:
    """Markdown: per arm, effect setting, case and joint, the law with the smallest ``key``."""
    lines = ["| arm | effects | case | " + key + ": smallest per joint |", "|---|---|---|---|"]
    groups = dict.fromkeys((c.arm, c.effects, c.case, c.timing) for c in cases)
    for arm, effects, case_name, timing in groups:
        members = [c for c in cases if (c.arm, c.effects, c.case, c.timing)
                   == (arm, effects, case_name, timing)]  # fmt: skip
        measured = {c.law: m for c in members if (m := _metrics(results, c)) is not None}
        if not measured:
            continue
        joints = next(iter(measured.values()))["joints"]
        best = [min(measured, key=lambda law, j=j: measured[law][key][j])
                for j in range(len(joints))]  # fmt: skip
        tag = case_name if timing == "sim" else f"{case_name} ({timing})"
        lines.append(f"| {arm} | {effects} | {tag} | {', '.join(best)} |")
    return "\n".join(lines)


def figures(cases: Sequence[RobotCase], results: Mapping[str, dict], out: Path) -> list[Path]:
    """Per arm, like the paper's Figs 6-8: case (c) error per joint for each law, ideal and with
    every effect on; and the pickup with every effect on."""
    from apc_lab import plots

    made: list[Path] = []
    titles = {"puma3": "3-joint PUMA 560", "panda": "Franka Panda"}
    for arm in dict.fromkeys(c.arm for c in cases):
        for effects in EFFECTS:
            for case_name in ("c", "pickup"):
                chosen = [c for c in cases if (c.arm, c.effects, c.case, c.timing)
                          == (arm, effects, case_name, "sim") and _metrics(results, c)]  # fmt: skip
                if not chosen or (case_name == "pickup" and effects == "ideal"):
                    continue
                runs = {c.law: load(results[c.name]["path"]) for c in chosen}
                what = "ideal arm" if effects == "ideal" else "every physical-arm effect on"
                target = out / f"robot_{arm}_{case_name}_{effects}.png"
                title = f"{titles[arm]} through the robot interface ({what})"
                signs = arm == "puma3"
                if case_name == "c":
                    made.append(plots.controller_comparison(
                        runs, target, f"{title}, 5 lb", paper_signs=signs))  # fmt: skip
                else:
                    first = next(iter(runs.values())).run
                    pickup_s = first["scenario"]["payload_at_s"] - first["move_start_s"]
                    made.append(plots.pickup(
                        runs, pickup_s, target, f"{title}, 5 lb picked up",
                        paper_signs=signs))  # fmt: skip
    return made


def report_section(cases: Sequence[RobotCase], results: Mapping[str, dict]) -> str:
    """The report's section: tables per arm, who wins per joint, the goal's verdict."""
    parts = []
    for arm in dict.fromkeys(c.arm for c in cases):
        parts.append(
            f"### {arm}: max / final error (deg) per joint\n\n"
            + comparison_table(cases, results, arm)
        )
        if any(c.arm == arm and c.timing == "realtime" for c in cases):
            parts.append(
                f"{arm}, real time (driver at {DRIVER_RATE_HZ:g} Hz, controllers at 100 Hz):\n\n"
                + comparison_table(cases, results, arm, "realtime")
            )
    for key in ("max_error_deg", "final_error_deg"):
        parts.append(winners(cases, results, key))
    for law in ("adaptive recommended", ROBOT_FILE_LAW):
        verdicts = beats_baselines(cases, results, law)
        if not verdicts:
            continue
        lines = [f"| run | {law} beats computed torque and PID on every joint | where not |",
                 "|---|---|---|"]  # fmt: skip
        for run, v in verdicts.items():
            verdict = "yes" if v["beats"] else "no"
            lines.append(f"| {run} | {verdict} | {'; '.join(v['where_not'])} |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts)
