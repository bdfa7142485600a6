"""Node processes of a test: their parameter files, started with their output kept, always
stopped (SIGINT, then SIGTERM, then SIGKILL) when the test ends.

:func:`node_process` runs one process for the length of a block; :class:`Children` runs the
nodes of a system test (``python -m <package>.<module>``, as on a robot), each of which the test
may kill and start again; :func:`wait_all` and :func:`process_group` tell how and whether they
ended.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

from apc_lab.experiment import stop_processes

#: The module each node runs as (``python -m``), by node name.
NODE_MODULES = {
    "plant_node": "apc_plant_sim.node",
    "feedforward_node": "apc_feedforward.node",
    "feedback_node": "apc_feedback.node",
    "recorder": "apc_recording.recorder",
}


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


class Children:
    """Node processes of one test, by key (the node's name unless ``key`` is given).

    Each runs ``python -m`` its node's module (:data:`NODE_MODULES`), with ``params_file``
    (but the recorder), or a helper module (:meth:`start_module`), behind ``prefix`` (``ip
    netns exec ...``) and in ``env``; its stdout and stderr go to ``<key>.<n>.out`` / ``.err``
    in ``tmp_path``. A node started again under its key replaces the old process, which is kept
    for :meth:`close`; that stops them all.
    """

    def __init__(self, tmp_path: Path, params_file: Path | None = None) -> None:
        self.dir = tmp_path
        self.params_file = params_file
        self.procs: dict[str, subprocess.Popen] = {}
        self.dead: list[subprocess.Popen] = []
        self._n = 0

    def start(
        self,
        name: str,
        *args: str,
        prefix: tuple[str, ...] = (),
        env: dict | None = None,
        key: str | None = None,
    ) -> subprocess.Popen:
        ros_args = ["--ros-args"]
        if self.params_file is not None and name != "recorder":
            ros_args += ["--params-file", str(self.params_file)]
        return self.start_module(
            key or name, NODE_MODULES[name], *ros_args, *args, prefix=prefix, env=env
        )

    def start_module(
        self,
        key: str,
        module: str,
        *args: str,
        prefix: tuple[str, ...] = (),
        env: dict | None = None,
    ) -> subprocess.Popen:
        """``python -m module args`` under ``key`` (a node, or a helper such as the clock
        stepper of :mod:`support.sim_clock`)."""
        self._n += 1
        stem = self.dir / f"{key}.{self._n}"
        with open(f"{stem}.out", "wb") as out, open(f"{stem}.err", "wb") as err:
            proc = subprocess.Popen(
                [*prefix, sys.executable, "-m", module, *args], stdout=out, stderr=err, env=env
            )
        proc.stderr_path = Path(f"{stem}.err")  # type: ignore[attr-defined]
        proc.stdout_path = Path(f"{stem}.out")  # type: ignore[attr-defined]
        if key in self.procs:
            self.dead.append(self.procs[key])
        self.procs[key] = proc
        return proc

    def start_controllers(self) -> None:
        """The feedforward and feedback nodes (the plant is started once they are up)."""
        self.start("feedforward_node")
        self.start("feedback_node")

    def kill(self, key: str) -> float:
        """SIGKILL a node; return the monotonic time of the kill.

        It is not waited for here: reaping a process can take a while (its DDS threads and
        shared memory are torn down) and the observer must keep spinning meanwhile, or the
        receive times it records would be late. :meth:`close` reaps it.
        """
        proc = self.procs[key]
        t = time.monotonic()
        proc.kill()
        return t

    def stderr(self, key: str) -> str:
        return self.procs[key].stderr_path.read_text(errors="replace")  # type: ignore[attr-defined]

    def close(self) -> None:
        stop_processes([*self.procs.values(), *self.dead], timeout_s=3.0)


def wait_all(
    procs: dict[str, subprocess.Popen],
    timeout_s: float,
    stacks: dict[str, str] | None = None,
    stacks_after_s: float = 2.5,
) -> dict[str, float]:
    """Poll until every process has exited; return each one's exit time from now (s).

    With ``stacks``, a process still running ``stacks_after_s`` from now gets its native
    stacks taken once (:func:`native_stacks`) into ``stacks`` by name: a node's teardown that
    blocked below Python shows only its Python frames in the teardown limit's dump.
    """
    t0 = time.monotonic()
    took: dict[str, float] = {}
    while len(took) < len(procs) and time.monotonic() - t0 < timeout_s:
        for name, proc in procs.items():
            if name not in took and proc.poll() is not None:
                took[name] = time.monotonic() - t0
            elif (
                stacks is not None
                and name not in took
                and name not in stacks
                and time.monotonic() - t0 > stacks_after_s
            ):
                stacks[name] = native_stacks(proc.pid)
        time.sleep(0.002)
    return took


def native_stacks(pid: int) -> str:
    """Every thread's native stack of a running process, by gdb (a test may attach to the
    processes it started), or why there are none."""
    gdb = shutil.which("gdb")
    if gdb is None:
        return "(no gdb on PATH: no native stacks)"
    try:
        out = subprocess.run(
            [gdb, "-p", str(pid), "-batch", "-ex", "thread apply all bt 30"],
            capture_output=True,
            text=True,
            timeout=60,
        )
    except subprocess.TimeoutExpired:
        return "(gdb took over 60 s)"
    return out.stdout[-30000:] or out.stderr[-2000:]


def process_group(pgid: int) -> list[str]:
    """Processes (``pid name state``) whose process group is ``pgid``, from ``/proc``."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()
        if int(fields[2]) == pgid:
            members.append(f"{entry.name} {name} {fields[0]}")
    return members
