"""Every package's ``package.xml`` declares what its code imports, by its rosdep key; the
packages depend one way and their modules stay small.

rosdep installs what ``package.xml`` lists; a module imported but not declared is a broken
install on a machine that has only what rosdep gave it. Keys are rosdistro's (ROS packages by
name, ``python3-*`` for Python packages with an apt package) or, for what has none, the pip keys
of ``rosdep/apc.yaml``, which is checked to define them.
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
PACKAGES = (
    "apc_msgs_py",
    "apc_core",
    "apc_recording",
    "apc_feedforward",
    "apc_feedback",
    "apc_plant_sim",
    "apc_lab",
)
#: Imported module -> rosdep key (the module's own name when it is a ROS package).
KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "pinocchio": "pinocchio",
    "mcap": "python3-mcap-pip",
    "zstandard": "python3-zstandard-pip",
    "mujoco": "python3-mujoco-pip",
    "pytest": "python3-pytest",
    "rosbags": "python3-rosbags-pip",
    "mcap_ros2": "python3-mcap-ros2-support-pip",
}
#: ROS packages imported by name (their rosdep key is the package name).
ROS_PACKAGES = {
    "rclpy",
    "ament_index_python",
    "builtin_interfaces",
    "diagnostic_msgs",
    "lifecycle_msgs",
    "rcl_interfaces",
    "rosgraph_msgs",
    "sensor_msgs",
    "std_msgs",
    "trajectory_msgs",
}
#: Imported indirectly: rclpy.lifecycle needs lifecycle_msgs.
IMPLIED = {"rclpy.lifecycle": "lifecycle_msgs"}


def _imports(package: str, part: str | None = None) -> set[str]:
    """Top-level modules (and the implied ones) imported anywhere in ``package``'s code, or in
    its ``part`` (``"test"``: its unit tests, less their own helper modules, which the tests
    import by name from their directory as pytest puts it on ``sys.path``)."""
    root = REPO / "src" / package / (part or package)
    own = {path.stem for path in root.glob("*.py")} if part else set()
    found: set[str] = set()
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            for name in names:
                found.add(name.split(".")[0])
                found |= {IMPLIED[name]} if name in IMPLIED else set()
    return found - own


def _declared(package: str, tags: tuple[str, ...] = ("depend", "exec_depend")) -> set[str]:
    root = ET.parse(REPO / "src" / package / "package.xml").getroot()
    return {e.text for tag in tags for e in root.iter(tag) if e.text}


def _keys(package: str, modules: set[str]) -> set[str]:
    """The rosdep keys of ``modules`` (apc's own and the standard library's left out)."""
    needed = set()
    for module in modules - set(sys.stdlib_module_names) - {package}:
        if module in KEYS:
            needed.add(KEYS[module])
        elif module in ROS_PACKAGES or module in PACKAGES:
            needed.add(module)
        else:
            pytest.fail(f"{package} imports {module!r}: give it a rosdep key in this test")
    return needed


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_every_import(package):
    missing = _keys(package, _imports(package)) - _declared(package)
    assert not missing, f"{package}/package.xml lacks {sorted(missing)}"


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_what_its_unit_tests_import(package):
    """``colcon test`` runs ``src/<pkg>/test``: what it imports is a dependency or a
    ``test_depend``."""
    needed = _keys(package, _imports(package, "test"))
    missing = needed - _declared(package, ("depend", "exec_depend", "test_depend"))
    assert not missing, f"{package}/package.xml lacks test_depend {sorted(missing)}"


def test_the_pip_keys_are_defined_for_rosdep():
    defined = yaml.safe_load((REPO / "rosdep" / "apc.yaml").read_text())
    tags = ("depend", "exec_depend", "test_depend")
    used = {k for p in PACKAGES for k in _declared(p, tags) if k.endswith("-pip")}
    assert used <= set(defined)
    for key in used:
        assert set(defined[key]) == {"debian", "ubuntu"}, key


#: The apc packages each package may use: the contract, the runtime, then recording, the two
#: controllers and the simulated arms beside each other, and the lab on top (nothing uses it).
MAY_USE = {
    "apc_msgs_py": set(),
    "apc_core": {"apc_msgs_py"},
    "apc_recording": {"apc_msgs_py", "apc_core"},
    "apc_feedforward": {"apc_msgs_py", "apc_core"},
    "apc_feedback": {"apc_msgs_py", "apc_core", "apc_feedforward"},
    "apc_plant_sim": {"apc_msgs_py", "apc_core"},
    "apc_lab": set(PACKAGES) - {"apc_lab"},
}


@pytest.mark.parametrize("package", PACKAGES)
def test_dependencies_point_one_way(package):
    """No package uses one above it: the simulated arms import no controller, a robot install
    (robot_node) pulls in neither the simulator nor the lab."""
    used = _declared(package) | _imports(package) | _imports(package, "test")
    used &= set(PACKAGES) - {package}
    assert used <= MAY_USE[package], f"{package} uses {sorted(used - MAY_USE[package])}"


def test_no_module_over_600_lines():
    """Small modules with one job: a module that grows past 600 lines is split by job (a test
    module in ``src/<pkg>/test`` by topic)."""
    long = {
        str(path.relative_to(REPO)): n
        for package in PACKAGES
        for part in (package, "test")
        for path in (REPO / "src" / package / part).rglob("*.py")
        if (n := len(path.read_text().splitlines())) > 600
    }
    assert not long, long
