"""The player replays a recorded run: a fresh feedback node fed the recorded inputs answers with
the recorded torques, bit for bit; plus the window, rate, clock and command-line behaviour."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from support.nodes import overrides

import apc_msgs_py as wire
from apc_feedback.node import FeedbackNode
from apc_lab.experiment import RunSpec, run_in_process
from apc_lab.scenario import paper_scenario, paper_settings
from apc_recording.bag import read_messages
from apc_recording.player import PlayerNode, main

pytestmark = pytest.mark.ros

JS = "/" + wire.JOINT_STATES
SP = "/" + wire.SETPOINT
FB = "/" + wire.FEEDBACK_TORQUE
MS = 1_000_000


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[RunSpec, Path]:
    """One lockstep run of the adaptive law (case c, 0.1 s hold: 111 samples, 0 .. 1.10 s)."""
    spec = RunSpec(
        paper_scenario("c", hold_s=0.1),
        "adaptive",
        paper_settings(1.5e5),
        "lockstep",
        name="adaptive_c",
    )
    outcome = run_in_process(spec, tmp_path_factory.mktemp("run"), progress=False, timeout_s=60)
    assert outcome.ok, outcome.message
    for topic in (JS, SP, FB):
        stamps = [
            wire.stamp_to_ns(m.decode().header.stamp) for m in read_messages(outcome.path, topic)
        ]
        assert len(stamps) == len(set(stamps)), (
            f"{topic} recorded twice for some stamps: another process on "
            f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')} took part in the run"
        )
    return spec, outcome.path


class Collector(Node):
    """Keeps every message of one topic with its arrival time (monotonic s)."""

    def __init__(self, ctx: rclpy.Context, msg_type: type, topic: str, qos, **kwargs) -> None:
        super().__init__("collector", context=ctx, **kwargs)
        self.messages: list = []
        self.arrivals: list[float] = []
        self.sub = self.create_subscription(msg_type, topic, self._on_message, qos)

    def _on_message(self, msg) -> None:
        self.messages.append(msg)
        self.arrivals.append(time.monotonic())


def assert_alone(node: Node, publishers: dict[str, int]) -> None:
    """Fail clearly if another process on this ROS domain publishes on the test's topics.

    A feedback node of another process would answer the player too, and a plant would feed
    the feedback node: the values would differ for a reason that has nothing to do with the
    player.
    """
    for topic, count in publishers.items():
        found = [
            p.node_namespace.rstrip("/") + "/" + p.node_name
            for p in node.get_publishers_info_by_topic(topic)
        ]
        assert len(found) == count, (
            f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')} is shared with another process: "
            f"{found} publish {topic}, expected {count}"
        )


def stamps_ns(messages) -> list[int]:
    return [wire.stamp_to_ns(m.header.stamp) for m in messages]


def test_replay_into_fresh_feedback_gives_recorded_torques_exactly(recorded, graph):
    spec, path = recorded
    ctx = graph.context
    expected = {
        wire.stamp_to_ns(msg.header.stamp): msg
        for msg in (m.decode() for m in read_messages(path, FB))
    }
    n_states = sum(1 for _ in read_messages(path, JS))
    assert len(expected) == n_states > 100

    params = overrides(spec.node_parameters()["feedback_node"])
    feedback = graph.add(FeedbackNode(context=ctx, parameter_overrides=params))
    collector = graph.add(Collector(ctx, JointState, wire.FEEDBACK_TORQUE, wire.CONTROL_QOS))
    # The first torque must not be lost either: wait for feedback -> collector to match.
    graph.spin_until(lambda: feedback.torque_pub.get_subscription_count() >= 1, 30)
    player = graph.add(
        PlayerNode(context=ctx, bag=path, topics=[JS, SP], rate=5.0, wait_for_subscribers=1)
    )
    assert {t.recorded: t.published for t in player.played.values()} == {JS: JS, SP: SP}

    graph.spin_until(
        lambda: player.done and len(collector.messages) >= len(expected),
        60,
        f"all {len(expected)} torques",
    )
    # The feedforward ran one sample ahead: one set point more than joint states.
    assert player.published == {JS: n_states, SP: n_states + 1}
    assert_alone(collector, {JS: 1, SP: 1, FB: 1})
    assert feedback.diagnostics.counters == {"samples": n_states}
    got = {wire.stamp_to_ns(m.header.stamp): m for m in collector.messages}
    assert len(collector.messages) == len(got) == len(expected)
    assert sorted(got) == sorted(expected)
    for stamp, msg in expected.items():
        assert list(got[stamp].name) == list(msg.name)
        np.testing.assert_array_equal(
            np.array(got[stamp].effort), np.array(msg.effort), err_msg=f"stamp {stamp} ns"
        )


def test_window_selects_messages_by_log_time(recorded, graph):
    _, path = recorded
    ctx = graph.context
    collector = graph.add(Collector(ctx, JointState, wire.JOINT_STATES, wire.CONTROL_QOS))
    player = graph.add(PlayerNode(
        context=ctx, bag=path, topics=["joint_states"], start=0.2, duration=0.3, rate=0.0,
        wait_for_subscribers=1,
    ))  # fmt: skip
    graph.spin_until(lambda: player.done and len(collector.messages) >= 30, 30, "30 states")
    graph.spin_for(0.1)  # nothing more arrives
    # [0.2 s, 0.5 s), end excluded: samples 20 .. 49.
    assert stamps_ns(collector.messages) == [k * 10 * MS for k in range(20, 50)]
    assert player.published == {JS: 30}


def test_default_topics_leave_out_clock_and_diagnostics(recorded, graph):
    _, path = recorded
    player = graph.add(PlayerNode(context=graph.context, bag=path, duration=0.001))
    assert set(player.played) == {
        "/" + s.name for s in wire.TOPICS if s.name not in (wire.CLOCK, wire.DIAGNOSTICS)
    }
    graph.spin_until(lambda: player.done, 30, "the end of the window")
    # The first sample of every recorded topic (the goal topic holds no message), the set
    # point and nominal torque of sample 1, which the feedforward sent ahead at sim time 0,
    # and the arm's URDF the plant published at its start (robot_description).
    assert sum(player.published.values()) == 8
    assert player.published["/" + wire.ROBOT_DESCRIPTION] == 1


def test_rate_paces_the_pass_never_ahead_of_the_bag(recorded, graph):
    """Nothing goes out before its due time (0.59 s of bag time is the last message): a lower
    bound, which a loaded machine cannot break. The rate rule itself is test_playback's."""
    _, path = recorded
    for rate in (1.0, 2.0):
        player = graph.add(
            PlayerNode(
                f"player_{int(rate)}",
                context=graph.context,
                bag=path,
                topics=[JS],
                duration=0.6,
                rate=rate,
            )
        )
        graph.spin_until(lambda p=player: p.done, 30, f"the pass at rate {rate}")
        assert player.published == {JS: 60}
        assert player.pass_wall_s >= 0.59 / rate, (rate, player.pass_wall_s)


def test_loop_starts_over(recorded, graph):
    _, path = recorded
    ctx = graph.context
    collector = graph.add(Collector(ctx, JointState, wire.JOINT_STATES, wire.CONTROL_QOS))
    player = graph.add(PlayerNode(
        context=ctx, bag=path, topics=[JS], duration=0.03, rate=1.0, loop=True,
        wait_for_subscribers=1,
    ))  # fmt: skip
    graph.spin_until(lambda: len(collector.messages) >= 9, 30, "three passes")
    assert not player.done
    assert stamps_ns(collector.messages[:9]) == [0, 10 * MS, 20 * MS] * 3


def test_clock_follows_bag_time(recorded, graph):
    """``/clock`` carries the bag time: rising times within the window; how fast it advances
    is test_playback's (synthetic time), not this machine's load."""
    _, path = recorded
    ctx = graph.context
    follower = graph.add(
        Collector(
            ctx,
            Clock,
            wire.CLOCK,
            wire.CLOCK_QOS,
            parameter_overrides=overrides({"use_sim_time": True}),
        )
    )
    # Play once the follower's node listens (one context: both ends match together).
    follower.create_subscription(JointState, wire.JOINT_STATES, lambda _: None, 10)
    player = graph.add(
        PlayerNode(
            context=ctx,
            bag=path,
            topics=[JS],
            start=0.5,
            duration=0.4,
            rate=1.0,
            clock_hz=100.0,
            wait_for_subscribers=1,
        )
    )
    assert JS in player.played and "/clock" not in player.played
    graph.spin_until(lambda: player.done, 30, "the end of the window")
    ticks = [wire.stamp_to_ns(m.clock) for m in follower.messages]
    assert ticks and all(500 * MS <= t <= 900 * MS for t in ticks), ticks
    assert ticks == sorted(ticks) and ticks[-1] > ticks[0], ticks
    # A use_sim_time node's clock now follows the bag.
    assert 500 * MS <= follower.get_clock().now().nanoseconds <= 900 * MS


def test_clock_cannot_be_played_and_published(recorded, graph):
    _, path = recorded
    with pytest.raises(ValueError, match="parameter 'topics'"):
        PlayerNode(context=graph.context, bag=path, topics=["/clock"], clock_hz=10.0)


def test_remap_publishes_on_the_new_name(recorded, graph):
    _, path = recorded
    player = graph.add(
        PlayerNode(
            context=graph.context,
            bag=path,
            topics=[JS],
            remap=["/joint_states:=replay/joint_states"],
        )
    )
    assert player.played[JS].published == "/replay/joint_states"


def test_main_plays_to_the_end_and_exits_0(recorded):
    _, path = recorded
    assert main([str(path), "--topics", JS, "--duration", "0.05", "--rate", "0"]) == 0


def test_missing_bag_exits_2_with_one_line(tmp_path, capsys):
    assert main([str(tmp_path / "missing.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing.mcap" in err, err


def test_unreadable_bag_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file")
    assert main([str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.mcap" in err, err


def test_unknown_topic_exits_2(recorded, capsys):
    _, path = recorded
    assert main([str(path), "--topics", "/nope"]) == 2
    assert "/nope" in capsys.readouterr().err


def test_help_exits_0(capsys):
    assert main(["--help"]) == 0
    assert "--clock" in capsys.readouterr().out
