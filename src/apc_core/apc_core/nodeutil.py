"""What every apc node shares: diagnostics, the border, and ``main`` (the arm it loads from
its parameters: :mod:`apc_core.robot_params`).

- :class:`Diagnostics` — counters and timing, published on ``/diagnostics`` at 1 Hz wall time.
- :func:`run_node` — ``main`` for a node executable: ``--help``, one-line start-up errors with
  exit code 2, clean shutdown on SIGINT/SIGTERM (Jazzy: try/finally and ``try_shutdown``).
- :func:`reject`, :func:`guarded` — the border: a bad message is counted and logged
  (throttled), and an exception in a callback is caught and counted instead of ending the
  node's spin.
"""

from __future__ import annotations

import contextlib
import faulthandler
import functools
import os
import signal
import statistics
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from std_msgs.msg import String

import apc_msgs_py as wire
from apc_core.params import ConfigError, Param
from apc_core.robot import RobotModelError
from apc_msgs_py import DIAGNOSTICS, DIAGNOSTICS_QOS, WireError


def publish_robot_description(node: Node, xml: str) -> Publisher:
    """Publish the arm's URDF once on ``robot_description`` (transient local, as
    robot_state_publisher does): a recorder or a viewer that comes later still gets it. Keep
    the publisher: its history is what late joiners receive."""
    publisher = node.create_publisher(String, wire.ROBOT_DESCRIPTION, wire.ROBOT_DESCRIPTION_QOS)
    publisher.publish(String(data=xml))
    return publisher


def matched_publisher(node: Node, msg_type: Any, topic: str, qos: QoSProfile) -> Publisher:
    """``node.create_publisher`` that logs how many subscriptions it is matched with, each time
    that changes (``<topic>: N subscriber(s)``): the writer's side of the match the recorder
    logs from the reader's. The two sides match at different times (across a lossy network
    seconds apart: a lost discovery message waits for its repair), and a message published
    before a reader is matched never reaches it (VOLATILE): what a run that must be recorded
    whole waits for."""
    resolved = node.resolve_topic_name(topic)

    def matched(info: Any) -> None:
        node.get_logger().info(f"{resolved}: {info.current_count} subscriber(s)")

    return node.create_publisher(
        msg_type, topic, qos, event_callbacks=PublisherEventCallbacks(matched=matched)
    )


class Diagnostics:
    """Counters and per-sample timings of one node, turned into a ``DiagnosticStatus``.

    Counters (``rejected``, ``late`` ...) only go up. Timings keep the last ``window`` values
    and are reported as median / max in microseconds.
    """

    def __init__(self, name: str, hardware_id: str = "apc", window: int = 1000) -> None:
        self.name = name
        self.hardware_id = hardware_id
        self.counters: dict[str, int] = {}
        self.values: dict[str, Any] = {}
        self._timings: dict[str, deque[float]] = {}
        self._window = window
        self.level = DiagnosticStatus.OK
        self.message = "ok"

    def count(self, key: str, n: int = 1) -> int:
        self.counters[key] = self.counters.get(key, 0) + n
        return self.counters[key]

    def time(self, key: str, seconds: float) -> None:
        self._timings.setdefault(key, deque(maxlen=self._window)).append(seconds)

    def set(self, key: str, value: Any) -> None:
        """Report ``value`` (a float as 4 significant digits); formatted when published."""
        self.values[key] = value

    def status(self) -> DiagnosticStatus:
        values = [KeyValue(key=k, value=str(v)) for k, v in sorted(self.counters.items())]
        for key, samples in sorted(self._timings.items()):
            if samples:
                values.append(
                    KeyValue(
                        key=f"{key}_median_us", value=f"{1e6 * statistics.median(samples):.1f}"
                    )
                )
                values.append(KeyValue(key=f"{key}_max_us", value=f"{1e6 * max(samples):.1f}"))
        values += [
            KeyValue(key=k, value=f"{v:.4g}" if isinstance(v, float) else str(v))
            for k, v in sorted(self.values.items())
        ]
        return DiagnosticStatus(
            level=self.level,
            name=self.name,
            message=self.message,
            hardware_id=self.hardware_id,
            values=values,
        )


class DiagnosticsPublisher:
    """Publishes a node's :class:`Diagnostics` on ``/diagnostics`` every ``period_s`` wall time."""

    def __init__(self, node: Node, diagnostics: Diagnostics, period_s: float = 1.0) -> None:
        self._node = node
        self._diagnostics = diagnostics
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, DIAGNOSTICS_QOS)
        self._timer = node.create_timer(
            period_s, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )

    def publish(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [self._diagnostics.status()]
        self._pub.publish(msg)


class Stopwatch:
    """``with Stopwatch(diag, "compute"):`` records the block's wall time."""

    def __init__(self, diagnostics: Diagnostics, key: str) -> None:
        self._d, self._key = diagnostics, key

    def __enter__(self) -> Stopwatch:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self._d.time(self._key, time.perf_counter() - self._t0)


def reject(node: Node, diagnostics: Diagnostics, topic: str, exc: Exception) -> None:
    """Count and log (throttled) a message that failed validation; the node carries on."""
    n = diagnostics.count(f"rejected.{topic}")
    diagnostics.count("rejected")
    node.get_logger().warn(
        f"rejected message on '{topic}' ({n} so far): {exc}", throttle_duration_sec=1.0
    )


def guarded(node: Node, diagnostics: Diagnostics, name: str, callback: Callable) -> Callable:
    """Wrap a subscription or timer callback so that an exception cannot end the spin.

    Bad input is rejected inside the callbacks (:func:`reject`); what reaches this is a bug or
    an unforeseen case. It is counted (``callback_errors`` and ``callback_errors.<name>`` on
    ``/diagnostics``), logged (throttled) with its type, and the node carries on with the next
    message. A callback that fails because the node's context was shut down while it ran (a
    publish on a stopping node: "publisher's context is invalid") is the stop, not a bug: it
    is neither counted nor logged. The wrapper keeps the callback's signature (rclpy inspects
    it).
    """

    @functools.wraps(callback)
    def wrapper(*args: Any) -> Any:
        try:
            return callback(*args)
        except Exception as exc:  # the last line of defence of a running node
            if not node.context.ok():
                return None  # stopping (Ctrl-C mid-callback): nothing to report
            n = diagnostics.count(f"callback_errors.{name}")
            diagnostics.count("callback_errors")
            node.get_logger().error(
                f"{name}: {type(exc).__name__}: {exc} ({n} so far); carrying on",
                throttle_duration_sec=1.0,
            )
            return None

    return wrapper


def destroy_nodes(
    nodes: Iterable[Node], context: rclpy.Context | None = None, executor: Any = None
) -> None:
    """Tear down in reverse order of creation: shut the executor down (if given), ``close()``
    what can be closed (a recorder's file), destroy every node, then shut the context down (the
    default one if ``None``).

    The executor lets go of the nodes first: the events executor keeps using a node's handles
    (and serves timers from a thread of its own) while the node is added to it, and rclpy's
    ``destroy_when_not_in_use`` then defers the teardown (with the process's last node, the
    DDS participant's) to whenever the executor lets go, outside the teardown limit.
    """
    nodes = list(nodes)
    if executor is not None:
        for node in nodes:
            with contextlib.suppress(Exception):  # after the context's shutdown it may refuse
                executor.remove_node(node)
        with contextlib.suppress(Exception):
            executor.shutdown(timeout_sec=1.0)
    for node in reversed(nodes):
        closer = getattr(node, "close", None)
        if callable(closer):
            closer()
        node.destroy_node()
    rclpy.try_shutdown(context=context)


def print_help(prog: str, summary: str, params: Iterable[Param]) -> None:
    print(f"usage: {prog} [--ros-args -p NAME:=VALUE ... --params-file FILE]\n")
    print(summary.strip() + "\n")
    print("parameters:")
    for p in params:
        rng = f" [{p.low}, {p.high}]" if p.low is not None else ""
        ro = " (read-only)" if p.read_only else ""
        print(f"  {p.name} = {p.default!r}{rng}{ro}\n      {p.description}")


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """A command line split into the program's own arguments and ROS's (``--ros-args`` and
    everything after it, as rcl parses them)."""
    args = list(argv)
    split = args.index("--ros-args") if "--ros-args" in args else len(args)
    return args[:split], args[split:]


#: Longest teardown of a node process before it is ended with its tracebacks (s).
TEARDOWN_LIMIT_S = 5.0
#: At the end of a completed run, how long the nodes' reliable publishers may wait for their
#: subscribers to acknowledge what was sent (:func:`wait_for_delivery`).
DELIVERY_LIMIT_S = 2.0


def wait_for_delivery(nodes: Iterable[Node], timeout_s: float = DELIVERY_LIMIT_S) -> bool:
    """Wait until every reliable publisher of ``nodes`` has its samples acknowledged by its
    subscribers, at most ``timeout_s`` in all; whether all were.

    A run that ends and destroys its writers at once can take the last samples with it: a
    reliable reader that misses one sample holds every later one back until the repair comes,
    and a writer that has left repairs nothing, so a recorder or an observer loses the run's
    tail from the gap on. Best-effort publishers and publishers without subscribers return at
    once.
    """
    deadline = time.monotonic() + timeout_s
    for node in nodes:
        for publisher in node.publishers:
            left = deadline - time.monotonic()
            if left <= 0.0 or not publisher.wait_for_all_acked(Duration(seconds=left)):
                return False
    return True


#: Executors a node process can spin (:func:`make_executor`).
EXECUTORS = ("events", "single")
#: Environment variable that picks the executor of ``ros2 run`` nodes (``events`` unless set).
EXECUTOR_ENV = "APC_EXECUTOR"


def make_executor(kind: str, context: rclpy.Context | None = None) -> Any:
    """``events``: rclpy's ``EventsExecutor``, ``single``: ``SingleThreadedExecutor``.

    The events executor takes a message to its callback several times faster, so lockstep runs
    more samples per second (figures: docs/nodes.md and docs/performance.md, from
    ``bench/ros_loop.py``); results are the same bit for bit. Only its ``spin_once`` is
    used: in the Jazzy wheels apc runs on, ``EventsExecutor.spin()`` runs no callbacks and
    ignores shutdown.
    """
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        return SingleThreadedExecutor(context=context)
    raise ValueError(f"executor must be one of {EXECUTORS}, got {kind!r}")


def spin_once_or_stop(executor: Any, context: rclpy.Context | None = None) -> bool:
    """One ``spin_once`` (0.1 s at most); False once the context is shut down (a signal).

    One event per call, because the events executor's ``spin()`` runs no callbacks in these
    wheels. Its ``spin_until_future_complete`` would save a few per cent of Python per event
    but makes the real-time fault tests miss samples now and then under load.
    """
    if not rclpy.ok(context=context):
        return False
    try:
        executor.spin_once(timeout_sec=0.1)
    except Exception:
        # A signal between ok() and spin_once() invalidates the context: that is a shutdown,
        # not an error. Anything else is re-raised.
        if rclpy.ok(context=context):
            raise
        return False
    return True


def run_node(
    make_node: Callable[[], Node],
    *,
    prog: str,
    summary: str,
    params: Iterable[Param],
    args: Sequence[str] | None = None,
    spin_until: Callable[[Node], bool] | None = None,
) -> int:
    """``main`` of a node executable; returns the process exit code.

    ``--help`` prints the parameters. A :class:`ConfigError` (or a model/wire error) while the
    node is built prints one line naming the parameter and returns 2. The node spins on
    :func:`make_executor` of ``$APC_EXECUTOR``, ``events`` (rclpy's ``EventsExecutor``, ~2x
    the single-threaded executor's messages per second) unless set to ``single``.
    SIGINT/SIGTERM end the spin and the node is destroyed before ``rclpy`` shuts down; it
    leaves the executor first (:func:`destroy_nodes`): the events executor holds the handles
    of a node still added to it.
    ``spin_until(node)`` returning True ends a finite run (e.g. the plant after ``n_samples``)
    with the node's ``exit_code``.
    """
    return run_nodes(
        lambda: [make_node()],
        prog=prog,
        print_help=lambda: print_help(prog, summary, params),
        args=args,
        spin_until=None if spin_until is None else (lambda nodes: spin_until(nodes[0])),
    )


def run_nodes(
    make_nodes: Callable[[], list[Node]],
    *,
    prog: str,
    print_help: Callable[[], None],
    args: Sequence[str] | None = None,
    spin_until: Callable[[list[Node]], bool] | None = None,
) -> int:
    """:func:`run_node` for several nodes in one process on one executor (composition).

    ``spin_until(nodes)`` returning True ends the run with the first node's ``exit_code``
    that is not 0 (or 0). The executor is ``$APC_EXECUTOR``'s, ``events`` unless set.
    """
    argv = list(sys.argv[1:] if args is None else args)
    if {"-h", "--help"} & set(split_ros_args(argv)[0]):
        print_help()
        return 0
    executor_kind = os.environ.get(EXECUTOR_ENV) or "events"
    if executor_kind not in EXECUTORS:
        print(f"{prog}: {EXECUTOR_ENV} must be one of {', '.join(EXECUTORS)}", file=sys.stderr)
        return 2
    previous_sigint = leave_sigint_to_rclpy()  # restored on the way out
    rclpy.init(args=[prog, *argv])
    nodes: list[Node] = []
    executor = None
    code = 0
    try:
        try:
            for node in make_nodes():
                nodes.append(node)
        except (ConfigError, RobotModelError, WireError, ValueError) as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 2
        except Exception:
            if rclpy.ok():
                raise
            return 0  # stopped by a signal while the node was being built
        executor = make_executor(executor_kind)
        for node in nodes:
            executor.add_node(node)
            node.get_logger().info(f"{prog} running (namespace '{node.get_namespace()}')")
        while spin_once_or_stop(executor):
            if spin_until is not None and spin_until(nodes):
                codes = [getattr(node, "exit_code", 0) for node in nodes]
                code = next((c for c in codes if c), 0)
                # Only a completed run: after a failure a peer is likely dead, and its reader
                # would hold the wait to the limit.
                if code == 0 and not wait_for_delivery(nodes):
                    nodes[0].get_logger().warning(
                        f"not every subscriber acknowledged the run's last messages within "
                        f"{DELIVERY_LIMIT_S} s"
                    )
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # A teardown that hangs (rclpy's and DDS's threads) must not keep a stopped node alive:
        # after 5 s the tracebacks of every thread go to stderr and the process exits with 1.
        # (Not where stderr has no file descriptor, e.g. main() called under pytest's capture.)
        guarded_teardown = _arm_teardown_limit()
        destroy_nodes(nodes, executor=executor)
        if guarded_teardown:
            faulthandler.cancel_dump_traceback_later()
        if previous_sigint is not None:
            signal.signal(signal.SIGINT, previous_sigint)
    return code


def _arm_teardown_limit() -> bool:
    """Have faulthandler end the process after :data:`TEARDOWN_LIMIT_S`; False if it cannot."""
    try:
        faulthandler.dump_traceback_later(TEARDOWN_LIMIT_S, exit=True, file=sys.__stderr__)
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is an OSError
        return False
    return True


def leave_sigint_to_rclpy() -> Any:
    """Before ``rclpy.init()``: Python's SIGINT handler becomes a no-op; the handler replaced
    (to restore), or None where nothing was replaced.

    rclpy's SIGINT handler shuts the context down and then calls the handler it replaced. If
    that is Python's default, a KeyboardInterrupt is also raised wherever Python happens to be,
    e.g. inside rclpy's message conversion in take_message, which turns it into "RuntimeError:
    Unable to convert call argument" and a traceback with exit code 1 (e.g. when the runner
    stops its children), or inside a timer callback, which the events executor logs as
    "[FATAL] Exception in 'timers' callback". With a no-op Python handler the shutdown is
    rclpy's alone: a spin loop on ``rclpy.ok()`` ends cleanly. Only from the main thread and
    over Python's default handler (a program's own is left alone).
    """
    if (
        threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    ):
        return signal.signal(signal.SIGINT, _leave_to_rclpy)
    return None


def _leave_to_rclpy(signum: int, frame: Any) -> None:
    """SIGINT handler under rclpy's: do nothing (rclpy has already shut the context down)."""


class StopSignals:
    """SIGINT/SIGTERM as a flag, for a program that spins its own ``rclpy.Context``.

    ``rclpy.init()`` installs its SIGINT/SIGTERM handlers only for the *default* context; a
    program that creates its own ``rclpy.Context()`` (the ``experiment`` runner) gets none:
    SIGINT raises ``KeyboardInterrupt`` wherever Python happens to be (possibly inside a
    recorder callback, half-way through a chunk) and SIGTERM kills the process on the spot (no
    finished recording, child nodes left running). Inside ``with StopSignals() as stop:`` both
    signals only set :attr:`received`; the program calls :meth:`check` between ``spin_once``
    calls, where stopping is safe, and cleans up in ``finally``. The previous handlers come
    back on exit. Outside the main thread, or where a signal's handler is not Python's default
    (ignored, or installed from C), nothing is changed for that signal.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.received: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is not threading.main_thread():
            return self
        for sig in self.SIGNALS:
            current = signal.getsignal(sig)
            if current in (signal.SIG_DFL, signal.default_int_handler):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame: Any) -> None:
        if self.received is None:
            self.received = signum

    def check(self) -> bool:
        """Raise ``KeyboardInterrupt`` once a signal has arrived; else return False.

        Returns False so that it can lead a wait condition: ``lambda: stop.check() or ready()``.
        """
        if self.received is not None:
            raise KeyboardInterrupt(signal.Signals(self.received).name)
        return False

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
