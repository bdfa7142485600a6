from setuptools import find_packages, setup

package_name = "apc_msgs_py"

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
        "The wire contract of apc: topic names, QoS, stamps, message <-> numpy conversion and "
        "validation (as sensor_msgs_py is for sensor_msgs)."
    ),
    license="Apache-2.0",
)
