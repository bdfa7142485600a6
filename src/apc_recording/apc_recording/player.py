"""``player``: republish a recorded MCAP bag on its recorded topics, like ``ros2 bag play``.

Each message goes out on the topic it was recorded on (the resolved name, e.g.
``/joint_states``), with its recorded type, as the **raw CDR bytes** read from the file (no
deserialise / serialise round trip), and with the QoS its publishers offered
(``offered_qos_profiles`` of the channel, else :data:`apc_msgs_py.TOPICS`, else the ROS
default). Message ``i`` of the selected window goes out at wall time
``t0 + (log_time_i - window_start) / rate``, in log-time order.

    player BAG.mcap [--rate R] [--topics T ...] [--loop] [--clock [HZ]]
                    [--start S] [--duration D] [--remap FROM:=TO ...]
                    [--wait-for-subscribers N] [--ros-args ...]

    player runs/adaptive_c.mcap --topics /joint_states /feedforward/setpoint --rate 5
    player run.mcap --clock 100          # use_sim_time nodes follow the bag's time
    player run.mcap --remap /joint_states:=/replay/joint_states

Options
-------
``--rate R``
    Speed factor (default 1). ``0`` (or a huge value) plays as fast as possible, still in order.
``--topics T ...``
    Play only these recorded topics (relative names are expanded in the node's namespace).
    ``/clock`` and ``/diagnostics`` are **not played unless named here**: with ``--clock`` the
    player owns ``/clock`` (two time sources would make sim time jump), and recorded
    diagnostics describe the original run's nodes, not anything running now.
``--loop``
    Start over at the end of the window, until interrupted (bag time jumps back).
``--clock [HZ]``
    Publish ``/clock`` at HZ wall-clock hertz (default 40, as ``ros2 bag play --clock``) with
    the bag time of the playback: the window start while waiting, then
    ``window_start + rate * (wall time since start)``, or, at ``--rate 0``, the log time of the
    last message sent. Put it after BAG (``player --clock BAG`` would read BAG as HZ).
``--start S`` / ``--duration D``
    Play the log-time window ``[first + S, first + S + D)`` (seconds after the bag's first log
    time; the end is excluded, as in mcap). ``D = 0``: to the end of the bag.
``--remap FROM:=TO ...``
    Publish the recorded topic FROM on TO. ``--ros-args -r FROM:=TO`` works too (rcl remapping
    of the publishers), as do ``-r __ns:=/ns`` and ``-p name:=value`` (parameters below).
``--wait-for-subscribers N``
    Before the first message, wait until the publisher of every played topic that holds
    messages has matched N subscribers (default 0), so that nothing is lost on VOLATILE topics
    while discovery finishes. ``/clock`` is not waited for.

Every option is also a ROS parameter of the node (``bag``, ``rate``, ``topics``, ``loop``,
``clock_hz``, ``start``, ``duration``, ``remap``, ``wait_for_subscribers``), so a
:class:`PlayerNode` can be composed in-process. It plays from a steady-clock timer on the
executor that spins it, one message per timer callback when behind schedule, so nodes on the
same executor get their turn between messages; the due times and the bag time are
:class:`apc_recording.playback.PlaybackTimeline`'s. The executable exits 0 at the end of the window
(never with ``--loop``), cleanly on SIGINT/SIGTERM, and with code 2 and one line when the bag
cannot be read or an option is invalid.

Recorded names are absolute, so ``__ns`` moves only the node (and relative ``TO`` names), not
the played topics; use ``--remap`` to move those.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg

import apc_msgs_py as wire
from apc_core.nodeutil import run_node, split_ros_args
from apc_core.params import ConfigError, Param, declare
from apc_recording.bag import (
    BagError,
    BagMessage,
    bag_info,
    get_message_class,
    qos_profiles_from_yaml,
    read_messages,
)
from apc_recording.playback import PlaybackTimeline

#: ``--clock`` without a value: the rate of ``ros2 bag play --clock``.
DEFAULT_CLOCK_HZ = 40.0
#: Recorded topics left out unless named in ``topics`` (see the module docstring for why).
NOT_PLAYED_BY_DEFAULT = (wire.CLOCK, wire.DIAGNOSTICS)
#: Re-check period while waiting for subscribers (wall time).
_WAIT_POLL_NS = 10_000_000

PARAMS: tuple[Param, ...] = (
    Param("bag", "", "MCAP file to play (a directory holding exactly one .mcap also works)"),
    Param(
        "rate",
        1.0,
        "playback speed factor; 0 = as fast as possible (in log-time order)",
        0.0,
        1e12,
    ),
    Param(
        "topics",
        [],
        "recorded topics to play; empty = all but /clock and /diagnostics",
        array_of=str,
    ),
    Param("loop", False, "start over at the end of the window, until interrupted"),
    Param(
        "clock_hz",
        0.0,
        "publish /clock with the bag time at this wall-clock rate (Hz); 0 = off",
        0.0,
        1e6,
    ),
    Param("start", 0.0, "window start, seconds after the bag's first log time (s)", 0.0, 1e12),
    Param("duration", 0.0, "window length (s), end excluded; 0 = to the end of the bag", 0.0, 1e12),
    Param(
        "remap",
        [],
        "'FROM:=TO' pairs: publish recorded topic FROM on topic TO",
        array_of=str,
    ),
    Param(
        "wait_for_subscribers",
        0,
        "before playing, wait until the publisher of every played topic that has messages "
        "(not /clock) has matched this many subscribers",
        0,
        1_000_000,
    ),
)


@dataclass(frozen=True)
class PlayedTopic:
    """One recorded topic and the publisher that replays it.

    Attributes
    ----------
    recorded : str
        The topic name in the bag.
    published : str
        The fully qualified name it is published on (after ``remap`` and rcl remapping).
    type_name : str
        ``"sensor_msgs/msg/JointState"``.
    qos : rclpy.qos.QoSProfile
        The profile offered.
    publisher : rclpy.publisher.Publisher
    """

    recorded: str
    published: str
    type_name: str
    qos: QoSProfile
    publisher: Publisher


def resolve_bag_path(bag: str | Path) -> Path:
    """The MCAP file of ``bag``: the path itself, or the only ``*.mcap`` in a directory.

    Raises
    ------
    ConfigError
        Naming parameter ``bag`` if it is empty, missing, or a directory without exactly one
        ``.mcap`` file.
    """
    if not str(bag):
        raise ConfigError("parameter 'bag': no bag given (player BAG.mcap)")
    path = Path(bag).expanduser()
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if len(files) != 1:
            raise ConfigError(
                f"parameter 'bag': directory {str(path)!r} holds {len(files)} .mcap files, "
                "expected exactly one"
            )
        return files[0]
    if not path.exists():
        raise ConfigError(f"parameter 'bag': {str(path)!r} does not exist")
    return path


def offered_qos(recorded_topic: str, offered_yaml: str) -> QoSProfile:
    """The QoS to replay a topic with, chosen the way ``ros2 bag play`` adapts its offer.

    One recorded publisher, or several offering the same profile: that profile. Several
    differing ones: RELIABLE only if all were, TRANSIENT_LOCAL only if all were, the largest
    depth. Nothing recorded (or unreadable): the :data:`apc_msgs_py.TOPICS` profile of
    the topic (matched by name, relative names at the end of the recorded one), else the ROS
    default (RELIABLE, KEEP_LAST 10, VOLATILE).

    Parameters
    ----------
    recorded_topic : str
        Name in the bag, e.g. ``/puma/joint_states``.
    offered_yaml : str
        The channel's ``offered_qos_profiles`` metadata.
    """
    try:
        profiles = qos_profiles_from_yaml(offered_yaml)
    except BagError:
        profiles = []
    if profiles:
        first = profiles[0]
        if all(p == first for p in profiles[1:]):
            return first
        return QoSProfile(
            depth=max(p.depth for p in profiles),
            reliability=(
                ReliabilityPolicy.RELIABLE
                if all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
                else ReliabilityPolicy.BEST_EFFORT
            ),
            durability=(
                DurabilityPolicy.TRANSIENT_LOCAL
                if all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
                else DurabilityPolicy.VOLATILE
            ),
        )
    for spec in wire.TOPICS:
        if spec.name == recorded_topic or (
            not spec.name.startswith("/") and recorded_topic.endswith("/" + spec.name)
        ):
            return spec.qos
    return QoSProfile(depth=10)


def parse_remaps(items: Sequence[str]) -> list[tuple[str, str]]:
    """``["FROM:=TO", ...]`` -> ``[(FROM, TO), ...]``.

    Raises
    ------
    ConfigError
        Naming parameter ``remap`` for an item that is not ``FROM:=TO`` with both sides set.
    """
    pairs = []
    for item in items:
        src, sep, dst = item.partition(":=")
        if not sep or not src.strip() or not dst.strip():
            raise ConfigError(f"parameter 'remap': {item!r} is not of the form FROM:=TO")
        pairs.append((src.strip(), dst.strip()))
    return pairs


class PlayerNode(Node):
    """Composable bag player (see module docstring).

    Keyword arguments that are not ``None`` (or an empty list) override the ROS parameter of
    the same name (they are passed as parameter overrides, so ``ros2 param get`` shows what is
    used).

    Parameters
    ----------
    node_name : str
    bag : str or Path, optional
        MCAP file (parameter ``bag``).
    rate : float, optional
        Speed factor; 0 = as fast as possible.
    topics : sequence of str, optional
        Recorded topics to play; empty = all but ``/clock`` and ``/diagnostics``.
    loop : bool, optional
    clock_hz : float, optional
        ``/clock`` publishing rate (Hz); 0 = off.
    start, duration : float, optional
        Window (s) relative to the bag's first log time; duration 0 = to the end.
    remap : sequence of str, optional
        ``"FROM:=TO"`` items.
    wait_for_subscribers : int, optional
    **kwargs
        Passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``, ...).

    Attributes
    ----------
    done : bool
        True once the window has been played (never with ``loop``) or nothing can be played.
    exit_code : int
        0 (what ``main`` returns when ``done``).
    played : dict[str, PlayedTopic]
        By recorded topic name.
    published : dict[str, int]
        Messages sent per recorded topic, over all passes.
    passes : int
        Passes started over the window.
    pass_wall_s : float
        Wall time (s) from the start of the last complete pass to its last message.

    Raises
    ------
    ConfigError
        One line naming the parameter: unreadable bag, unknown topic, bad remap, ``/clock``
        both played and published.
    """

    def __init__(
        self,
        node_name: str = "player",
        *,
        bag: str | Path | None = None,
        rate: float | None = None,
        topics: Sequence[str] | None = None,
        loop: bool | None = None,
        clock_hz: float | None = None,
        start: float | None = None,
        duration: float | None = None,
        remap: Sequence[str] | None = None,
        wait_for_subscribers: int | None = None,
        **kwargs: Any,
    ) -> None:
        given = {
            "bag": None if bag is None else str(bag),
            "rate": None if rate is None else float(rate),
            "topics": None if topics is None else [str(t) for t in topics],
            "loop": None if loop is None else bool(loop),
            "clock_hz": None if clock_hz is None else float(clock_hz),
            "start": None if start is None else float(start),
            "duration": None if duration is None else float(duration),
            "remap": None if remap is None else [str(r) for r in remap],
            "wait_for_subscribers": (
                None if wait_for_subscribers is None else int(wait_for_subscribers)
            ),
        }
        overrides = list(kwargs.pop("parameter_overrides", None) or [])
        # Later overrides win. rclpy retypes an empty list override as a byte array, so an empty
        # list leaves the parameter as it is (its default is empty anyway).
        overrides += [Parameter(k, value=v) for k, v in given.items() if v is not None and v != []]
        super().__init__(node_name, parameter_overrides=overrides, **kwargs)
        try:
            self._setup(declare(self, PARAMS))
        except ConfigError:
            self.destroy_node()  # nothing half-built stays on the graph
            raise

    def _setup(self, values: dict[str, Any]) -> None:
        """Open the bag, create the publishers and timers (see :class:`PlayerNode`)."""
        self.rate = float(values["rate"])
        self.loop = bool(values["loop"])
        self.clock_hz = float(values["clock_hz"])
        self.wait_for = int(values["wait_for_subscribers"])
        self.path = resolve_bag_path(values["bag"])
        try:
            info = bag_info(self.path)
        except BagError as exc:
            where = "" if str(self.path) in str(exc) else f"{str(self.path)!r}: "
            raise ConfigError(f"parameter 'bag': {where}{exc}") from None

        recorded = info["topics"]
        wanted = [self.resolve_topic_name(t, only_expand=True) for t in values["topics"]]
        unknown = sorted(set(wanted) - set(recorded))
        if unknown:
            raise ConfigError(
                f"parameter 'topics': not in the bag: {unknown}; it holds {sorted(recorded)}"
            )
        if self.clock_hz > 0 and wire.CLOCK in wanted:
            raise ConfigError(
                f"parameter 'topics': {wire.CLOCK} cannot be played while clock_hz > 0 "
                "(the player publishes /clock itself)"
            )
        names = wanted or [t for t in recorded if t not in NOT_PLAYED_BY_DEFAULT]
        remaps = {
            self.resolve_topic_name(src, only_expand=True): dst
            for src, dst in parse_remaps(values["remap"])
        }
        stray = sorted(set(remaps) - set(recorded))
        if stray:
            raise ConfigError(f"parameter 'remap': not in the bag: {stray}")

        self.played: dict[str, PlayedTopic] = {}
        for name in names:
            type_name = recorded[name]["type"]
            try:
                msg_type = get_message_class(type_name)
            except BagError as exc:
                if wanted:
                    raise ConfigError(f"parameter 'topics': {name}: {exc}") from None
                self.get_logger().warn(f"not playing {name}: {exc}")
                continue
            qos = offered_qos(name, recorded[name]["offered_qos_profiles"])
            pub = self.create_publisher(msg_type, remaps.get(name, name), qos)
            self.played[name] = PlayedTopic(name, pub.topic_name, type_name, qos, pub)
        self.published = dict.fromkeys(self.played, 0)
        # Only topics with messages are waited for (a goal topic recorded empty has no reader).
        self._with_messages = [t for t in self.played if recorded[t]["message_count"] > 0]

        first = info["start_ns"]
        start_ns = (first or 0) + wire.seconds_to_ns(values["start"])
        end_ns = start_ns + wire.seconds_to_ns(values["duration"]) if values["duration"] else None
        self.window_ns = (start_ns, end_ns)
        self.timeline = PlaybackTimeline(start_ns, end_ns, self.rate)
        self.done = False
        self.exit_code = 0
        self.passes = 0
        self.pass_wall_s = 0.0
        self._iter: Iterator[BagMessage] | None = None
        self._next: BagMessage | None = None
        self._waited_since = time.monotonic()

        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._clock_pub: Publisher | None = None
        self._clock_timer = None
        if self.clock_hz > 0:
            self._clock_pub = self.create_publisher(ClockMsg, wire.CLOCK, wire.CLOCK_QOS)
            self._clock_timer = self.create_timer(
                1.0 / self.clock_hz, self._publish_clock, clock=steady
            )
        self._timer = self.create_timer(0.0, self._tick, clock=steady)

        window = f"[{values['start']:g} s, " + (
            f"{values['start'] + values['duration']:g} s)" if end_ns is not None else "end]"
        )
        if first is None or not self.played:
            self.get_logger().warn(f"nothing to play in {self.path}")
            self._finish()
        else:
            self.get_logger().info(
                f"playing {len(self.played)} topics of {self.path}, window {window}, "
                f"rate {self.rate:g}" + (", loop" if self.loop else "")
            )

    # ------------------------------------------------------------------------------------------
    def bag_time_ns(self) -> int:
        """Current playback time on the bag's time line (ns), what ``--clock`` publishes."""
        return self.timeline.bag_time_ns(time.monotonic_ns())

    def _publish_clock(self) -> None:
        if self._clock_pub is not None and not self.done:
            self._clock_pub.publish(ClockMsg(clock=wire.ns_to_stamp(self.bag_time_ns())))

    def _subscribers_ready(self) -> bool:
        waiting = [
            name
            for name in self._with_messages
            if self.played[name].publisher.get_subscription_count() < self.wait_for
        ]
        if not waiting:
            return True
        self.get_logger().info(
            f"waiting for {self.wait_for} subscriber(s) on each of {waiting} "
            f"({time.monotonic() - self._waited_since:.0f} s)",
            throttle_duration_sec=5.0,
        )
        return False

    def _begin_pass(self, now_ns: int) -> None:
        if self._iter is not None:
            self._iter.close()
        start_ns, end_ns = self.window_ns
        self._iter = read_messages(self.path, list(self.played), start_ns, end_ns)
        self._next = next(self._iter, None)
        self.timeline.begin_pass(now_ns)
        self.passes += 1
        self._publish_clock()

    def _schedule(self, delay_ns: int) -> None:
        self._timer.timer_period_ns = max(0, delay_ns)
        self._timer.reset()

    def _tick(self) -> None:
        """Send the next message if it is due, then re-arm the timer for the one after."""
        if self.done:
            return
        now = time.monotonic_ns()
        if not self.timeline.started:
            if not self._subscribers_ready():
                self._schedule(_WAIT_POLL_NS)
                return
            self._begin_pass(now)
        msg = self._next
        if msg is None:
            self._end_pass()
            return
        due = self.timeline.due_ns(msg.log_time_ns)
        if due > now:
            self._schedule(due - now)
            return
        self.played[msg.topic].publisher.publish(bytes(msg.data))
        self.published[msg.topic] += 1
        self.timeline.sent(msg.log_time_ns, time.monotonic_ns())
        assert self._iter is not None
        self._next = next(self._iter, None)
        if self._next is None:
            self._end_pass()
        else:
            due = self.timeline.due_ns(self._next.log_time_ns)
            self._schedule(max(0, due - time.monotonic_ns()))

    def _end_pass(self) -> None:
        sent = self.timeline.sent_this_pass
        if sent:
            self.pass_wall_s = self.timeline.pass_wall_s()
        if self.loop and sent:
            self._begin_pass(time.monotonic_ns())
            self._schedule(0)
            return
        if sent == 0:
            self.get_logger().warn("no message of the selected topics in the window")
        self.get_logger().info(
            f"played {sum(self.published.values())} messages in {self.passes} pass(es)"
        )
        self._finish()

    def _finish(self) -> None:
        self.done = True
        self._timer.cancel()
        if self._clock_timer is not None:
            self._clock_timer.cancel()
        if self._iter is not None:
            self._iter.close()
            self._iter = None

    def close(self) -> None:
        """Stop playing and close the bag (idempotent); the node can then be destroyed."""
        if not self.done:
            self.get_logger().info(f"stopped after {sum(self.published.values())} messages")
            self._finish()


# ----------------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The ``player`` command line (everything after ``--ros-args`` goes to rclpy)."""
    doc = __doc__ or ""
    parser = argparse.ArgumentParser(
        prog="player",
        description=doc.split("\n\n")[0],
        epilog="Every option is also a ROS parameter: --ros-args -p rate:=2.0 -p loop:=true. "
        "/clock and /diagnostics are played only if named in --topics.",
    )
    parser.add_argument("bag", nargs="?", help="MCAP file (or a directory with one)")
    parser.add_argument("--rate", type=float, help="speed factor (default 1; 0 = fast as possible)")
    parser.add_argument("--topics", nargs="+", metavar="T", help="recorded topics to play")
    parser.add_argument("--loop", action="store_true", default=None, help="repeat until stopped")
    parser.add_argument(
        "--clock",
        nargs="?",
        type=float,
        const=DEFAULT_CLOCK_HZ,
        metavar="HZ",
        dest="clock_hz",
        help=f"publish /clock with the bag time at HZ (default {DEFAULT_CLOCK_HZ:g})",
    )
    parser.add_argument("--start", type=float, metavar="S", help="skip the first S seconds")
    parser.add_argument("--duration", type=float, metavar="D", help="play D seconds (0 = all)")
    parser.add_argument(
        "--remap", nargs="+", metavar="FROM:=TO", help="publish recorded topic FROM on TO"
    )
    parser.add_argument(
        "--wait-for-subscribers",
        type=int,
        metavar="N",
        help="wait until each publisher has N subscribers before playing (default 0)",
    )
    return parser


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``player``; returns the exit code (0 done, 2 bad bag or option).

    Parameters
    ----------
    args : sequence of str, optional
        Command line without the program name; default ``sys.argv[1:]``.
    """
    own, ros = split_ros_args(sys.argv[1:] if args is None else args)
    try:
        opts = build_parser().parse_args(own)
    except SystemExit as exc:  # --help (0) or a usage error (2), already printed
        return int(exc.code or 0)
    kwargs = {k: v for k, v in vars(opts).items() if v is not None}
    return run_node(
        lambda: PlayerNode(**kwargs),
        prog="player",
        summary=__doc__ or "",
        params=PARAMS,
        args=ros,
        spin_until=lambda node: bool(getattr(node, "done", False)),
    )


if __name__ == "__main__":
    sys.exit(main())
