"""Node processes of a test: their parameter files, started with their stderr kept, always
stopped (SIGINT, then SIGTERM, then SIGKILL) when the test ends."""

from __future__ import annotations

import contextlib
import subprocess
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

from apc_lab.experiment import stop_processes


def write_params(path: Path, params: Mapping[str, Mapping[str, Any]]) -> Path:
    """A ROS parameter file at ``path``: one section per node name."""
    path.write_text(yaml.safe_dump({k: {"ros__parameters": dict(v)} for k, v in params.items()}))
    return path


@contextlib.contextmanager
def node_process(
    argv: list[str], log_path: Path, *, with_stdout: bool = False, timeout_s: float = 10.0
) -> Iterator[subprocess.Popen]:
    """``argv`` as a process, its stderr (and its stdout ``with_stdout``, else dropped) in
    ``log_path``; stopped when the block ends, whatever happened in it."""
    with open(log_path, "wb") as log:
        stdout = log if with_stdout else subprocess.DEVNULL
        proc = subprocess.Popen(argv, stdout=stdout, stderr=log)
        try:
            yield proc
        finally:
            stop_processes([proc], timeout_s=timeout_s)
