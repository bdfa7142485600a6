from setuptools import find_packages, setup

package_name = "apc_plant_sim"

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
        "apc's simulated arms: the plant (Lagrange-Euler, RK4) behind plant_node and a"
        " ros2_control-style robot (apc's plant or MuJoCo) behind robot_sim."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "plant_node = apc_plant_sim.node:main",
            "robot_sim = apc_plant_sim.robot_sim:main",
        ],
    },
)
