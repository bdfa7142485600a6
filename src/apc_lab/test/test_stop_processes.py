"""The runner's way of ending its children (``apc_lab.experiment.stop_processes``)."""

from __future__ import annotations

import subprocess
import sys

from apc_lab.experiment import INTERRUPTED_STOP_S, _name_killed, stop_processes

#: A child that ignores SIGINT and SIGTERM, as one blocked in native code does (its Python
#: handler never runs), and one that ends on SIGINT (set, not inherited: a test run in the
#: background of a non-interactive shell starts its children with SIGINT ignored).
STUCK = "import signal, time; [signal.signal(s, signal.SIG_IGN) for s in (2, 15)]; "
STUCK += "print('ready', flush=True); time.sleep(60)"
OBEDIENT = "import signal, sys, time; signal.signal(2, lambda *_: sys.exit(0)); "
OBEDIENT += "print('ready', flush=True); time.sleep(60)"


def _child(code: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    return proc


def test_a_child_that_ignores_sigint_and_sigterm_is_killed_and_named(capsys):
    stuck, obedient = _child(STUCK), _child(OBEDIENT)
    try:
        killed = stop_processes([stuck, obedient], INTERRUPTED_STOP_S)
        assert killed == [stuck]
        assert stuck.returncode == -9 and obedient.returncode == 0
        _name_killed({"plant_node": obedient, "feedback_node": stuck}, killed, 0.5)
        err = capsys.readouterr().err
        assert "experiment: feedback_node did not stop on SIGINT or SIGTERM within 1 s" in err
        assert "plant_node" not in err
    finally:
        for proc in (stuck, obedient):
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            assert proc.stdout is not None
            proc.stdout.close()


def test_children_that_end_on_sigint_are_not_killed():
    children = [_child(OBEDIENT), _child(OBEDIENT)]
    try:
        assert stop_processes(children, INTERRUPTED_STOP_S) == []
        assert [p.returncode for p in children] == [0, 0]
    finally:
        for proc in children:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            assert proc.stdout is not None
            proc.stdout.close()
