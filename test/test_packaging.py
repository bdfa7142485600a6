"""The ROS packaging: ``colcon build`` of ``src/`` gives a workspace that ``ros2 run`` can use.

One ``colcon build`` (colcon from PyPI, in the venv) into a temporary build/install/log base,
then: every executable is in ``install/<pkg>/lib/<pkg>/`` (where ``ros2 run`` looks) and is a
console script in the venv; package.xml, the ament resource marker and apc's config files are
under ``share``; the nodes start from the install the way ``ros2 run`` starts them (after
``. install/setup.sh``, with the venv — where rclpy and the message packages live — as the
underlay of the workspace) and find their URDF in ``share/apc_core/config``, not in the
source checkout.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
VENV_BIN = VENV / "bin"

PACKAGES = (
    "apc_msgs_py",
    "apc_core",
    "apc_recording",
    "apc_feedforward",
    "apc_feedback",
    "apc_plant_sim",
    "apc_lab",
)
EXECUTABLES: dict[str, tuple[str, ...]] = {
    "apc_recording": ("recorder", "player", "bag_recover"),
    "apc_feedforward": ("feedforward_node",),
    "apc_feedback": ("feedback_node", "robot_node"),
    "apc_plant_sim": ("plant_node", "robot_sim"),
    "apc_lab": ("composed", "experiment", "analyze", "apc_params"),
}
#: One node of each package that has one, run to ``--help`` (the lab's ``experiment`` runs from
#: the install below).
HELP_RUNS = (
    ("apc_recording", "recorder"),
    ("apc_feedforward", "feedforward_node"),
    ("apc_feedback", "feedback_node"),
    ("apc_feedback", "robot_node"),
    ("apc_plant_sim", "plant_node"),
)
#: Installed into share/apc_core/config (relative to the repository's config/).
CONFIG_GLOBS = ("*.urdf", "*.yaml", "reference/*.json")
PARAMS_FILE = "puma560_3dof.yaml"

#: Variables of an already sourced ROS environment or workspace: dropped, so the build and the
#: children see only the workspace under test and the venv.
_WORKSPACE_VARS = (
    "AMENT_PREFIX_PATH",
    "COLCON_PREFIX_PATH",
    "COLCON_CURRENT_PREFIX",
    "CMAKE_PREFIX_PATH",
    "PYTHONPATH",
    "ROS_DISTRO",
)

#: ``ros2 run`` in a shell: source the workspace, then the venv is the underlay (after the
#: workspace in AMENT_PREFIX_PATH, as /opt/ros/jazzy would be), then exec the command.
_SOURCED = (
    '. "$APC_INSTALL/setup.sh" && '
    'AMENT_PREFIX_PATH="${AMENT_PREFIX_PATH:+$AMENT_PREFIX_PATH:}$APC_UNDERLAY" && '
    'export AMENT_PREFIX_PATH && exec "$@"'
)

START_TIMEOUT_S = 30.0
RUN_S = 2.0
STOP_TIMEOUT_S = 2.0


def _base_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in _WORKSPACE_VARS}
    env["PATH"] = os.pathsep.join([str(VENV_BIN), env.get("PATH", "")])
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # conftest.py set ROS_DOMAIN_ID
    return env


def _default_sigint() -> None:
    # A child of a process started in the background by a non-interactive shell inherits
    # SIGINT ignored, and would then never see our SIGINT.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Workspace:
    def __init__(self, root: Path, build_s: float) -> None:
        self.root = root
        self.install = root / "install"
        self.build_s = build_s
        self.colcon_home = root / "colcon_home"
        self.scratch = root / "cwd"  # a working directory outside the repository
        self.scratch.mkdir()

    def env(self) -> dict[str, str]:
        env = _base_env()
        env["APC_INSTALL"] = str(self.install)
        env["APC_UNDERLAY"] = str(VENV)
        return env

    def command(self, *argv: str | Path) -> list[str]:
        """``argv`` run by ``sh`` after ``. install/setup.sh``."""
        return ["sh", "-c", _SOURCED, "sh", *map(str, argv)]

    def executable(self, pkg: str, exe: str) -> Path:
        return self.install / pkg / "lib" / pkg / exe

    def share(self, pkg: str) -> Path:
        return self.install / pkg / "share" / pkg

    def popen(self, *argv: str | Path, **kwargs) -> subprocess.Popen:
        return subprocess.Popen(
            self.command(*argv),
            env=self.env(),
            cwd=self.scratch,
            preexec_fn=_default_sigint,
            **kwargs,
        )

    def run(self, *argv: str | Path, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run(
            self.command(*argv),
            env=self.env(),
            cwd=self.scratch,
            capture_output=True,
            text=True,
            timeout=timeout,
        )


def _new_artefacts() -> set[Path]:
    """What a build that writes into the source tree would leave there."""
    found: set[Path] = set()
    for pkg in PACKAGES:
        src = REPO / "src" / pkg
        found |= set(src.glob("*.egg-info")) | {p for p in (src / "build",) if p.exists()}
    return found


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workspace]:
    colcon = VENV_BIN / "colcon"
    assert colcon.is_file(), f"colcon is not installed in the venv ({colcon})"
    root = tmp_path_factory.mktemp("colcon")
    before = _new_artefacts()
    env = _base_env()
    env["COLCON_HOME"] = str(root / "colcon_home")  # no user defaults (e.g. symlink-install)
    argv = [
        str(colcon),
        "--log-base",
        str(root / "log"),
        "build",
        "--base-paths",
        str(REPO / "src"),
        "--build-base",
        str(root / "build"),
        "--install-base",
        str(root / "install"),
    ]
    t0 = time.monotonic()
    proc = subprocess.run(
        argv, cwd=root, env=env, capture_output=True, text=True, timeout=300, check=False
    )
    build_s = time.monotonic() - t0
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"colcon build failed ({proc.returncode}):\n{output[-6000:]}"
    print(f"colcon build: {build_s:.1f} s")
    for pkg in PACKAGES:
        assert f"Finished <<< {pkg}" in output, f"colcon did not build {pkg}:\n{output[-3000:]}"
    assert _new_artefacts() == before, "colcon build wrote into the source tree"
    yield Workspace(root, build_s)


def test_colcon_test_runs_every_package_unit_tests(workspace):
    """``colcon test`` runs each package's own tests (``src/<pkg>/test``, pytest) against the
    install, and every one passes."""
    results = workspace.root / "test_results"
    before = _new_artefacts()
    env = _base_env()
    env["COLCON_HOME"] = str(workspace.colcon_home)
    argv = [
        str(VENV_BIN / "colcon"),
        "--log-base",
        str(workspace.root / "log"),
        "test",
        "--base-paths",
        str(REPO / "src"),
        "--build-base",
        str(workspace.root / "build"),
        "--install-base",
        str(workspace.install),
        "--test-result-base",
        str(results),
        "--pytest-args",
        "-p",
        "no:cacheprovider",
    ]
    proc = subprocess.run(
        argv, cwd=workspace.root, env=env, capture_output=True, text=True, timeout=600
    )
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"colcon test failed ({proc.returncode}):\n{output[-6000:]}"
    for pkg in PACKAGES:
        report = results / pkg / "pytest.xml"
        assert report.is_file(), f"colcon test ran no pytest for {pkg}:\n{output[-3000:]}"
        suite = ET.parse(report).getroot()
        suite = suite if suite.tag == "testsuite" else suite.find("testsuite")
        counts = {k: int(suite.get(k, "0")) for k in ("tests", "failures", "errors")}
        assert counts["tests"] > 0, f"{pkg} has no unit tests"
        assert counts["failures"] == counts["errors"] == 0, f"{pkg}: {counts}"
    assert _new_artefacts() == before, "colcon test wrote into the source tree"


def test_config_link_in_source_package():
    link = REPO / "src" / "apc_core" / "config"
    assert link.is_symlink() and not Path(os.readlink(link)).is_absolute()
    assert link.resolve() == (REPO / "config").resolve()


@pytest.mark.parametrize(
    ("pkg", "exe"), [(pkg, exe) for pkg, exes in EXECUTABLES.items() for exe in exes]
)
def test_executable_installed(workspace, pkg, exe):
    """Where ``ros2 run <pkg> <exe>`` looks, and as a console script in the venv."""
    for path in (workspace.executable(pkg, exe), VENV_BIN / exe):
        assert path.is_file(), f"missing: {path}"
        assert os.access(path, os.X_OK), f"not executable: {path}"


@pytest.mark.parametrize("pkg", list(EXECUTABLES))
def test_package_share(workspace, pkg):
    prefix = workspace.install / pkg
    assert (workspace.share(pkg) / "package.xml").is_file()
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / pkg).is_file()
    # colcon built it as an ament_python package (a manifest catkin_pkg rejects gives a plain
    # Python package without the ament hook, which `ros2 run` and ament_index would not see).
    assert (workspace.share(pkg) / "hook" / "ament_prefix_path.dsv").is_file()


def test_config_installed_as_files(workspace):
    source = REPO / "config"
    expected = sorted(p.relative_to(source) for g in CONFIG_GLOBS for p in source.glob(g))
    assert Path("puma560_3dof.urdf") in expected and Path(PARAMS_FILE) in expected
    installed = workspace.share("apc_core") / "config"
    found = sorted(p.relative_to(installed) for p in installed.rglob("*") if not p.is_dir())
    assert found == expected
    for rel in expected:
        path = installed / rel
        assert path.is_file() and not path.is_symlink(), f"not a copied file: {path}"
        assert path.read_bytes() == (source / rel).read_bytes(), f"differs from source: {rel}"


def test_help_from_install_and_venv(workspace):
    """One executable of each package to ``--help``: from the install and from the venv."""
    runs = {}
    for pkg, exe in HELP_RUNS:
        runs[f"install {pkg}/{exe}"] = workspace.popen(
            workspace.executable(pkg, exe),
            "--help",
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        runs[f"venv {exe}"] = subprocess.Popen(
            [str(VENV_BIN / exe), "--help"],
            env=_base_env(),
            cwd=workspace.scratch,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
    failures = []
    try:
        for name, proc in runs.items():
            out, err = proc.communicate(timeout=60)
            text = out.lower()
            if proc.returncode != 0 or "usage" not in text or "parameters" not in text:
                failures.append(f"{name}: exit {proc.returncode}\n{out[-1500:]}{err[-1500:]}")
    finally:
        for proc in runs.values():
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert not failures, "\n".join(failures)


def test_config_resolved_through_install_share(workspace):
    """From a directory outside the repo, apc is imported from the install and its config
    files are found in share/apc_core/config of the install, not in the checkout."""
    probe = (
        "import apc_core.config_files as u;"
        "print(u.__file__);"
        f"print(u.resolve_config_path('puma560_3dof.urdf'));"
        f"print(u.resolve_config_path('{PARAMS_FILE}'))"
    )
    proc = workspace.run(sys.executable, "-c", probe)
    assert proc.returncode == 0, proc.stderr
    module, urdf, params = (Path(line) for line in proc.stdout.split())
    assert module.is_relative_to(workspace.install / "apc_core"), module
    config = workspace.share("apc_core") / "config"
    assert urdf == config / "puma560_3dof.urdf"
    assert params == config / PARAMS_FILE


@pytest.mark.ros
def test_experiment_runs_from_the_install_without_the_source_tree(workspace, ros_domain):
    """``experiment --case a`` from a directory outside the checkout, with apc imported from
    the install: the scenario's URDF and reference numbers come from share/apc_core/config
    (a checkout's ``config/`` is not where an install looks), the run is recorded."""
    probe = "import apc_lab.scenario as s; print(s.__file__); print(s.CONFIG_DIR)"
    proc = workspace.run(sys.executable, "-c", probe)
    assert proc.returncode == 0, proc.stderr
    module, config = (Path(line) for line in proc.stdout.split())
    assert module.is_relative_to(workspace.install / "apc_lab"), module
    assert config == workspace.share("apc_core") / "config"
    out = workspace.root / "runs"
    run = workspace.run(
        workspace.executable("apc_lab", "experiment"),
        "--case",
        "a",
        "--hold",
        "0.1",
        "--out",
        out,
        "--quiet",
        timeout=180.0,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert list(out.glob("*.mcap")), run.stdout[-2000:]


def _wait_for_node(name: str, child: subprocess.Popen, timeout_s: float) -> bool:
    """True once ``/name`` is in the ROS graph (seen from a context of our own)."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    try:
        probe = rclpy.create_node("apc_packaging_probe", context=context)
        try:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline and child.poll() is None:
                if (name, "/") in probe.get_node_names_and_namespaces():
                    return True
                time.sleep(0.05)
            return False
        finally:
            probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.ros
def test_feedback_node_runs_from_install_and_stops_on_sigint(workspace, ros_domain):
    params = workspace.share("apc_core") / "config" / PARAMS_FILE
    out, err = workspace.root / "feedback_node.out", workspace.root / "feedback_node.err"
    with open(out, "w") as stdout, open(err, "w") as stderr:
        child = workspace.popen(
            workspace.executable("apc_feedback", "feedback_node"),
            "--ros-args",
            "--params-file",
            params,
            stdout=stdout,
            stderr=stderr,
        )
    try:
        started = _wait_for_node("feedback_node", child, START_TIMEOUT_S)
        assert started, f"feedback_node did not start (exit {child.poll()}):\n{err.read_text()}"
        time.sleep(RUN_S)
        assert child.poll() is None, f"feedback_node exited early:\n{err.read_text()}"
        child.send_signal(signal.SIGINT)
        try:
            code = child.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"feedback_node still running {STOP_TIMEOUT_S} s after SIGINT")
        assert code == 0, f"feedback_node exited {code} on SIGINT:\n{err.read_text()}"
        assert "Traceback" not in err.read_text()
    finally:
        if child.poll() is None:
            child.terminate()
            try:
                child.wait(timeout=2)
            except subprocess.TimeoutExpired:
                child.kill()
                child.wait()


def test_bad_parameter_exits_2_with_one_line(workspace, ros_domain):
    # No params file: a node-specific entry in it would outrank the global -p.
    proc = workspace.run(
        workspace.executable("apc_feedback", "feedback_node"),
        "--ros-args",
        "-p",
        "adaptive.rho:=1.5",
    )
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, f"exit {proc.returncode}:\n{proc.stderr}"
    assert len(lines) == 1 and "adaptive.rho" in lines[0], proc.stderr
