"""A lockstep ROS run equals the offline closed loop, bit for bit, in one and in three processes.

This is the integration test that catches off-by-one sample bugs: the recording of the real
nodes over DDS is read back and compared with :func:`apc_plant_sim.scenario.run_offline` on
every recorded signal.
"""

from __future__ import annotations

import numpy as np
import pytest

from apc_plant_sim.experiment import RunSpec, run_in_process, run_in_processes
from apc_plant_sim.recording import load_run
from apc_plant_sim.scenario import paper_scenario, paper_settings, run_offline

pytestmark = pytest.mark.ros


def _compare(recorded, offline) -> None:
    n = len(offline.t)
    assert len(recorded.t) == n
    np.testing.assert_allclose(recorded.t, offline.t, rtol=0, atol=1e-12)
    for name in ("q", "qd", "q_d", "qd_d", "qdd_d", "u_n", "du"):
        np.testing.assert_allclose(
            getattr(recorded, name), getattr(offline, name), rtol=0, atol=1e-12, err_msg=name
        )
    # joint_states(k).effort is what was applied over [(k-1)T, kT).
    assert np.all(np.isnan(recorded.effort[0]))
    np.testing.assert_allclose(recorded.effort[1:], offline.applied[:-1], rtol=0, atol=1e-12)


def _compare_identification(recorded, offline) -> None:
    np.testing.assert_allclose(recorded.trace_p, offline.trace_p, rtol=1e-12)
    np.testing.assert_allclose(recorded.residual_norm[1:], offline.residual_norm[1:], rtol=1e-12)
    theta = np.concatenate([offline.F, offline.G, offline.w[:, :, None]], axis=2)
    np.testing.assert_allclose(recorded.theta, theta, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("case", "controller", "settings"),
    [("c", "adaptive", paper_settings(1.5e5)), ("b", "computed_torque", None)],
)
def test_lockstep_one_process_equals_offline(tmp_path, case, controller, settings):
    scenario = paper_scenario(case, hold_s=0.2)
    spec = RunSpec(scenario, controller, settings, "lockstep", name=f"{controller}_{case}")
    outcome = run_in_process(spec, tmp_path, progress=False, timeout_s=120)
    assert outcome.ok, outcome.message
    recorded = load_run(outcome.path)
    offline = run_offline(scenario, controller, settings)
    _compare(recorded, offline)
    if controller == "adaptive":
        _compare_identification(recorded, offline)


@pytest.mark.slow
def test_lockstep_three_processes_equals_offline(tmp_path):
    scenario = paper_scenario("c", hold_s=0.1)
    settings = paper_settings(1500.0)
    spec = RunSpec(scenario, "adaptive", settings, "lockstep", name="three_processes")
    outcome = run_in_processes(spec, tmp_path, progress=False, timeout_s=180)
    assert outcome.ok, outcome.message
    recorded = load_run(outcome.path)
    offline = run_offline(scenario, "adaptive", settings)
    _compare(recorded, offline)
    _compare_identification(recorded, offline)
