"""The adaptive law's presets: ``recommended`` by default, ``paper`` one parameter away."""

from __future__ import annotations

import dataclasses

import pytest
import rclpy
from support.nodes import overrides

from apc_core.params import ConfigError
from apc_feedback.controller import AdaptiveConfig
from apc_feedback.node import PARAMS, FeedbackNode
from apc_feedback.presets import DEFAULT_PRESET, PRESETS, law_params
from apc_lab.experiment import RunSpec, build_parser, law_parameters, spec_from_args
from apc_lab.scenario import (
    CONFIG_DIR,
    paper_scenario,
    paper_settings,
    recommended_settings,
)

pytestmark = pytest.mark.ros


def _feedback(*files: str, **values) -> AdaptiveConfig:
    """The adaptive law's settings of a feedback node started from ``files`` (in apc's config
    directory) and parameter overrides ``values``."""
    context = rclpy.Context()
    args = ["--ros-args"] + [a for f in files for a in ("--params-file", str(CONFIG_DIR / f))]
    rclpy.init(args=args, context=context)
    node = None
    try:
        node = FeedbackNode(context=context, parameter_overrides=overrides(values))
        return node.law.settings
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_the_recommended_preset_is_the_default_everywhere():
    assert DEFAULT_PRESET == "recommended"
    shown = {p.name: p.default for p in PARAMS}
    assert shown["preset"] == "recommended"
    for key, value in recommended_settings().items():
        assert shown[f"adaptive.{key}"] == value, key
    assert build_parser().parse_args([]).preset == "recommended"


def test_the_node_starts_with_the_recommended_law():
    config = _feedback()
    for key, value in recommended_settings().items():
        assert getattr(config, key) == value, key


def test_the_paper_preset_is_one_parameter_away_and_a_setting_overrides_it():
    config = _feedback(preset="paper")
    for key, value in paper_settings().items():
        assert getattr(config, key) == value, key
    # What the paper preset leaves alone is the law's own default (one step, no integral).
    assert config.horizon == AdaptiveConfig.horizon and config.q_integral == 0.0
    assert _feedback(**{"preset": "paper", "adaptive.q_position": 5.0}).q_position == 5.0


def test_an_unknown_preset_stops_the_node_naming_it():
    with pytest.raises(ConfigError, match=r"^parameter 'preset': must be one of"):
        _feedback(preset="fast")
    with pytest.raises(ConfigError, match="preset"):
        law_params("fast")


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_a_run_gives_the_node_every_setting_so_its_preset_does_not_matter(preset):
    settings = PRESETS[preset]()
    params = RunSpec(paper_scenario("c"), "adaptive", settings).node_parameters()
    feedback = params["feedback_node"]
    written = {k.removeprefix("adaptive."): v for k, v in feedback.items() if "adaptive." in k}
    expected = AdaptiveConfig.from_dict({"period": 0.01, **settings})
    for key, value in written.items():
        assert getattr(expected, key) == value, key
    assert {f"adaptive.{k}" for k in written} == set(law_parameters("adaptive", {})) - {
        "controller"
    }
    args = build_parser().parse_args(["--preset", preset])
    assert spec_from_args(args).settings == settings


def test_the_shipped_file_runs_the_recommended_preset_and_the_paper_file_the_printed_one():
    recommended = dataclasses.asdict(_feedback("puma560_3dof.yaml"))
    for key, value in recommended_settings().items():
        assert recommended[key] == value, key
    paper = dataclasses.asdict(_feedback("puma560_3dof.yaml", "puma560_3dof_paper.yaml"))
    for key, value in paper_settings().items():
        assert paper[key] == value, key


@pytest.mark.parametrize("preset", ["recommended", "paper"])
def test_robot_node_takes_the_same_presets(preset):
    from apc_feedback.robot_node import RobotNode

    context = rclpy.Context()
    rclpy.init(context=context)
    node = None
    try:
        node = RobotNode(context=context, parameter_overrides=overrides({"preset": preset}))
        for key, value in PRESETS[preset]().items():
            assert node.get_parameter(f"adaptive.{key}").value == value, key
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
