from setuptools import find_packages, setup

package_name = "apc_lab"

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
        "apc's lab: the launch-free experiment runner, scenarios, the paper's experiment, the "
        "robot comparison, analysis, plots and the parameter-file writer."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "composed = apc_lab.composed:main",
            "experiment = apc_lab.experiment:main",
            "analyze = apc_lab.analyze:main",
            "apc_params = apc_lab.params_file:main",
        ],
    },
)
