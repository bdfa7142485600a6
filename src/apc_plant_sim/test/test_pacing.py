"""The plant's wall-time rules (apc_plant_sim.pacing), no ROS graph and no clock: resend after
resend_s, the lockstep timeouts at start and at a sample, and where latency counts from."""

from __future__ import annotations

from apc_plant_sim.pacing import StatePacer


def test_peers_missing_time_out_from_the_node_s_creation():
    pacer = StatePacer(resend_s=0.5, timeout_s=10.0, now=100.0)
    assert not pacer.start_timed_out(110.0)
    assert pacer.start_timed_out(110.001)


def test_a_state_without_answers_is_sent_again_after_resend_s():
    pacer = StatePacer(resend_s=0.5, timeout_s=10.0, now=0.0)
    pacer.sent(1.0)
    assert not pacer.resend_due(1.5)
    assert pacer.resend_due(1.501)
    pacer.sent(1.501, resend=True)
    assert not pacer.resend_due(2.0) and pacer.resend_due(2.01)


def test_a_sample_times_out_from_its_first_send_not_its_resends():
    pacer = StatePacer(resend_s=0.5, timeout_s=2.0, now=0.0)
    pacer.sent(1.0)
    for t in (1.6, 2.2, 2.8):
        pacer.sent(t, resend=True)
    assert pacer.waited(3.0) == 2.0 and not pacer.sample_timed_out(3.0)
    assert pacer.sample_timed_out(3.01)
    pacer.sent(3.01)  # the next sample
    assert pacer.waited(3.5) == 3.5 - 3.01 and not pacer.sample_timed_out(3.5)


def test_the_pacer_reads_its_parameters():
    from apc_plant_sim.pacing import PACING_PARAMS

    values = {p.name: p.default for p in PACING_PARAMS}
    pacer = StatePacer.from_params(values, now=5.0)
    assert (pacer.resend_s, pacer.timeout_s, pacer.created) == (0.5, 10.0, 5.0)
