"""The Panda through the robot interface after holds of different lengths: does a law hold an
unknown payload, and does it track the move that follows the hold?

The Franka Panda on robot_sim (MuJoCo, ideal arm, sim time) with the robot-mode controllers
(:mod:`apc_lab.robot_compare`: 10 % inertia error, 5 lb unknown to the model in (c) and
the pickup): the arm holds its measured position for a while, then the move arrives as a goal.
Per law: the worst joint's sag while holding (deg, 5 lb, the 0.3 s hold), max / final error
of (a), (c) and the pickup after a 0.3 s hold, and max error of (c) after 1 s and 5 s holds.
Laws: the recommended preset (what ``config/panda_robot.yaml`` runs), the same with the
paper's prior at the first set point (``relinearize: false``), the same with ``P(0) = alpha I``
everywhere (``alpha_model: 0``, the paper's Eq. 32), the paper's preset and computed torque.
About three minutes on one core.

    .venv/bin/python bench/panda_holds.py
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from apc_lab import robot_compare as rc
from apc_lab.scenario import paper_settings, recommended_settings

LAWS = {
    "recommended": ("adaptive", recommended_settings()),
    "recommended, relinearize false": (
        "adaptive",
        {**recommended_settings(), "relinearize": False},
    ),
    "recommended, alpha_model 0": ("adaptive", {**recommended_settings(), "alpha_model": 0.0}),
    "paper": ("adaptive", paper_settings()),
    "computed torque": ("computed_torque", None),
}
#: (hold before the move in s, case) of each run.
RUNS = ((0.3, "a"), (0.3, "c"), (0.3, "pickup"), (1.0, "c"), (5.0, "c"))


def cell(metrics: dict, final: bool = True) -> str:
    worst = max(metrics["max_error_deg"])
    if worst > 90.0:
        return "diverges"
    return f"{worst:.2f}" + (f" / {max(metrics['final_error_deg']):.2f}" if final else "")


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    rc.LAWS.update(LAWS)
    print("| law | hold sag (5 lb) | (a) max / final | (c) max / final | pickup max / final "
          "| (c) after 1 s | (c) after 5 s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for law in LAWS:
            cells, sag = [], ""
            for hold_s, case in RUNS:
                rc.HOLD_BEFORE_S = hold_s
                run = rc.RobotCase("panda", case, "ideal", law)
                outcome = rc.run_case(run, Path(tmp) / f"{hold_s:g}s", timeout_s=120.0)
                metrics = rc.measure(outcome.path)
                if (hold_s, case) == (0.3, "c"):
                    sag = f"{rc.hold_error_deg(outcome.path):.2f}"
                cells.append(cell(metrics, final=hold_s == 0.3))
            print(f"| {law} | {sag} | {' | '.join(cells)} |", flush=True)


if __name__ == "__main__":
    main()
