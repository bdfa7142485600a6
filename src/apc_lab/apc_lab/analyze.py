"""``analyze``: tracking metrics of recorded runs (MCAP), as a table or as JSON.

Reads each recording (not in-memory results), aligns the signals by sample stamp and reports per
joint: maximum tracking error (deg), the tip displacement it causes (mm), final error at the end
of the move, maximum and last error over the hold after it, RMS error, peak and RMS torque, and
the RLS residual (definitions: :mod:`apc_lab.metrics`).

    analyze runs/*.mcap
    analyze --json runs/adaptive_alpha150000_2.268kg_lockstep.mcap
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from apc_core.config_files import resolve_config_path
from apc_core.robot import Robot, RobotModelError, load_robot
from apc_lab.metrics import compute_metrics
from apc_recording.bag import BagError
from apc_recording.runs import RecordedRun, load_run


def robot_of(run: RecordedRun) -> Robot | None:
    """The arm of a recording (for the tip metric): its stored scenario's, else the URDF it
    recorded on ``robot_description`` with every joint it did not record locked (a gripper);
    None without either. The tip metric is kinematics: gravity does not enter it."""
    scenario = run.run.get("scenario", {})
    urdf = scenario.get("urdf")
    try:
        if urdf:
            return load_robot(
                resolve_config_path(urdf),
                gravity=scenario.get("gravity", 9.8062),
                lock_joints=tuple(scenario.get("lock_joints", ())),
            )
        if run.robot_description:
            return load_robot(run.robot_description, keep_joints=run.joint_names)
    except RobotModelError:
        return None
    return None


def analyze_file(path: str | Path) -> dict[str, Any]:
    """Metrics of one recording as a JSON-ready dict."""
    run = load_run(path)
    # joint_states(k).effort is the torque applied over [(k-1)T, kT): shift it back one row.
    applied = np.vstack([run.applied[1:], np.full((1, len(run.joint_names)), np.nan)])
    metrics = compute_metrics(
        run.joint_names,
        run.q,
        run.q_d,
        applied,
        run.move_end_index,
        robot=robot_of(run),
        residual_norm=run.residual_norm,
    )
    return {
        "file": str(path),
        "controller": run.run.get("controller"),
        "mode": run.run.get("mode"),
        "payload_kg": run.run.get("scenario", {}).get("payload_kg"),
        "samples": len(run.t),
        **metrics.as_dict(),
    }


def format_table(results: Sequence[dict[str, Any]]) -> str:
    """A Markdown table: one row per run and joint."""
    lines = [
        "| run | joint | max err (deg) | max tip (mm) | final err (deg) | hold max (deg) "
        "| RMS err (deg) | peak torque (N m) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for i, joint in enumerate(r["joints"]):
            lines.append(
                f"| {Path(r['file']).stem} | {joint} | {r['max_error_deg'][i]:.3f} "
                f"| {r['max_tip_mm'][i]:.2f} | {r['final_error_deg'][i]:.3f} "
                f"| {r['hold_max_error_deg'][i]:.3f} | {r['rms_error_deg'][i]:.3f} "
                f"| {r['peak_torque_nm'][i]:.1f} |"
            )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="analyze", description=__doc__.split("\n\n")[0])
    parser.add_argument("recordings", nargs="+", help="MCAP files written by experiment/recorder")
    parser.add_argument("--json", action="store_true", help="print {'runs': [...]} as JSON")
    parser.add_argument(
        "--report",
        metavar="DIR",
        help="also write DIR/report.md with the table and PNG figures of these recordings",
    )
    args = parser.parse_args(argv)
    results = []
    for path in args.recordings:
        try:
            results.append(analyze_file(path))
        except (OSError, ValueError, BagError) as exc:
            print(f"analyze: {path}: {exc}", file=sys.stderr)
            return 2
    if args.json:
        print(json.dumps({"runs": results}, indent=1))
    else:
        print(format_table(results))
    if args.report:
        path = write_report(Path(args.report), args.recordings, results)
        print(f"report: {path}", file=sys.stderr)
    return 0


def write_report(out: Path, recordings: Sequence[str], results: Sequence[dict[str, Any]]) -> Path:
    """``out/report.md``: the metrics table and, for all recordings together, the position
    errors and applied torques per joint, plus the identified parameters of each adaptive run.
    """
    from apc_lab import plots, plots_beyond

    out.mkdir(parents=True, exist_ok=True)
    runs = {Path(p).stem: load_run(p) for p in recordings}
    pumas = all(r.joint_names == ("joint_1", "joint_2", "joint_3") for r in runs.values())
    figures = [
        plots.controller_comparison(
            runs, out / "errors.png", "Position error per joint", paper_signs=pumas
        ),
        plots.applied_torques(
            runs, out / "torques.png", "Applied torque per joint", paper_signs=pumas
        ),
    ]
    for name, run in runs.items():
        if run.theta_t is not None:
            figures.append(
                plots_beyond.identified_parameters(
                    run, out / f"identified_{name}.png", f"Identified parameters: {name}"
                )
            )
    text = (
        "# apc analysis\n\n"
        + format_table(results)
        + "\n\n"
        + "\n".join(f"![{f.stem}]({f.name})" for f in figures)
        + "\n"
    )
    (out / "report.md").write_text(text)
    return out / "report.md"


if __name__ == "__main__":
    sys.exit(main())
