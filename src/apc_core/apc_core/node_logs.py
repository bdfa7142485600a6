"""Where nodes' log lines go: the plain classes' ``log(level, text)`` on a node's logger, and a
process's node logs sent to a folder instead of the console."""

from __future__ import annotations

import contextlib
import math
import os
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import rclpy
from rclpy.node import Node

#: Numbers in a log line (sample indices, times): a repeat of an event differs only in them.
_DIGITS = re.compile(r"[-+]?\d+(\.\d+)?")


def level_logger(node: Node, throttle_s: float = 1.0) -> Callable[[str, str], None]:
    """``log(level, text)`` for the plain classes (``"info"``, ``"warn"``, ``"error"``) on
    ``node``'s logger. A line that repeats another but for its numbers (the same event at
    another sample) within ``throttle_s`` is dropped; different events are all logged (rclpy's
    own throttle is per call site, and would drop the second of two events in a second)."""
    logger = node.get_logger()
    last: dict[tuple[str, str], float] = {}

    def log(level: str, text: str) -> None:
        key = (level, _DIGITS.sub("#", text))
        now = time.monotonic()
        if now - last.get(key, -math.inf) < throttle_s:
            return
        last[key] = now
        # rclpy refuses a second severity from one call site: each level has its own.
        if level == "error":
            logger.error(text)
        elif level == "warn":
            logger.warning(text)
        else:
            logger.info(text)

    return log


@contextlib.contextmanager
def node_logs_to(directory: Path) -> Iterator[None]:
    """While inside, the log lines of nodes made in this process go to rcl's log file in
    ``directory`` (``ROS_LOG_DIR``), not to the console: rclpy configures rcl's logging when
    its first context comes and keeps that configuration while any context lives, so one
    context made here with ``--disable-stdout-logs`` sets it for every context after it.
    Without effect if a context already lives in the process (logging is configured then)."""
    directory.mkdir(parents=True, exist_ok=True)
    before = os.environ.get("ROS_LOG_DIR")
    os.environ["ROS_LOG_DIR"] = str(directory)
    context = rclpy.Context()
    rclpy.init(args=["--ros-args", "--disable-stdout-logs"], context=context)
    try:
        yield
    finally:
        rclpy.try_shutdown(context=context)
        if before is None:
            os.environ.pop("ROS_LOG_DIR", None)
        else:
            os.environ["ROS_LOG_DIR"] = before
