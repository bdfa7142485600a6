"""What a long run prints: one progress line per run when stderr is not a terminal, and the
nodes' log lines in a file of the run's folder instead of the console."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from apc_lab.experiment import Progress

pytestmark = pytest.mark.ros


def test_progress_prints_one_line_per_named_step_off_a_terminal(capsys):
    bar = Progress(3, "make run")
    bar.tty = False
    for i, name in enumerate(("a_ct", "a_apc", "b_ct")):
        bar.update(i, name)
    bar.update(3)
    bar.close()
    err = capsys.readouterr().err.splitlines()
    assert err == ["make run 1/3: a_ct", "make run 2/3: a_apc", "make run 3/3: b_ct"]
    quiet = Progress(3, "make run", enabled=False)
    quiet.tty = False
    quiet.update(0, "a_ct")
    assert capsys.readouterr().err == ""


def test_node_logs_go_to_the_folder_not_the_console(tmp_path):
    """In a process of its own: rcl's logging is configured once per process."""
    script = textwrap.dedent(
        f"""
        from pathlib import Path
        import rclpy
        from apc_core.node_logs import node_logs_to

        with node_logs_to(Path({str(tmp_path / "logs")!r})):
            context = rclpy.Context()
            rclpy.init(context=context)
            node = rclpy.create_node("chatty", context=context)
            node.get_logger().info("a line for the file")
            node.destroy_node()
            rclpy.shutdown(context=context)
        print("done")
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "done" and "a line for the file" not in out.stderr
    logs = list((tmp_path / "logs").glob("*.log"))
    assert logs and "a line for the file" in "".join(p.read_text() for p in logs)
