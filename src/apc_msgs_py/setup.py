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
    zip_safe=True,
    maintainer="apc maintainers",
    maintainer_email="apc-maintainers@example.org",
    description=(
        "The shared contract of apc: topic names, QoS, message conversion and validation,"
        " robot models, config, rosbag2-compatible MCAP recording and playback."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = apc_msgs_py.recorder:main",
            "player = apc_msgs_py.player:main",
        ],
    },
)
