from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

package_name = "apc_core"

# config/ is a relative symlink to the repository's top-level config/ (URDFs, parameter files,
# reference data); its files are installed as copies into share/apc_core/config, where
# apc_core.config_files.resolve_config_path finds them through ament_index_python.
_HERE = Path(__file__).resolve().parent


def _config_files(pattern: str) -> list[str]:
    """Files matching ``pattern``, relative to this directory as setuptools wants them."""
    files = sorted(glob(pattern, root_dir=_HERE))
    if not files:
        raise SystemExit(
            f"apc_core: no config files match {pattern!r} (is config/ a dangling link?)"
        )
    return files


setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        (
            "share/" + package_name + "/config",
            _config_files("config/*.urdf") + _config_files("config/*.yaml"),
        ),
        ("share/" + package_name + "/config/reference", _config_files("config/reference/*.json")),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="apc maintainers",
    maintainer_email="apc-maintainers@example.org",
    description=(
        "What every apc node needs: robot models and their config files, parameters and"
        " their defaults, the node runtime (executors, signals, diagnostics)."
    ),
    license="Apache-2.0",
)
