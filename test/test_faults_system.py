"""Process-level faults: dying nodes, signals, a killed recorder.

Every node here runs as its own process (``sys.executable -m <package>.<module>``), as on a
robot (:class:`support.processes.Children`); an in-test rclpy node
(:class:`support.observer.Observer`) watches ``joint_states``, the torques and ``/diagnostics``.
Times measured here are printed (``pytest -s``) and quoted in docs/reliability.md; what is
asserted are the documented bounds plus a scheduling margin.

- a feedback node that dies (SIGKILL) in real time: the plant applies the nominal torque
  alone and reports a warning; a feedforward node that dies: the plant brakes within the
  watchdog window and reports a fault; restarted, the loop resumes. Real time here runs on a
  ``/clock`` the test moves (:mod:`support.sim_clock`), so the watchdog is asserted sample by
  sample, not against a wall clock. In lockstep a dead peer ends the plant with exit code 1
  and an error naming it;
- SIGINT / SIGTERM end every node and the ``experiment`` runner within 2 s, leaving no child
  process and a complete recording;
- a recorder killed with SIGKILL leaves a readable file that holds an exact prefix of what was
  published, losing less than one chunk interval.

A lossy network between the nodes: ``test_faults_system_network.py``; long runs (offline):
``test_faults_system_long_runs.py``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import random
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from support.arm import ROBOT, T_NS
from support.observer import Observer
from support.processes import Children, process_group, wait_all, write_params
from support.report import report
from support.sim_clock import FB, FF, ClockStepper

import apc_msgs_py as wire
from apc_lab.experiment import RunSpec
from apc_lab.run_recorder import RESEND_WAIT_S
from apc_lab.scenario import paper_scenario, paper_settings
from apc_recording.bag import BagTruncatedWarning, bag_info, read_messages
from apc_recording.bag.recovery import main as bag_recover

T = 0.010
WATCHDOG_S = 0.05
#: The feedforward node's lookahead (its default): how many samples ahead its torques are.
LOOKAHEAD = 1


# ----------------------------------------------------------------------------------------------
# Real-time runs, and what the observer sees of them
# ----------------------------------------------------------------------------------------------
def realtime_params(
    case: str = "c", segment_times: tuple[float, float, float] | None = None, **plant: object
) -> dict:
    """Node parameters of the paper's case for a real-time run that lasts until stopped (its
    move's ``segment_times`` changed if given)."""
    scenario = paper_scenario(case, hold_s=0.0)
    if segment_times is not None:
        scenario = dataclasses.replace(scenario, segment_times=segment_times)
    spec = RunSpec(scenario, "adaptive", paper_settings())
    params = spec.node_parameters()
    params["plant_node"].update(
        mode="realtime", n_samples=0, watchdog_s=WATCHDOG_S, wait_for_subscribers=3
    )
    params["plant_node"].update(plant)
    return params


def _braked(state) -> bool:
    return bool(np.all(state[3] == 0.0))


# ----------------------------------------------------------------------------------------------
# 1. A controller node dies mid-run
# ----------------------------------------------------------------------------------------------
@pytest.mark.ros
@pytest.mark.slow
def test_controller_death_watchdog_and_restart_in_simulated_time(tmp_path, observer):
    """Real time on a clock the test moves (:class:`support.sim_clock.ClockStepper`), three
    processes, case (c) slowed to a 5 s move, sample by sample whatever the machine's load.

    Kill the feedback: from the sample its last torque goes stale (``watchdog_s`` after the
    sample it answered) the nominal torque alone, WARN with ``feedback_missing_samples``.
    Restart it: both torques again, OK. Kill the feedforward: from the sample its last nominal
    torque goes stale the arm brakes (zero velocity, constant position), ERROR with
    ``watchdog_trips``. Restart it: the brake is released and the arm moves (the new
    feedforward plans its move from the measured position); the feedback does not identify
    across the samples it had no set point for.

    Which torques the plant held at a tick is read from what it reports having applied (each
    joint state's effort): the clock waits until the observer has seen both answers, but a
    process preempted between delivering a message to the observer and to the plant (a
    loaded machine) makes a torque late at the plant now and then, as on a robot; the rules
    are asserted on the torques the plant had.
    """
    obs = observer
    params = realtime_params(segment_times=(1.0, 3.0, 1.0), use_sim_time=True, publish_clock=False)
    kids = Children(tmp_path, write_params(tmp_path / "params.yaml", params))
    stale = round(WATCHDOG_S / T) + 1  # a torque answering sample j is stale from j + stale on
    try:
        kids.start_controllers()
        obs.spin_until(obs.controllers_up, 30, "controllers' publishers")
        kids.start("plant_node")
        clock = ClockStepper(obs, T_NS, LOOKAHEAD, list(kids.procs.values()))
        k = clock.start()
        while k < 100:
            k = clock.step()
        late = _assert_both_fresh(obs, 1, k, stale)

        # -- feedback dies: nominal torque alone once its last torque is stale, WARN ----------
        killed = k
        _kill(kids, "feedback_node")
        clock.procs = [kids.procs["plant_node"], kids.procs["feedforward_node"]]
        for _ in range(stale + 20):
            k = clock.step((FF,))
        states = _by_sample(obs)
        used = [_sources(obs, states[j]) for j in range(killed + 1, k + 1)]
        last_fb = max(m_fb for _, m_fb in used if m_fb is not None)
        assert killed - stale < last_fb <= killed, used
        # The tick of sample j applies its torques over [j, j+1): joint state j + 1 reports it.
        first_nominal = last_fb + stale + 1
        for j in range(killed + 1, k + 1):
            m_ff, m_fb = _sources(obs, states[j])
            assert m_ff is not None and j - 1 - m_ff < stale, (j, m_ff)
            # (a torque late at the plant may still come after an older one was applied)
            assert (m_fb is not None) == (j < first_nominal), (j, m_fb, first_nominal)
        assert np.ptp([states[j][2] for j in range(first_nominal, k + 1)], axis=0).max() > 0.0
        level, message, values = _plant_diagnostics(obs)  # the plant does not tick meanwhile
        assert level == DiagnosticStatus.WARN and "feedback" in message, message
        assert int(values["feedback_missing_samples"]) == k - first_nominal + 1, values
        assert int(values.get("watchdog_trips", 0)) == 0, values

        # -- feedback restarted: both torques again, OK ---------------------------------------
        kids.start("feedback_node")
        clock.procs = list(kids.procs.values())
        clock.step_until_answered(FB, (FF,), max_samples=300)
        back = _step_until(clock, lambda j: _sources(obs, _by_sample(obs)[j])[1] is not None)
        for _ in range(20):
            k = clock.step()
        late += _assert_both_fresh(obs, back, k, stale)
        level, message, values = _plant_diagnostics(obs)
        assert level == DiagnosticStatus.OK, message

        # -- feedforward dies: the brake once its last nominal torque is stale, ERROR ---------
        killed = k
        _kill(kids, "feedforward_node")
        clock.procs = [kids.procs["plant_node"], kids.procs["feedback_node"]]
        for _ in range(LOOKAHEAD + stale + 30):
            k = clock.step(())
        states = _by_sample(obs)
        used = [_sources(obs, states[j])[0] for j in range(killed + 1, k + 1)]
        last_ff = max(m for m in used if m is not None)
        # The last nominal torque was sent ahead, with the joint state before the kill.
        assert killed - stale < last_ff <= killed + LOOKAHEAD, used
        first_braked = last_ff + stale + 1
        for j in range(killed + 1, first_braked):
            assert not _braked(states[j]), j
        held = states[first_braked - 1][2]
        for j in range(first_braked, k + 1):
            assert _braked(states[j]) and np.array_equal(states[j][2], held), j
            assert states[j][4] is not None and np.all(states[j][4] == 0.0), j
        level, message, values = _plant_diagnostics(obs)
        assert level == DiagnosticStatus.ERROR and "brake" in message, message
        assert int(values["watchdog_trips"]) == 1, values
        assert int(values["braked_samples"]) == k - first_braked + 1, values

        # -- feedforward restarted: the brake released, the arm moves, OK --------------------
        kids.start("feedforward_node")
        clock.procs = list(kids.procs.values())
        clock.step_until_answered(FF, (), max_samples=300)
        # The feedback answers once it has discovered the new node's set points.
        clock.step_until_answered(FB, (FF,), max_samples=300)
        back = _step_until(clock, lambda j: _sources(obs, _by_sample(obs)[j]) != (None, None))
        for _ in range(40):
            k = clock.step()
        states = _by_sample(obs)
        after = [states[j] for j in range(back, k + 1)]
        assert not any(_braked(s) for s in after)
        late += _assert_both_fresh(obs, back + stale, k, stale)
        assert np.ptp([s[2] for s in after], axis=0).max() > 0.0, "the arm does not move"
        level, message, values = _plant_diagnostics(obs)
        assert level == DiagnosticStatus.OK, message
        assert int(values["watchdog_trips"]) == 1, values
        # The feedback saw no set point while the feedforward was down: its first sample after
        # the restart is not one period after its last, so that step is not identified.
        obs.spin_until(
            lambda: int(obs.feedback_diag.get("rls_skipped_updates", 0)) >= 1,
            5,
            "the feedback's skipped identification step",
        )
        assert all(np.all(np.isfinite(s[2])) for s in obs.states)
        report("controller death and restart in simulated time", late_torques_at_plant=late)
    finally:
        kids.close()


def _sources(obs: Observer, state, depth: int = 10) -> tuple[int | None, int | None]:
    """Whose torques a joint state reports applied: ``(m_ff, m_fb)``, the samples whose ``u_n``
    and ``du`` sum (within the effort limits) to its effort, the newest that fit; ``m_fb`` None
    for the nominal torque alone; ``(None, None)`` for neither (braked)."""
    j, effort = state[1] // T_NS, state[4]
    limit = ROBOT.effort_limit
    for m_ff in range(j - 1, j - 2 - depth, -1):
        ff = obs.ff.get(m_ff * T_NS)
        if ff is None:
            continue
        for m_fb in range(j - 1, j - 2 - depth, -1):
            fb = obs.fb.get(m_fb * T_NS)
            if fb is not None and np.array_equal(effort, np.clip(ff + fb, -limit, limit)):
                return m_ff, m_fb
        if np.array_equal(effort, np.clip(ff, -limit, limit)):
            return m_ff, None
    return None, None


def _assert_both_fresh(obs: Observer, first: int, last: int, stale: int) -> int:
    """Joint states ``first..last`` report both torques applied, each of them fresh (answering
    a sample less than ``stale`` before); how many of them were late (older than the sample)."""
    states, late = _by_sample(obs), 0
    for j in range(first, last + 1):
        m_ff, m_fb = _sources(obs, states[j])
        assert m_ff is not None and m_fb is not None, (j, m_ff, m_fb)
        assert j - 1 - min(m_ff, m_fb) < stale, (j, m_ff, m_fb)
        late += min(m_ff, m_fb) < j - 1
    return late


def _step_until(clock: ClockStepper, taken, max_samples: int = 300) -> int:
    """Step with both controllers answering until ``taken(j)`` holds for the new joint state
    ``j``: the plant discovers a restarted node in a while of its own, and until then applies
    what it had; ``j``."""
    for _ in range(max_samples):
        j = clock.step()
        if taken(j):
            return j
    raise AssertionError(f"the plant did not take the restarted node's torques in {max_samples}")


def _by_sample(obs: Observer) -> dict:
    """The joint states seen, by sample index (a resent state 0 counts once)."""
    return {s[1] // T_NS: s for s in obs.states}


def _kill(kids: Children, key: str) -> None:
    """SIGKILL a node and wait until it is gone: it must not answer the next sample."""
    kids.kill(key)
    kids.procs[key].wait(10)


def _plant_diagnostics(obs: Observer) -> tuple[int, str, dict[str, str]]:
    """The plant's next ``/diagnostics`` (sent every second of wall time): level, message,
    values. The test does not move the clock meanwhile, so it is the state of now."""
    t = time.monotonic()
    obs.spin_until(lambda: obs.diag_after(t), 5, "the plant's diagnostics")
    _, level, message, values = obs.diag_after(t)[0]
    return level, message, values


@pytest.mark.ros
@pytest.mark.slow
def test_lockstep_three_processes_peer_killed_ends_with_error(tmp_path, observer):
    """Lockstep, three processes: SIGKILL the feedback mid-run; the plant exits 1 after its
    ``lockstep_timeout_s`` (the spin's bound, timeout + 5 s, is the liveness limit).

    (``lockstep_timeout_s`` also bounds the wait for the peers at start, and discovering a new
    process took up to ~3 s here: FastDDS re-announces a participant every few seconds when its
    first announcements are missed.)
    """
    obs = observer
    timeout_s = 4.0
    params = RunSpec(paper_scenario("a", hold_s=10.0), "computed_torque").node_parameters()
    params["plant_node"].update(lockstep_timeout_s=timeout_s, resend_s=0.2)
    kids = Children(tmp_path, write_params(tmp_path / "params.yaml", params))
    try:
        kids.start_controllers()
        obs.spin_until(obs.controllers_up, 30, "controllers' publishers")
        plant = kids.start("plant_node")
        obs.spin_until(lambda: obs.k() >= 20, 30, "lockstep samples", [plant])
        t_kill = kids.kill("feedback_node")
        obs.spin_until(lambda: plant.poll() is not None, timeout_s + 5, "the plant's exit")
        took = time.monotonic() - t_kill
        report("lockstep peer killed -> plant exit", took_s=took, timeout_s=timeout_s)
        assert plant.returncode == 1
        # Not before the timeout (less the part of a sample already waited when the feedback
        # died); how soon after it a loaded machine exits is reported, not asserted.
        assert took >= timeout_s - 0.5
        stderr = kids.stderr("plant_node")
        assert "no feedback/torque for sample" in stderr, stderr[-2000:]
        assert obs.k() < params["plant_node"]["n_samples"]
    finally:
        kids.close()


# ----------------------------------------------------------------------------------------------
# 2. Shutdown by signal
# ----------------------------------------------------------------------------------------------
SIGNALS = pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])


@pytest.mark.ros
@SIGNALS
def test_every_node_stops_on_signal_within_2s(tmp_path, observer, sig):
    """SIGINT/SIGTERM mid-run: plant, feedforward, feedback and recorder exit 0 within 2 s."""
    obs = observer
    bag = tmp_path / "nodes.mcap"
    params = realtime_params(wait_for_subscribers=4)  # ff, fb, recorder, observer
    kids = Children(tmp_path, write_params(tmp_path / "params.yaml", params))
    try:
        kids.start("recorder", "-p", f"output:={bag}")
        kids.start_controllers()
        obs.spin_until(
            lambda: obs.controllers_up() and obs.subscribers(wire.FEEDBACK_TORQUE) >= 1,
            30,
            "controllers and recorder",  # the recorder listening to the feedback
        )
        kids.start("plant_node")
        obs.spin_until(lambda: obs.k() >= 50, 30, "the run", list(kids.procs.values()))
        for proc in kids.procs.values():
            proc.send_signal(sig)
        stacks: dict[str, str] = {}  # of a node still there 2.5 s on: the next hang's cause
        took = wait_all(kids.procs, 10.0, stacks)
        report(f"{signal.Signals(sig).name} -> node exit", **{k: v for k, v in took.items()})
        for name, proc in kids.procs.items():
            native = f"\nnative stacks at 2.5 s:\n{stacks[name]}" if name in stacks else ""
            assert name in took, f"{name} still running 10 s after {signal.Signals(sig).name}"
            assert proc.returncode == 0, (name, proc.returncode, kids.stderr(name)[-2000:], native)
            assert took[name] <= 2.0, (name, took[name], native)
            assert "Traceback" not in kids.stderr(name), kids.stderr(name)[-2000:]
        info = bag_info(bag)
        assert info["complete"] is True
        # The recorder recorded the run, however far behind the plant a loaded machine left it
        # when the signal came (it takes what DDS handed it; the count is not a timing claim).
        assert info["topics"]["/joint_states"]["message_count"] >= 1
        assert info["topics"]["/robot_description"]["message_count"] == 1
    finally:
        kids.close()


#: ``python`` as a terminal starts a foreground job: SIGINT at its default disposition. A test
#: run in the background of a non-interactive shell (``make test &``) has SIGINT ignored, its
#: children inherit that, and the runner, as a program should, leaves an ignored SIGINT
#: ignored (:class:`apc_core.nodeutil.StopSignals`): SIGINT would then not stop it at all.
FOREGROUND = [
    sys.executable,
    "-c",
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])",
]


def _stop_runner_by_signal(
    tmp_path: Path, sig: int, processes: bool
) -> tuple[dict[str, int], int, str]:
    """Start the runner, signal it once 40 set points are out; check that it ends within 2 s,
    leaves no process of its group and finishes a complete recording; the recording's counts,
    the newest sample whose feedforward torque the observer had seen at the signal, and the
    end of the runner's stderr (its children's too: whether it waited for resends, how the
    plant ended).

    The observer does not subscribe to ``joint_states``: the runner's plant starts when three
    nodes listen (recorder, feedforward, feedback), and an extra listener could let it start
    before the recorder has matched it.
    """
    tmp_path.mkdir(parents=True, exist_ok=True)
    obs = Observer(states=False)
    out = tmp_path / "runs"
    cmd = [*FOREGROUND, "-m", "apc_lab.experiment", "--case", "c", "--hold", "60"]
    cmd += ["--quiet", "--out", str(out), "--name", "sig", "--timeout", "120"]
    cmd += ["--processes"] if processes else []
    with open(tmp_path / "runner.err", "wb") as err:
        runner = subprocess.Popen(
            cmd, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True
        )
    try:
        # The recorder's side of its match with the plant may come after the plant's (which
        # starts the run): the plant's writer then repairs what the recorder dropped meanwhile
        # (apc_msgs_py.CONTROL_WRITER_DEPTH). The signal comes 40 samples after the recorder
        # says it hears the plant; 30 required in the file, from sample 0: samples still in
        # flight to the recorder when the signal lands may be missing from it.
        heard = f"/{wire.JOINT_STATES}: 1 publisher"
        obs.spin_until(
            lambda: heard in (tmp_path / "runner.err").read_text(), 60, "the run", [runner]
        )
        seen = len(obs.ff)
        obs.spin_until(lambda: len(obs.ff) >= seen + 40, 60, "40 samples on", [runner])
        newest = max(obs.ff) // T_NS  # keyed by stamp kT
        t0 = time.monotonic()
        runner.send_signal(sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            runner.wait(10)
        took = time.monotonic() - t0
        left = process_group(runner.pid)
        stderr = (tmp_path / "runner.err").read_text(errors="replace")
        # A recorder that lost a sample keeps the run going until the sample's writer resends
        # it at its next heartbeat, and says so.
        resent = "keeping the run up to" in stderr
        # A child whose teardown blocks (experiment.INTERRUPTED_STOP_S) is killed and named.
        killed = [line for line in stderr.splitlines() if "did not stop on SIGINT" in line]
        report(
            f"{signal.Signals(sig).name} -> experiment exit",
            processes=processes,
            took_s=took,
            returncode=runner.returncode,
            left=len(left),
            resent=resent,
            killed=killed,
        )
        assert runner.returncode is not None, f"runner still running after {took:.1f} s"
        assert not left, f"left behind: {left}"
        assert took <= 2.0 + (RESEND_WAIT_S if resent else 0.0), stderr[-3000:]
        assert runner.returncode == 1 and "interrupted" in stderr, stderr[-2000:]
        assert "Traceback" not in stderr, stderr[-2000:]
        info = bag_info(out / "sig.mcap")
        assert info["complete"] is True
        states = read_messages(out / "sig.mcap", topics=["/joint_states"])
        first = min(wire.stamp_to_ns(m.decode().header.stamp) for m in states)
        assert first == 0, f"the recording's first state: {first} ns"
        counts = {topic: t["message_count"] for topic, t in info["topics"].items()}
        return counts, newest, stderr[-3000:]
    finally:
        obs.close()
        if runner.poll() is None:
            runner.kill()
            runner.wait(5)
        if process_group(runner.pid):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(runner.pid, signal.SIGKILL)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("processes", [False, True], ids=["in_process", "processes"])
@SIGNALS
def test_experiment_runner_stops_on_signal_within_2s(tmp_path, sig, processes):
    """The runner ends within 2 s, leaves no process of its group, and finishes its recording
    with the samples seen on the wire, from sample 0 on (the plant's writer repairs what the
    recorder dropped before its side of the match: apc_msgs_py.CONTROL_WRITER_DEPTH) to the
    newest one the observer had seen when the signal came (the plant is stopped first and the
    recorder takes what is still queued for it: it lagged 13 samples behind once).

    With --processes, a recorder that lost a sample holds back every later one of its writer
    until the writer resends it at its next heartbeat: the runner keeps the run going until
    then and says so (up to RESEND_WAIT_S more). Stopped at once, the plant took the rest of
    the run with it: 1 run in 26 under two busy loops kept joint states 0-21 of 108, and one in
    CI kept none."""
    counts, newest, stderr = _stop_runner_by_signal(tmp_path, sig, processes)
    assert counts["/joint_states"] >= 30, (counts, stderr)
    assert counts["/feedforward/torque"] >= newest + 1, (counts, newest, stderr)


# ----------------------------------------------------------------------------------------------
# 3. The recorder killed with SIGKILL
# ----------------------------------------------------------------------------------------------
@pytest.mark.ros
@pytest.mark.slow
def test_killed_recorder_keeps_an_exact_prefix_of_the_run(tmp_path):
    """SIGKILL the recorder mid-run: the file reads (truncated), is an exact prefix of what was
    published on every topic, loses at most the chunk still open, and recovers to a complete
    file that rosbags opens.

    Real time on a ``/clock`` the test moves (:mod:`support.sim_clock`), the recorder on it too:
    its chunks close by log time, so the open chunk spans at most ``max_chunk_interval_s`` of
    samples, whatever the machine's load. The clock stops at a sample anywhere within a chunk;
    the recorder is killed after it has had a second to take what was sent (the wait adds no
    log time: the open chunk spans what it did when the clock stopped).
    """
    from rosbags.highlevel import AnyReader

    interval_s = 0.2
    obs = Observer(raw=True)
    bag = tmp_path / "killed.mcap"
    # ff, fb, the recorder and the observer listen to the joint states
    params = realtime_params(wait_for_subscribers=4, use_sim_time=True, publish_clock=False)
    kids = Children(tmp_path, write_params(tmp_path / "params.yaml", params))
    try:
        kids.start(
            "recorder",
            "-p",
            f"output:={bag}",
            "-p",
            f"max_chunk_interval_s:={interval_s}",
            "-p",
            "use_sim_time:=true",
        )
        kids.start_controllers()
        obs.spin_until(
            lambda: obs.controllers_up() and obs.subscribers(wire.FEEDBACK_TORQUE) >= 2,
            30,
            "controllers and recorder",  # the observer and the recorder listening to the feedback
        )
        obs.spin_for(1.0)  # let the recorder match the controllers' writers
        kids.start("plant_node")
        clock = ClockStepper(obs, T_NS, LOOKAHEAD, list(kids.procs.values()))
        k = clock.start()
        last = 250 + random.randrange(round(interval_s / T))  # anywhere within a chunk
        while k < last:
            k = clock.step()
        obs.spin_for(1.0)  # the clock stands at sample `last`
        kids.kill("recorder")
        obs.spin_for(0.3)
    finally:
        kids.close()
        obs.close()

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recorded = list(read_messages(bag, log_time_order=False))
    assert any(issubclass(w.category, BagTruncatedWarning) for w in caught)
    assert bag_info(bag)["complete"] is False
    by_key: dict[tuple[str, str], list[bytes]] = {}
    for m in recorded:
        key = m.topic, (m.decode().status[0].name if m.topic == "/diagnostics" else "")
        by_key.setdefault(key, []).append(bytes(m.data))
    js = ("/joint_states", "")
    assert len(by_key.get(js, [])) >= 150
    counts = {}
    for key, published in obs.raw.items():
        if key[0] == "/clock":
            continue  # best effort by design (KEEP_LAST 1): either side may drop one
        got = by_key.get(key, [])
        data = [d for _, d in published]
        if key[0] == "/diagnostics":
            # A node's first statuses (one a second from its start) may come before the
            # recorder or the observer has discovered it (up to ~3 s): compare from the first
            # status both have.
            skip = next((i for i, d in enumerate(got) if d in data), len(got))
            assert skip <= 5, (key, skip)
            got = got[skip:]
        start = data.index(got[0]) if got else 0
        # Control topics are matched before the run starts.
        assert start == 0 or (key[0] == "/diagnostics" and start <= 5), (key, start)
        assert data[start : start + len(got)] == got, f"{key}: not an exact prefix"
        counts[key] = (len(got), len(data) - start - len(got))
    assert set(by_key) <= set(obs.raw)
    lost_js = counts[js][1]
    report(
        "recorder SIGKILL",
        recorded=len(recorded),
        joint_states_recorded=counts[js][0],
        joint_states_lost=lost_js,
        lost_per_topic={k[0] + (":" + k[1] if k[1] else ""): v[1] for k, v in counts.items()},
    )
    # The open chunk: at most the interval's samples (the recorder's clock may lag the test's
    # by a few samples: /clock is best effort).
    assert lost_js <= round(interval_s / T) + 5, counts[js]

    fixed = tmp_path / "recovered.mcap"
    assert bag_recover([str(bag), str(fixed)]) == 0
    info = bag_info(fixed)
    assert info["complete"] is True and info["message_count"] == len(recorded)
    with AnyReader([fixed]) as reader:
        n = 0
        for connection, _, data in reader.messages():
            reader.deserialize(data, connection.msgtype)
            n += 1
    assert n == len(recorded)
