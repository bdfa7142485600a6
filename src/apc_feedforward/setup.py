from setuptools import find_packages, setup

package_name = "apc_feedforward"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="apc maintainers",
    maintainer_email="apc-maintainers@example.org",
    description=(
        "Trajectory planning (4-3-4, quintic, waypoints) and nominal torques by recursive"
        " Newton-Euler for apc."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "feedforward_node = apc_feedforward.node:main",
        ],
    },
)
