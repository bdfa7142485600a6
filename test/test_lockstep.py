"""A lockstep ROS run equals the offline closed loop, bit for bit, in one and in three processes.

This is the integration test that catches off-by-one sample bugs: the recording of the real
nodes over DDS is read back and compared with :func:`apc_lab.scenario.run_offline` on
every recorded signal.
"""

from __future__ import annotations

import numpy as np
import pytest

from apc_lab.experiment import RunSpec, run_in_process, run_in_processes
from apc_lab.scenario import (
    paper_scenario,
    paper_settings,
    recommended_settings,
    run_offline,
)
from apc_recording.runs import load_run

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
    assert np.all(np.isnan(recorded.applied[0]))
    np.testing.assert_allclose(recorded.applied[1:], offline.applied[:-1], rtol=0, atol=1e-12)


def _compare_identification(recorded, offline) -> None:
    np.testing.assert_allclose(recorded.trace_p, offline.trace_p, rtol=1e-12)
    # No residual without an identification step (sample 0, and with input lags the samples
    # until every lagged input is known): the estimate message carries 0 there.
    no_step = np.isnan(offline.residual_norm)
    assert no_step[0] and np.all(recorded.residual_norm[1:][no_step[1:]] == 0.0)
    np.testing.assert_allclose(
        recorded.residual_norm[~no_step], offline.residual_norm[~no_step], rtol=1e-12
    )
    theta_t = np.concatenate([offline.F, offline.G, offline.w[:, :, None]], axis=2)
    np.testing.assert_allclose(recorded.theta_t, theta_t, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("case", "controller", "settings"),
    [
        ("c", "adaptive", paper_settings(1.5e5)),
        ("c", "adaptive", recommended_settings(1500.0)),
        ("b", "computed_torque", None),
    ],
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


def test_a_real_recording_opens_in_independent_readers(tmp_path):
    """mcap with mcap_ros2's decoder, and rosbags (neither is ours), read every message."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    from apc_recording.bag import bag_info

    spec = RunSpec(paper_scenario("b", hold_s=0.0), "adaptive", paper_settings(), name="readers")
    outcome = run_in_process(spec, tmp_path, progress=False, timeout_s=120)
    assert outcome.ok, outcome.message
    info = bag_info(outcome.path)
    assert info["profile"] == "ros2" and info["complete"]
    counts = {topic: t["message_count"] for topic, t in info["topics"].items()}
    assert counts["/joint_states"] == counts["/feedback/torque"] == 101

    recorded = load_run(outcome.path)
    seen = {}
    with open(outcome.path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if channel.topic == "/joint_states":
                k = round((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) / 1e7)
                np.testing.assert_array_equal(msg.position, recorded.q[k])
    assert seen == {t: c for t, c in counts.items() if c}

    with AnyReader([outcome.path]) as reader:
        by_topic = {}
        for connection, _, data in reader.messages():
            msg = reader.deserialize(data, connection.msgtype)
            by_topic[connection.topic] = by_topic.get(connection.topic, 0) + 1
            if connection.topic == "/feedback/torque":
                k = round((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) / 1e7)
                np.testing.assert_array_equal(msg.effort, recorded.du[k])
    assert by_topic == seen
