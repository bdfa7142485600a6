"""Plant and controllers in two network namespaces joined by a link with 2 ms delay and 1 %
loss (netem, or a user-space emulation of it over TAP devices where the kernel has no netem:
:class:`support.netns.Link`): real time on a stepped clock stays within 2x of the lossless
loop's error, lockstep still equals the offline loop bit for bit, real time on wall time
completes (its error is reported).

Every node runs as its own process (:class:`support.processes.Children`), as on two robots'
machines. Times and errors measured here are printed (``pytest -s``) and quoted in
docs/reliability.md. (Dying nodes, signals, a killed recorder: ``test_faults_system.py``.)
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from support.netns import Link
from support.nodes import recorded_diagnostics
from support.processes import Children, write_params
from support.report import report

import apc_msgs_py as wire
from apc_lab.experiment import RunSpec
from apc_lab.scenario import paper_scenario, paper_settings, run_offline

#: FastDDS writer/reader timings for a lossy link. A lost sample of a reliable topic holds back
#: every later one until it is repaired (in-order delivery); with FastDDS's defaults (heartbeat
#: every 3 s, 5 ms response delays) the repair took 50-110 ms at 1 % loss (p99 of a ROS ping
#: over this link 104 ms; with this profile 17 ms, max 54 ms), which is longer than the plant's
#: watchdog. A heartbeat every period and no response delays make repairs take ~1-2 periods.
FASTDDS_LOSSY_LINK_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="apc_lossy_link_writer" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>10000000</nanosec></heartbeatPeriod>
      <nackResponseDelay><sec>0</sec><nanosec>0</nanosec></nackResponseDelay>
    </times>
  </data_writer>
  <data_reader profile_name="apc_lossy_link_reader" is_default_profile="true">
    <times>
      <heartbeatResponseDelay><sec>0</sec><nanosec>0</nanosec></heartbeatResponseDelay>
    </times>
  </data_reader>
</profiles>
"""
#: The plant's watchdog on the lossy link: a repair (~20-50 ms) plus scheduling must not brake
#: the arm mid-move; 0.05 s (the default, for a local loop) did, now and then.
NETWORK_WATCHDOG_S = 0.1


def _run_across_link(
    link: Link, tmp_path: Path, name: str, mode: str, stepped: bool = False
) -> tuple[int, Path, str]:
    """Plant + recorder in namespace A, feedforward + feedback in B; case (c), 1 s move + 0.5 s.

    ``stepped``: real time on a ``/clock`` that a stepper beside the plant moves one period at
    a time once it has seen both controllers' answers to the last joint state
    (``python -m support.sim_clock``): the link's losses count (the plant takes torques best
    effort and a lost one is not repaired for it, while the stepper's reliable reader has it
    repaired); its delay counts only where the plant's copy of a torque arrives after the
    stepper's (a separate packet), which the load varies: 6-14 of 151 measured, well inside
    the 2x bound.

    Returns the plant's exit code, the recording and the plant's stderr.
    """
    scenario = paper_scenario("c", hold_s=0.5)
    params = RunSpec(scenario, "adaptive", paper_settings(), mode).node_parameters()
    params["plant_node"].update(
        resend_s=0.1, lockstep_timeout_s=10.0, watchdog_s=NETWORK_WATCHDOG_S
    )
    if stepped:
        params["plant_node"].update(
            use_sim_time=True,
            publish_clock=False,
            wait_for_subscribers=params["plant_node"]["wait_for_subscribers"] + 1,
        )
    run_dir = tmp_path / name
    run_dir.mkdir()
    kids = Children(run_dir, write_params(run_dir / "params.yaml", params))
    bag = run_dir / f"{name}.mcap"
    a = {"prefix": link.prefix(0), "env": link.env(0)}
    b = {"prefix": link.prefix(1), "env": link.env(1)}
    try:
        kids.start("recorder", "-p", f"output:={bag}", **a)
        kids.start("feedforward_node", **b)
        kids.start("feedback_node", **b)
        deadline = time.monotonic() + 30
        while not all(
            "running" in kids.stderr(k) or "recording" in kids.stderr(k)
            for k in ("recorder", "feedforward_node", "feedback_node")
        ):
            assert time.monotonic() < deadline, "nodes in the namespaces did not start"
            assert all(p.poll() is None for p in kids.procs.values())
            time.sleep(0.05)
        # Discovery across the link (seconds when a discovery message is lost): the recorder
        # says when it hears each controller topic, so it keeps sample 0.
        heard = [
            f"/{topic}: 1 publisher"
            for topic in (wire.SETPOINT, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE)
        ]
        while not all(line in kids.stderr("recorder") for line in heard):
            assert time.monotonic() < deadline + 30, (
                "the recorder did not hear the controllers",
                kids.stderr("recorder")[-2000:],
            )
            time.sleep(0.05)
        # ... and each controller's writer says when it has matched the recorder (and the
        # set point, the feedback too): the two sides of a match across the link come at
        # different times, and a torque published before its writer matched the recorder never
        # reaches the recording (VOLATILE).
        matched = {
            "feedforward_node": (
                f"/{wire.SETPOINT}: 2 subscriber",
                f"/{wire.FEEDFORWARD_TORQUE}: 1 subscriber",
            ),
            "feedback_node": (f"/{wire.FEEDBACK_TORQUE}: 1 subscriber",),
        }
        while not all(line in kids.stderr(k) for k, lines in matched.items() for line in lines):
            assert time.monotonic() < deadline + 60, (
                "the controllers' writers did not match the recorder",
                {k: kids.stderr(k)[-1500:] for k in matched},
            )
            time.sleep(0.05)
        if stepped:
            lookahead = params["feedforward_node"].get("lookahead", 1)
            _start_stepper(kids, a, round(scenario.period * 1e9), lookahead, scenario.n_samples)
        plant = kids.start("plant_node", **a)
        stepper = kids.procs.get("clock")
        deadline = time.monotonic() + 60
        while plant.poll() is None and time.monotonic() < deadline:
            if stepper is not None and stepper.poll() is not None:
                break  # the clock stopped: the plant would wait for ever
            time.sleep(0.05)
        hung = plant.poll() is None
        if not hung:
            time.sleep(0.5)  # the last torques reach the recorder
    finally:
        kids.close()
    if hung:
        clock = f"; the clock stepper's stderr: {kids.stderr('clock')[-1500:]}" if stepped else ""
        pytest.fail(
            f"{name}: the plant did not end; its counters {_plant_counters(bag)}{clock}; "
            f"its stderr: {kids.stderr('plant_node')[-1500:]}"
        )
    return plant.returncode, bag, kids.stderr("plant_node")


def _start_stepper(
    kids: Children, side: dict, period_ns: int, lookahead: int, n_samples: int
) -> None:
    """The ``/clock`` stepper (:mod:`support.sim_clock`) in the plant's namespace, up once it
    says it listens (its joint-state reader is one the plant waits for)."""
    path = [str(Path(__file__).parent), side["env"].get("PYTHONPATH", "")]
    env = dict(side["env"], PYTHONPATH=os.pathsep.join(p for p in path if p))
    args = (str(period_ns), str(lookahead), str(n_samples))
    proc = kids.start_module("clock", "support.sim_clock", *args, prefix=side["prefix"], env=env)
    deadline = time.monotonic() + 30
    while "listening" not in proc.stdout_path.read_text():
        assert proc.poll() is None, kids.stderr("clock")[-2000:]
        assert time.monotonic() < deadline, "the clock stepper did not start"
        time.sleep(0.05)


def _plant_counters(bag: Path) -> dict[str, str]:
    """The plant's last diagnostics counters in a recording (late, braked, watchdog ...)."""
    last = recorded_diagnostics(bag).get("plant_node", {})
    keys = ("late_samples", "braked_samples", "watchdog_trips", "feedback_missing_samples")
    return {k: last[k] for k in keys if k in last}


@pytest.mark.ros
@pytest.mark.slow
def test_network_namespaces_with_delay_and_loss(tmp_path):
    """Across 2 ms +- 0.5 ms delay and 1 % loss (each way): real time at 100 Hz on a clock
    stepped beside the plant keeps case (c) within 2x of the lossless offline loop's maximum
    error (lost and late torques handled by the plant's rules); lockstep completes (reliable
    QoS) and still equals the offline loop bit for bit; real time on wall time completes and
    records its samples (its error is reported, not asserted: on wall time it depends on the
    machine's load, as every wall-clock figure does).

    Deployment settings for the lossy link (docs/reliability.md): the FastDDS profile
    :data:`FASTDDS_LOSSY_LINK_PROFILE` and ``watchdog_s`` = :data:`NETWORK_WATCHDOG_S`.
    """
    from apc_recording.runs import load_run

    if os.geteuid() != 0:
        pytest.skip("network namespaces need root")
    scenario = paper_scenario("c", hold_s=0.5)
    end = scenario.move_end_sample
    offline = run_offline(scenario, "adaptive", paper_settings())
    offline_max = np.abs(offline.error[: end + 1]).max(axis=0)
    profile = tmp_path / "fastdds_lossy_link.xml"
    profile.write_text(FASTDDS_LOSSY_LINK_PROFILE)
    link = Link(tmp_path, {"FASTRTPS_DEFAULT_PROFILES_FILE": str(profile)})
    results: dict[str, dict] = {}
    lossy = (2.0, 0.5, 0.01)

    def run(name: str, mode: str, stepped: bool = False) -> dict:
        link.impair(*lossy)
        t0 = time.monotonic()
        code, bag, stderr = _run_across_link(link, tmp_path, name, mode, stepped)
        wall = time.monotonic() - t0
        recorded = load_run(bag)
        rows = recorded.t <= scenario.duration + 1e-9
        err = np.abs(recorded.error[rows])
        results[name] = r = dict(
            code=code,
            wall_s=round(wall, 1),
            samples=len(recorded.t),
            covered=float(np.mean(np.all(np.isfinite(err), axis=1))),
            max_error_deg=np.rad2deg(np.nanmax(err, axis=0)).round(3).tolist(),
            within_2x=bool(np.all(np.nanmax(err, axis=0) <= 2.0 * offline_max)),
            plant=_plant_counters(bag),
            stderr=stderr,
            run=recorded,
        )
        assert code == 0 or "lockstep" in stderr, (name, code, stderr[-2000:])
        return r

    try:
        link.make()
        run("realtime_stepped_netem", "realtime", stepped=True)
        run("realtime_netem", "realtime")
        run("lockstep_netem", "lockstep")
    finally:
        link.close()
    for name, r in results.items():
        report(
            f"netns {name} ({link.kind})",
            **{k: v for k, v in r.items() if k not in ("stderr", "run")},
        )
    report(
        "netns offline reference",
        max_error_deg=np.rad2deg(offline_max).round(3).tolist(),
        link_stats=link.stats,
    )
    summary = {
        name: {k: v for k, v in r.items() if k not in ("stderr", "run")}
        for name, r in results.items()
    }
    stepped, wall = results["realtime_stepped_netem"], results["realtime_netem"]
    assert stepped["code"] == 0, stepped["stderr"][-2000:]
    assert stepped["covered"] >= 0.95, summary
    assert stepped["within_2x"], (summary, np.rad2deg(offline_max))
    # On wall time: the run completes and its joint states are recorded (the plant and the
    # recorder share a namespace); how many set points crossed the link in time is load.
    assert wall["code"] == 0, wall["stderr"][-2000:]
    assert stepped["samples"] == wall["samples"] == scenario.n_samples + 1, summary
    lock = results["lockstep_netem"]
    if lock["code"] == 0:
        recorded = lock["run"]
        assert len(recorded.t) == len(offline.t)
        np.testing.assert_allclose(recorded.q, offline.q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(recorded.du, offline.du, rtol=0, atol=1e-12)
    else:
        assert "lockstep: no" in lock["stderr"], lock["stderr"][-2000:]
    if link.kind == "tap":
        netem = link.stats[1]
        assert netem["dropped"] > 0 and netem["frames"] > 1000, link.stats
