"""A real-time run in simulated time: the test publishes ``/clock`` and moves it one period at a
time, each step once the nodes alive have answered the last joint state.

``plant_node`` in ``realtime`` mode with ``use_sim_time`` (``publish_clock: false``) ticks on
this clock, so a real-time run's rules (late torques, the watchdog, the brake) play out sample
by sample, the same on an idle machine and a loaded one: a slow process makes the run take
longer, never changes what the plant applies. Wall time only bounds how long a step may wait
before the test fails, and how long to look for a node that was just started.
"""

from __future__ import annotations

import time

from rosgraph_msgs.msg import Clock as ClockMsg

import apc_msgs_py as wire

from .observer import Observer

FF, FB = "feedforward", "feedback"


class ClockStepper:
    """Moves ``/clock`` for ``plant_node`` (real time on ``use_sim_time``) through ``obs``.

    Parameters
    ----------
    obs : Observer
        Sees the joint states and both torques.
    period_ns : int
        The plant's period.
    lookahead : int
        The feedforward's: joint state ``k`` is answered with ``u_n(k + lookahead)``.
    procs : sequence of subprocess.Popen
        The nodes that must stay alive while a step waits.
    """

    def __init__(self, obs: Observer, period_ns: int, lookahead: int, procs=()) -> None:
        self.obs = obs
        self.period_ns = period_ns
        self.lookahead = lookahead
        self.procs = procs
        self.now_ns = 0
        self._msg = ClockMsg()
        self._pub = obs.node.create_publisher(ClockMsg, wire.CLOCK, wire.CLOCK_QOS)

    def k(self) -> int:
        """The newest joint state's sample index at this period (-1 before the first)."""
        return self.obs.k(self.period_ns)

    def answered(self, k: int, who: str) -> bool:
        """Joint state ``k``'s answer from ``who`` (:data:`FF` or :data:`FB`) has been seen."""
        if who == FF:
            return (k + self.lookahead) * self.period_ns in self.obs.ff
        return k * self.period_ns in self.obs.fb

    def tick(self) -> None:
        """Move ``/clock`` one period on (the plant's timer fires once)."""
        self.now_ns += self.period_ns
        self._publish()

    def _publish(self) -> None:
        self._msg.clock = wire.ns_to_stamp(self.now_ns, self._msg.clock)
        self._pub.publish(self._msg)

    def start(self, timeout_s: float = 60.0) -> int:
        """Tick until the plant's clock runs: it waits for its peers, sends sample 0 (again
        every ``resend_s`` of this clock: a controller still being discovered may miss it) and
        steps once both controllers' answers to it are in. Returns at the first sample after
        0 with both its answers seen, its index."""
        deadline = time.monotonic() + timeout_s
        while True:
            assert time.monotonic() < deadline, f"the run did not start within {timeout_s} s"
            k = self.k()
            if k >= 1:
                self._spin_until(lambda k=k: self.answered(k, FF) and self.answered(k, FB), 5.0)
                if self.answered(k, FF) and self.answered(k, FB):
                    return k
                self.tick()  # an answer lost at start: the plant applies what it holds
            elif k == 0 and self.answered(0, FF) and self.answered(0, FB):
                self.tick()
                self._spin_until(lambda: self.k() >= 1, 0.5)
            else:
                self.tick()
                self._spin_until(lambda: False, 0.02)

    def step(self, alive: tuple[str, ...] = (FF, FB), timeout_s: float = 30.0) -> int:
        """One period: tick, then wait for the next joint state and the answers to it of the
        controllers ``alive``; the new sample's index."""
        k = self.k() + 1
        self.tick()
        deadline = time.monotonic() + timeout_s
        waited_for = time.monotonic() + 0.5
        while not (self.k() >= k and all(self.answered(k, who) for who in alive)):
            now = time.monotonic()
            assert now < deadline, (
                f"sample {k}: state {self.k()}, answered by "
                f"{[who for who in alive if self.answered(k, who)]} of {alive} in {timeout_s} s"
            )
            for proc in self.procs:
                assert proc.poll() is None, f"sample {k}: a node exited with {proc.returncode}"
            if now > waited_for:  # /clock is best effort: say the time again (no second tick)
                self._publish()
                waited_for = now + 0.5
            self.obs.executor.spin_once(timeout_sec=0.005)
        return k

    def step_until_answered(
        self, who: str, alive: tuple[str, ...], max_samples: int, look_s: float = 0.2
    ) -> int:
        """Step (answers of ``alive`` required) until ``who``, just started, answers a joint
        state within ``look_s`` of wall time; that sample's index. A new process may miss the
        first states sent while it is being discovered: the samples meanwhile run without it."""
        for _ in range(max_samples):
            k = self.step(alive)
            self._spin_until(lambda k=k: self.answered(k, who), look_s)
            if self.answered(k, who):
                return k
        raise AssertionError(f"{who} did not answer within {max_samples} samples")

    def _spin_until(self, condition, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while not condition() and time.monotonic() < deadline:
            self.obs.executor.spin_once(timeout_sec=0.005)


def main(argv: list[str] | None = None) -> int:
    """``python -m support.sim_clock PERIOD_NS LOOKAHEAD N_SAMPLES``: step ``/clock`` for a
    plant in other processes until its last sample, then keep saying the last time until
    stopped (SIGINT/SIGTERM). For nodes the test's own observer cannot reach, e.g. in a network
    namespace: the stepper runs beside the plant. Prints ``listening`` once its readers exist
    and ``stepped K`` when the last sample is reached; exits 1, saying why on stderr, if a step
    waits longer than its bound, and 0 on SIGINT/SIGTERM."""
    import argparse
    import signal
    import sys

    parser = argparse.ArgumentParser(prog="python -m support.sim_clock")
    parser.add_argument("period_ns", type=int)
    parser.add_argument("lookahead", type=int)
    parser.add_argument("n_samples", type=int)
    args = parser.parse_args(argv)

    def stop(signum: int, frame: object) -> None:
        raise SystemExit(0)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, stop)
    obs = Observer()
    try:
        clock = ClockStepper(obs, args.period_ns, args.lookahead)
        print("listening", flush=True)
        k = clock.start(timeout_s=120.0)
        while k < args.n_samples - 1:
            k = clock.step()
        clock.tick()  # the last sample: the plant applies its torques and ends
        print(f"stepped {k + 1}", flush=True)
        while True:  # /clock is best effort: the plant may not have heard the last tick
            clock._spin_until(lambda: False, 0.5)
            clock._publish()
    except AssertionError as exc:
        print(f"sim_clock: {exc}", file=sys.stderr, flush=True)
        return 1
    finally:
        obs.close()


if __name__ == "__main__":
    raise SystemExit(main())
