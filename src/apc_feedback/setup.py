from setuptools import find_packages, setup

package_name = "apc_feedback"

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
        "Recursive least-squares identification of the perturbation model and one-step "
        "optimal feedback for apc, plus computed-torque and PD baselines."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "feedback_node = apc_feedback.node:main",
            "robot_node = apc_feedback.robot_node:main",
        ],
    },
)
