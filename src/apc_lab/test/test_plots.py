"""plots: every figure writes a real PNG, says what it shows, and draws the data it was given.

Runs are made by the offline loop (no ROS) and converted to :class:`RecordedRun` the way a
recording stores them: ``effort[k]`` is the torque applied over ``[t[k-1], t[k])``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from apc_lab import metrics, plots, plots_beyond
from apc_lab.offline import RunResult
from apc_lab.scenario import (
    Scenario,
    paper_scenario,
    paper_settings,
    recommended_settings,
    run_offline,
)
from apc_recording.runs import RecordedRun

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def to_recorded(result: RunResult, scenario: Scenario) -> RecordedRun:
    """A RunResult as a recording would store it."""
    applied = np.full_like(result.applied, np.nan)
    applied[1:] = result.applied[:-1]
    theta_t = None
    if result.F is not None:
        theta_t = np.concatenate([result.F, result.G, result.w[:, :, None]], axis=2)
    return RecordedRun(
        path=Path("offline"),
        joint_names=tuple(result.joint_names),
        t=result.t,
        q=result.q,
        qd=result.qd,
        applied=applied,
        q_d=result.q_d,
        qd_d=result.qd_d,
        qdd_d=result.qdd_d,
        u_n=result.u_n,
        du=result.du,
        trace_p=result.trace_p,
        residual_norm=result.residual_norm,
        theta_t=theta_t,
        run={
            "controller": result.meta.get("controller"),
            "scenario": {
                "payload_kg": scenario.payload_kg,
                "segment_times": list(scenario.segment_times),
                "period": scenario.period,
            },
        },
    )


def offline(scenario: Scenario, controller: str, params=None) -> RecordedRun:
    return to_recorded(run_offline(scenario, controller, params), scenario)


def synthetic(error_deg: np.ndarray, period: float = 0.01) -> RecordedRun:
    """A run whose q - q_d is ``error_deg`` (N, n); move ends half-way."""
    rows, n = error_deg.shape
    zeros = np.zeros((rows, n))
    nan = np.full(rows, np.nan)
    return RecordedRun(
        path=Path("synthetic"),
        joint_names=tuple(f"joint_{i + 1}" for i in range(n)),
        t=np.arange(rows) * period,
        q=np.deg2rad(error_deg),
        qd=zeros,
        applied=zeros,
        q_d=zeros,
        qd_d=zeros,
        qdd_d=zeros,
        u_n=zeros,
        du=zeros,
        trace_p=nan,
        residual_norm=nan,
        theta_t=None,
        run={"scenario": {"segment_times": [rows * period / 2], "period": period}},
    )


@pytest.fixture(scope="module")
def case_c():
    """Case (c), short hold: computed torque, adaptive P1(0) and P2(0)."""
    scenario = paper_scenario("c", hold_s=0.2)
    return {
        "computed torque": offline(scenario, "computed_torque"),
        "adaptive P1(0)": offline(scenario, "adaptive", paper_settings(1500.0)),
        "adaptive P2(0)": offline(scenario, "adaptive", paper_settings(1.5e5)),
    }


@pytest.fixture(scope="module")
def by_load():
    return {
        label: offline(paper_scenario(case, hold_s=0.2), "adaptive", recommended_settings())
        for label, case in (("no load", "a"), ("1.134 kg", "b"), ("2.268 kg", "c"))
    }


def assert_png(path: Path) -> None:
    assert path.is_file()
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = imread(path)
    assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 300
    assert float(np.var(image[..., :3])) > 1e-3, "blank image"


def legend_texts(fig) -> list[str]:
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    return [t.get_text() for legend in legends for t in legend.get_texts()]


def line(ax, label: str):
    (found,) = [ln for ln in ax.get_lines() if ln.get_label() == label]
    return found


# ------------------------------------------------------------------------------------------
# every figure writes a PNG


def test_every_figure_writes_a_non_blank_png(tmp_path, case_c, by_load):
    sweep = {
        "computed torque": [(0.0, [0.09, 0.10, 0.33]), (2.268, [0.15, 0.19, 0.61])],
        "adaptive": [(2.268, [0.07, 0.07, 0.07]), (0.0, [0.02, 0.02, 0.03])],
    }
    outs = [
        plots.errors_by_load(by_load, tmp_path / "loads.png", "Figures 3-5"),
        plots.controller_comparison(case_c, tmp_path / "compare.png", "Figures 6-8"),
        plots.applied_torques(case_c, tmp_path / "torques.png", "Figure 9"),
        plots_beyond.identified_parameters(case_c["adaptive P2(0)"], tmp_path / "id.png", "P2(0)"),
        plots_beyond.payload_sweep(sweep, tmp_path / "deep" / "sweep.png", "sweep"),
        plots.pickup(case_c, 0.4, tmp_path / "pickup.png", "pick-up"),
    ]
    for out in outs:
        assert_png(out)
    assert outs[4] == tmp_path / "deep" / "sweep.png"


# ------------------------------------------------------------------------------------------
# labels, titles, legends


def test_error_figures_label_joints_units_and_paper_figures(by_load, case_c):
    fig = plots._figure_errors_by_load(by_load, "adaptive, recommended")
    axes = fig.axes
    assert len(axes) == 3
    for j, ax in enumerate(axes):
        label = ax.get_ylabel()
        assert f"joint {j + 1} error" in label and "deg" in label and "paper's sign" in label
    assert axes[-1].get_xlabel() == "time (s)"
    title = fig.get_suptitle()
    assert "adaptive, recommended" in title and "Figures 3-5" in title
    texts = legend_texts(fig)
    assert {"no load", "1.134 kg", "2.268 kg", "end of move"} <= set(texts)
    # the end-of-move line sits at the end of the move (1 s) on every panel
    for ax in axes:
        ends = [
            ln for ln in ax.get_lines() if ln.get_linestyle() == ":" and ln.get_xdata()[0] == 1.0
        ]
        assert ends, "no end-of-move line"

    fig = plots._figure_controller_comparison(case_c, "case (c)")
    assert "Figures 6-8" in fig.get_suptitle()
    assert {"computed torque", "adaptive P1(0)", "adaptive P2(0)"} <= set(legend_texts(fig))


def test_paper_signs_negate_joints_2_and_3(case_c):
    run = case_c["computed torque"]
    error = np.rad2deg(run.error)
    flipped = plots._figure_controller_comparison(case_c, paper_signs=True, yscale="linear")
    plain = plots._figure_controller_comparison(case_c, paper_signs=False, yscale="linear")
    for j, sign in enumerate((1.0, -1.0, -1.0)):
        np.testing.assert_allclose(
            line(flipped.axes[j], "computed torque").get_ydata(), sign * error[:, j]
        )
        np.testing.assert_allclose(line(plain.axes[j], "computed torque").get_ydata(), error[:, j])
        assert "paper's sign" not in plain.axes[j].get_ylabel()
    assert not np.allclose(error[:, 1], 0.0)  # the test would prove nothing on a zero error


def test_applied_torques_are_steps_over_the_period_they_were_applied(case_c):
    fig = plots._figure_applied_torques(case_c, "Figure 9")
    assert "Figure 9" in fig.get_suptitle()
    for j, sign in enumerate((1.0, -1.0, -1.0)):
        ax = fig.axes[j]
        assert "torque" in ax.get_ylabel() and "N m" in ax.get_ylabel()
        for label, run in case_c.items():
            drawn = line(ax, label)
            assert drawn.get_drawstyle() == "steps-pre"  # applied[k] spans [t[k-1], t[k])
            np.testing.assert_array_equal(drawn.get_xdata(), run.t)
            np.testing.assert_allclose(drawn.get_ydata(), sign * run.applied[:, j])
        nominal = line(ax, "nominal u_n (feedforward)")
        assert nominal.get_drawstyle() == "steps-post"  # u_n(k) is held over [t[k], t[k+1])
    assert {"computed torque", "adaptive P2(0)", "end of move"} <= set(legend_texts(fig))


def test_identified_parameters_draw_theta_and_refuse_runs_without_it(case_c, tmp_path):
    run = case_c["adaptive P2(0)"]
    n = 3
    fig = plots_beyond._figure_identified_parameters(run, "P2(0)")
    ax_g, ax_f, ax_w, ax_p = fig.axes[:4]
    for i in range(n):
        label = f"joint {i + 1}"
        np.testing.assert_allclose(line(ax_g, label).get_ydata(), run.theta_t[:, n + i, 2 * n + i])
        np.testing.assert_allclose(line(ax_f, label).get_ydata(), run.theta_t[:, n + i, i])
        np.testing.assert_allclose(line(ax_w, label).get_ydata(), run.theta_t[:, n + i, 3 * n])
    assert ax_p.get_yscale() == "log" and fig.axes[4].get_yscale() == "log"  # trace(P), residual
    assert "Ĝ" in ax_g.get_ylabel() and "F̂" in ax_f.get_ylabel() and "rad/s" in ax_w.get_ylabel()
    assert ax_w.get_xlabel() == ax_p.get_xlabel() == "time (s)"
    with pytest.raises(ValueError, match="theta"):
        plots_beyond.identified_parameters(case_c["computed torque"], tmp_path / "no.png", "CT")
    assert not (tmp_path / "no.png").exists()


def test_payload_sweep_axes_scale_and_legend():
    narrow = {"a": [(0.0, [1.0, 2.0]), (1.0, [3.0, 4.0])], "b": [(0.0, [1.5, 1.0])]}
    fig = plots_beyond._figure_payload_sweep(narrow, "narrow")
    ax = fig.axes[0]
    assert ax.get_yscale() == "linear"
    assert ax.get_xlabel() == "payload (kg)" and "deg" in ax.get_ylabel()
    assert any("lb" in a.get_xlabel() for a in ax.child_axes)  # secondary axis in pounds
    assert {"a", "b", "joint 1", "joint 2"} <= set(legend_texts(fig))
    # worst joint per payload, sorted by payload
    np.testing.assert_allclose(line(ax, "a").get_ydata(), [2.0, 4.0])

    wide = {"ct": [(2.268, [0.2, 18.0]), (0.0, [0.1, 0.4])], "ad": [(0.0, [0.01, 0.02])]}
    fig = plots_beyond._figure_payload_sweep(wide, "wide", per_joint=False)
    assert fig.axes[0].get_yscale() == "log"
    np.testing.assert_allclose(line(fig.axes[0], "ct").get_xdata(), [0.0, 2.268])


def test_symlog_only_when_lines_span_more_than_two_decades():
    t = np.linspace(0.0, 1.0, 101)
    big = synthetic(np.column_stack([10 * np.sin(6 * t), np.sin(6 * t)]))
    small = synthetic(np.column_stack([0.01 * np.sin(6 * t), 0.5 * np.sin(6 * t)]))
    fig = plots._figure_controller_comparison({"big": big, "small": small}, paper_signs=False)
    assert fig.axes[0].get_yscale() == "symlog"  # 10 vs 0.01 deg
    assert "symmetric log" in fig.axes[0].get_title(loc="right")
    assert fig.axes[1].get_yscale() == "linear"  # 1 vs 0.5 deg
    fig = plots._figure_controller_comparison(
        {"big": big, "small": small}, paper_signs=False, yscale="linear"
    )
    assert fig.axes[0].get_yscale() == "linear"


def test_pickup_marks_the_pickup_time(case_c):
    fig = plots._figure_pickup(case_c, 0.4, "pick-up")
    assert "payload picked up (0.4 s)" in legend_texts(fig)
    for ax in fig.axes:
        assert any(
            ln.get_xdata()[0] == 0.4 and ln.get_color() == "tab:red" for ln in ax.get_lines()
        )


def test_bad_inputs_are_refused(case_c):
    with pytest.raises(ValueError, match="no runs"):
        plots._figure_controller_comparison({})
    two = synthetic(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="numbers of joints"):
        plots._figure_controller_comparison({"3": case_c["computed torque"], "2": two})
    with pytest.raises(ValueError):
        plots_beyond._figure_payload_sweep({})


# ------------------------------------------------------------------------------------------
# recovery_samples


def test_recovery_samples_counts_from_the_pickup_to_the_last_excursion():
    rows = 100
    error = np.full((rows, 3), 0.01)
    error[30:47, 1] = 2.0  # joint 2 out of tolerance from the pick-up (sample 30) to 46
    error[40, 2] = -3.0
    run = synthetic(error)
    assert metrics.recovery_samples(run, 0.30, 0.5) == 17  # sample 47 is the first for good
    assert metrics.recovery_samples(run, 0.295, 0.5) == 17  # first sample at or after 0.295 s
    assert metrics.recovery_samples(run, 0.50, 0.5) == 0  # already within tolerance
    assert metrics.recovery_samples(run, 0.30, 5.0) == 0
    error[80, 0] = 0.6  # a later excursion restarts the count
    assert metrics.recovery_samples(synthetic(error), 0.30, 0.5) == 51


def test_recovery_samples_none_when_it_never_settles_and_nan_rows_are_skipped():
    error = np.full((50, 2), 0.01)
    error[20:, 0] = np.linspace(1.0, 0.2, 30)
    error[-1, 0] = 0.7  # out of tolerance at the last sample
    assert metrics.recovery_samples(synthetic(error), 0.2, 0.5) is None
    error[-1, 0] = 0.1
    error[-3, :] = np.nan  # a lost sample neither breaks nor ends the recovery
    expected = int(np.argmax(error[20:, 0] < 0.5))
    assert metrics.recovery_samples(synthetic(error), 0.2, 0.5) == expected
    with pytest.raises(ValueError, match="no sample"):
        metrics.recovery_samples(synthetic(error), 5.0, 0.5)
    with pytest.raises(ValueError, match="tolerance"):
        metrics.recovery_samples(synthetic(error), 0.2, 0.0)
