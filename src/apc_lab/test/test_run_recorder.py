"""The interrupted runner's wait for resent samples, on a stand-in recorder and executor."""

from __future__ import annotations

import apc_msgs_py as wire
from apc_lab.run_recorder import PER_SAMPLE_TOPICS, wait_for_resends

STATES, SETPOINT, FF, FB, ESTIMATE = (
    f"/{t}"
    for t in (
        wire.JOINT_STATES,
        wire.SETPOINT,
        wire.FEEDFORWARD_TORQUE,
        wire.FEEDBACK_TORQUE,
        wire.ESTIMATE,
    )
)


class Recorder:
    def __init__(self, **counts: int) -> None:
        self.counts = {STATES: 0, SETPOINT: 0, FF: 0, FB: 0, ESTIMATE: 0}
        self.counts.update({f"/{getattr(wire, k)}": v for k, v in counts.items()})

    def resolve_topic_name(self, name: str) -> str:
        return f"/{name}"


class Wire:
    """An executor whose ``spin_once`` brings the run's next sample on every topic but those in
    ``stalled``, which a writer resends from call ``resend_after`` on (its heartbeat)."""

    def __init__(self, recorder: Recorder, stalled: set[str], resend_after: int | None) -> None:
        self.recorder, self.stalled, self.resend_after = recorder, stalled, resend_after
        self.calls = 0

    def spin_once(self, timeout_sec: float) -> None:
        self.calls += 1
        resending = self.resend_after is not None and self.calls >= self.resend_after
        for name in self.recorder.counts:
            if name not in self.stalled or resending:
                self.recorder.counts[name] += 1


def test_a_recorder_that_holds_every_sample_does_not_wait(capsys):
    recorder = Recorder(JOINT_STATES=40, SETPOINT=41, FEEDFORWARD_TORQUE=41, FEEDBACK_TORQUE=40)
    executor = Wire(recorder, set(), resend_after=None)
    assert not wait_for_resends(executor, recorder, lambda: True, quiet_s=0.0)
    assert executor.calls == 0
    assert capsys.readouterr().err == ""


def test_a_feedforward_ahead_is_not_a_loss():
    """Set points ahead of the plant's last joint state, or sent again for a resent one."""
    ahead = 40 + 3 * wire.MAX_LOOKAHEAD
    recorder = Recorder(
        JOINT_STATES=40, FEEDBACK_TORQUE=40, SETPOINT=ahead, FEEDFORWARD_TORQUE=ahead
    )
    executor = Wire(recorder, set(), resend_after=None)
    assert not wait_for_resends(executor, recorder, lambda: True, quiet_s=0.0)
    assert executor.calls == 0


def test_the_wait_lasts_until_every_topic_holds_the_newest_answered_sample(capsys):
    """The plant's joint states and the feedback's torques stalled at 85 (a lost sample each),
    its estimates and the set points went on to 427: the wait ends when joint states and
    torques are resent up to 427, not later (the run goes on meanwhile)."""
    recorder = Recorder(
        JOINT_STATES=85,
        FEEDBACK_TORQUE=85,
        ESTIMATE=427,
        SETPOINT=428,
        FEEDFORWARD_TORQUE=428,
    )
    executor = Wire(recorder, {STATES, FB}, resend_after=5)
    assert wait_for_resends(executor, recorder, lambda: True, quiet_s=0.0)
    assert all(recorder.counts[f"/{t}"] >= 427 for t in PER_SAMPLE_TOPICS)
    assert executor.calls == 5 - 1 + 427 - 85
    err = capsys.readouterr().err
    assert "at sample 427, the recorder's /joint_states 85, /feedback/torque 85" in err


def test_the_wait_ends_with_the_plant_or_at_its_limit():
    recorder = Recorder(FEEDBACK_TORQUE=50)
    running = iter([True, True, True, False])
    executor = Wire(recorder, {STATES}, resend_after=None)
    wait_for_resends(executor, recorder, lambda: next(running), quiet_s=10.0)
    assert executor.calls == 3
    executor = Wire(recorder, {STATES}, resend_after=None)
    wait_for_resends(executor, recorder, lambda: True, most_s=0.0, quiet_s=10.0)
    assert executor.calls == 0


def test_the_plants_clock_says_how_far_the_run_is_when_no_answer_does(capsys):
    """Joint states and every answer stalled at 85 (all lost behind one gap), the plant's
    ``/clock`` at sample 300: the wait lasts until they are resent up to 300."""
    recorder = Recorder(
        JOINT_STATES=85, FEEDBACK_TORQUE=85, ESTIMATE=85, SETPOINT=86, FEEDFORWARD_TORQUE=86
    )
    executor = Wire(recorder, {STATES, FB, ESTIMATE}, resend_after=3)
    assert wait_for_resends(executor, recorder, lambda: True, published=300, quiet_s=0.0)
    assert recorder.counts[STATES] == 300 and recorder.counts[FB] == 300
    assert "at sample 300" in capsys.readouterr().err
