"""Every command the README shows runs as written, at least to its first line of output.

The README's shell blocks are read; each command is started from the repository root, the
way a user pastes it into a shell with ``.venv`` active (on a random ``ROS_DOMAIN_ID``,
localhost only), until it prints its first line, and it must not have failed by then. A
long-lived node is then stopped with SIGINT. ``my_arm.urdf`` stands for the user's URDF (the
3-joint PUMA here) and ``my_robot.yaml`` for the file ``apc_params`` writes from it. The two
``make`` targets are this suite (``make test``) and ``test_reproduce.py`` (``make run``'s
runner on a shorter run).
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
#: Commands covered elsewhere (see the module docstring).
ELSEWHERE = {"make run", "make test"}
FIRST_OUTPUT_S = 60.0


def readme_commands(readme: Path = REPO / "README.md") -> list[str]:
    """The README's shell commands, continuation lines joined, comments dropped."""
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", readme.read_text(), flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line and not line.startswith("#"):
                commands.append(line)
    return commands


COMMANDS = readme_commands()


def test_the_readme_shows_its_commands():
    assert "make run" in COMMANDS and "make test" in COMMANDS
    assert any(c.startswith("robot_node") for c in COMMANDS)


def _argv(command: str, tmp: Path) -> list[str]:
    words = shlex.split(command)
    subst = {"my_arm.urdf": str(REPO / "config" / "puma560_3dof.urdf")}
    subst["my_robot.yaml"] = str(tmp / "my_robot.yaml")
    words = [subst.get(w, w) for w in words]
    return [str(BIN / words[0]), *words[1:]]


def _first_line(proc: subprocess.Popen, timeout_s: float) -> str:
    """The first line the process prints (stdout and stderr merged), or "" if it prints
    nothing before it exits or the time is up."""
    assert proc.stdout is not None
    os.set_blocking(proc.stdout.fileno(), False)
    buffer = b""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        chunk = proc.stdout.read()
        if chunk:
            buffer += chunk
            if b"\n" in buffer:
                return buffer.split(b"\n", 1)[0].decode(errors="replace")
        elif proc.poll() is not None:
            return buffer.decode(errors="replace")
        time.sleep(0.05)
    return buffer.decode(errors="replace")


@pytest.mark.parametrize("command", [c for c in COMMANDS if c not in ELSEWHERE])
def test_each_readme_command_runs_to_its_first_output(command, tmp_path, monkeypatch):
    if "my_robot.yaml" in command and "apc_params" not in command:
        # The file the README's apc_params line writes, as a user would have it.
        written = subprocess.run(
            _argv("apc_params --urdf my_arm.urdf --out my_robot.yaml --robot-mode", tmp_path),
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert written.returncode == 0, written.stderr
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen(
        _argv(command, tmp_path),
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        line = _first_line(proc, FIRST_OUTPUT_S)
        assert line.strip(), f"{command!r} printed nothing in {FIRST_OUTPUT_S} s"
        code = proc.poll()
        assert code in (None, 0), f"{command!r} exited {code}: {line}"
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        assert proc.stdout is not None
        proc.stdout.close()
