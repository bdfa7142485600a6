"""The runners' recorder: start it, know when it hears the controllers, and let it catch up with
what is on the wire before a run's writers go away.

A reliable reader delivers a writer's samples in order: after a loss (a sample dropped on a
loaded machine, or sent before the reader's side of the match) it holds back every later sample
of that writer until the writer resends the lost one, which Fast DDS does once a heartbeat of
the writer brings the reader's request for it: often within 0.1 s, at the latest at the
writer's periodic heartbeat (every :data:`HEARTBEAT_PERIOD_S`). A writer that has left resends
nothing: the reader loses everything from the gap on. A writer resends only what its history
still holds (``apc_msgs_py.CONTROL_WRITER_DEPTH`` samples): a lockstep run that goes on for a
heartbeat may have run further than that past a lost sample, which is then gone for good.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import rclpy
from rclpy.parameter import Parameter

import apc_msgs_py as wire

#: Fast DDS's default heartbeat period of a reliable writer (``WriterTimes.heartbeat_period``,
#: https://docs.ros.org/en/rolling/p/fastdds/generated/structeprosima_1_1fastdds_1_1rtps_1_1WriterTimes.html):
#: the longest a reader waits, after a loss, for the writer to resend.
HEARTBEAT_PERIOD_S = 3.0
#: How long an interrupted run keeps the plant for its writer to resend: a heartbeat and a margin.
RESEND_WAIT_S = HEARTBEAT_PERIOD_S + 0.5

#: Topics of which a complete lockstep recording holds a message for every sample 0..n.
PER_SAMPLE_TOPICS = (
    wire.JOINT_STATES,
    wire.SETPOINT,
    wire.FEEDFORWARD_TORQUE,
    wire.FEEDBACK_TORQUE,
)


def recorder_node(
    path: Path, context: rclpy.Context, description: Mapping[str, Any], sim_time: bool = True
) -> Any:
    """A recorder writing ``path``, the run's description in ``custom_data['apc.run']`` (what
    :func:`apc_recording.runs.load_run` reads back)."""
    import yaml

    from apc_recording.recorder import RecorderNode

    return RecorderNode(
        output=path,
        context=context,
        parameter_overrides=[Parameter("use_sim_time", value=sim_time)],
        custom_data={"apc.run": yaml.safe_dump(dict(description), sort_keys=False)},
    )


def recorder_hears_controllers(recorder: Any, controller: str) -> bool:
    """True once the recorder has discovered the controllers' publishers (so sample 0 is kept)."""
    topics = [wire.SETPOINT, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE]
    if controller == "adaptive":
        topics.append(wire.ESTIMATE)
    return all(recorder.count_publishers(recorder.resolve_topic_name(t)) >= 1 for t in topics)


def drain(
    executor: Any,
    recorder: Any,
    n_samples: int,
    stop: Any,
    least_s: float = 0.5,
    most_s: float = HEARTBEAT_PERIOD_S,
) -> None:
    """Let the recorder take what is still queued once the plant has finished: at least
    ``least_s`` (the plant's final /diagnostics), and up to ``most_s`` until it holds every
    sample 0..``n_samples`` of the per-sample topics (a recorder that lagged behind a fast
    lockstep run catches up instead of the file losing its tail; a sample lost on its way comes
    back at a heartbeat of its writer, while the writer is still there)."""
    names = [recorder.resolve_topic_name(t) for t in PER_SAMPLE_TOPICS]
    t0 = time.monotonic()
    while True:
        elapsed = time.monotonic() - t0
        complete = all(recorder.counts.get(name, 0) > n_samples for name in names)
        if elapsed >= most_s or (elapsed >= least_s and complete):
            return
        executor.spin_once(timeout_sec=0.01)
        stop.check()


def wait_for_resends(
    executor: Any,
    recorder: Any,
    plant_running: Any,
    published: int = 0,
    most_s: float = RESEND_WAIT_S,
    quiet_s: float = 0.2,
) -> bool:
    """After a signal, before the nodes (other processes) are stopped: wait, while
    ``plant_running()`` and at most ``most_s``, until the recorder holds every per-sample topic
    up to the newest joint state that it holds, or holds an answer to, at the signal, or the
    ``published`` samples the plant's clock says it had (``/clock`` is best effort: no loss holds
    it back). Whether it waited past ``quiet_s`` (and said so on stderr).

    In lockstep every sample has a joint state, a set point and the two torques; a recorder
    short of one of them lags (it catches up in milliseconds) or lost one, and then holds every
    later sample of that writer back: the writer must live until its next heartbeat to resend
    it, or the recording ends at the gap (a plant stopped at once took joint states 22-107 of a
    run with it, in another run all of them). The run goes on meanwhile; the recording holds
    every sample up to the signal, and more after it, unless a lockstep run outran the writers'
    history (module docstring). The feedforward's messages are no evidence: it sends again what
    it sent for a joint state the plant resends.
    """
    names = [recorder.resolve_topic_name(t) for t in PER_SAMPLE_TOPICS]
    count = recorder.counts.get
    # The feedback's torque or estimate k answers joint state k: the plant published it.
    answers = [recorder.resolve_topic_name(t) for t in (wire.FEEDBACK_TORQUE, wire.ESTIMATE)]
    wanted = max(
        published,
        count(recorder.resolve_topic_name(wire.JOINT_STATES), 0),
        *(count(name, 0) for name in answers),
    )

    def short() -> list[str]:
        return [n for n in names if count(n, 0) < wanted]

    t0 = time.monotonic()
    said = False
    while (missing := short()) and plant_running():
        waited = time.monotonic() - t0
        if waited >= most_s:
            break
        if waited >= quiet_s and not said:
            have = ", ".join(f"{n} {count(n, 0)}" for n in missing)
            print(
                f"experiment: the run is at sample {wanted}, the recorder's {have}; "
                f"keeping the run up to {most_s:.1f} s for their writers to resend them",
                file=sys.stderr,
                flush=True,
            )
            said = True
        executor.spin_once(timeout_sec=0.01)
    return said


def take_what_is_queued(
    executor: Any, recorder: Any, quiet_s: float = 0.1, most_s: float = 1.0
) -> None:
    """With the plant stopped (after an interruption, or at the end of a robot-mode run): let
    the recorder take what is still queued for it, until it has taken nothing for ``quiet_s``
    (other callbacks, such as the stopped plant's unmatched publishers, do not count), at most
    ``most_s``. A recorder that lagged behind a fast lockstep run, or a loaded machine's
    robot, would otherwise lose the samples in flight, published before the stop."""
    t0 = last = time.monotonic()
    taken = sum(recorder.counts.values())
    while (now := time.monotonic()) - last < quiet_s and now - t0 < most_s:
        executor.spin_once(timeout_sec=0.01)
        if (count := sum(recorder.counts.values())) != taken:
            taken, last = count, time.monotonic()
