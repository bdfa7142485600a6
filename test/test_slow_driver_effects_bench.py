"""``bench/slow_driver_effects.py``'s parts: which effects a cell has and what ``told`` tells.

The bench's figures come from full runs (minutes); what is checked here, in milliseconds, is
that its variants change what they say they change: the effects of each arm's preset one at a
time, and the delay and velocity stencil a ``told`` law receives in place of robot mode's.
"""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import pytest
from support.bench import bench_module

from apc_feedback.linearize import VelocityStencil
from apc_lab.robot_compare import ARM_EFFECTS
from apc_plant_sim.effects import ArmEffects


@pytest.fixture(scope="module")
def sde():
    with bench_module("slow_driver_effects") as module:
        yield module


class _Law:
    """Records what robot mode would tell the adaptive law at a start."""

    def __init__(self) -> None:
        self.delay: tuple | None = None
        self.stencil: object = "untold"

    def expect_input_delay(self, seconds, candidates=(), exact=False):
        self.delay = (seconds, tuple(candidates)) + ((True,) if exact else ())

    def expect_velocity_stencil(self, stencil):
        self.stencil = stencil


def _told(sde, effects: ArmEffects, driver_period: float, stencil=None) -> _Law:
    law = _Law()
    sde.tell(effects, driver_period)(SimpleNamespace(law=law))
    # What robot mode's start tells: one driver period, two as a candidate; its stencil.
    law.expect_input_delay(driver_period, (2.0 * driver_period,))
    law.expect_velocity_stencil(stencil)
    return law


def test_each_arm_has_none_its_presets_effects_alone_and_all(sde):
    for arm in ("puma3", "panda"):
        effects = sde.effects_of(arm)
        assert list(effects)[:: len(effects) - 1] == ["none", "physical"]
        assert effects["none"] == ArmEffects() and effects["physical"] == ARM_EFFECTS[arm]()
        assert {"friction", "velocity_difference", "delay"} <= set(effects)
    assert "armature" in sde.effects_of("puma3") and "armature" not in sde.effects_of("panda")


def test_told_gives_the_drives_delay_and_differenced_velocity(sde):
    period = 0.01
    physical = _told(sde, ARM_EFFECTS["panda"](), period)
    assert physical.delay == (pytest.approx(2 * period), ())
    assert physical.stencil == VelocityStencil((0.0, period), (100.0, -100.0))
    # robot mode's call with a delay the driver's effort shows (exact) keeps the told delay
    sde.tell(ARM_EFFECTS["panda"](), period)(SimpleNamespace(law=physical))
    physical.expect_input_delay(0.03, (), True)
    assert physical.delay == (pytest.approx(2 * period), (), True)
    ideal = _told(sde, ArmEffects(), period)
    assert ideal.delay == (pytest.approx(period), ()) and ideal.stencil is None
    # robot mode's own estimate (a driver without velocity) is left as it is
    own = VelocityStencil((0.0, 0.01, 0.02), (150.0, -200.0, 50.0))
    assert _told(sde, ARM_EFFECTS["puma3"](), period, own).stencil == own


def test_the_table_has_a_column_per_variant_and_says_lost(sde):
    cell = {"arm": "puma3", "rate_hz": 100, "effects": "friction", "handover_runs": 0}
    cells = [
        {**cell, "variant": v, "median_max_deg": m, "max_deg": m, "final_deg": 0.0, "lost": lost}
        for v, m, lost in zip(sde.VARIANTS, (90.1, 1e6, 1.57, 1.57), (5, 5, 0, 0), strict=True)
    ]
    row = sde.markdown(cells).splitlines()[-1]
    assert row.startswith("| puma3 | 100 Hz | friction | 90.10; 90.10 / 0.00 (lost 5) | lost;")
    assert row.endswith("| 1.57; 1.57 / 0.00 |")


def test_a_cell_counts_a_run_that_blew_up_as_lost(sde):
    """The grid's summary (shared by this bench): a run whose errors are not finite (the
    simulation blew up) is the cell's worst and lost, whatever its place among the runs."""
    from robot_clock_offline import summarise

    nan = float("nan")
    fine = {"max_deg": [0.3, 0.2], "move_end_deg": [0.05, 0.1], "final_deg": [0.01, 0.02]}
    fine |= {"handovers": 0, "chatter_nm": 1.5}
    blown = {"max_deg": [nan, 0.2], "move_end_deg": [nan, 0.1], "final_deg": [nan, 0.0]}
    blown |= {"handovers": 1, "chatter_nm": nan}
    assert summarise([blown])["move_end_deg"] == float("inf")
    for runs in ([fine, blown, fine], [blown, fine, fine]):
        cell = summarise(runs)
        assert cell["max_deg"] == float("inf") and cell["final_deg"] == float("inf")
        assert cell["move_end_deg"] == 0.1  # over the runs not lost
        assert cell["chatter_nm"] == float("inf")
        assert cell["lost"] == 1 and cell["runs"] == 3 and cell["handover_runs"] == 1
        assert cell["median_max_deg"] == 0.3


def test_the_grid_overrides_the_presets_settings_as_their_own_types(sde):
    """``robot_clock_offline``'s ``--set NAME=VALUE`` (shared ``--alpha-model`` and
    ``--no-relinearize``): each value parsed as the preset's own is, a later one winning; an
    unknown name or a value of the wrong kind is an argparse error naming it."""
    import robot_clock_offline as rco

    parse = rco.parser().parse_args
    assert rco.overrides(parse([])) == {}
    argv = ["--set", "r=3e-6", "--alpha-model", "1e-3", "--set", "horizon=4", "--no-relinearize"]
    changed = rco.overrides(parse([*argv, "--set", "project_g=false", "--set", "r=1e-5"]))
    assert changed == {
        "r": 1e-5,
        "alpha_model": 1e-3,
        "horizon": 4,
        "relinearize": False,
        "project_g": False,
    }
    assert type(changed["horizon"]) is int and type(changed["r"]) is float
    for bad, says in (("foo=1", "'foo'"), ("horizon=2.5", "'horizon'"), ("rho", "NAME=VALUE")):
        with pytest.raises(SystemExit):
            parse(["--set", bad])
        with pytest.raises(argparse.ArgumentTypeError, match=says):
            rco.setting(bad)
