from setuptools import find_packages, setup

package_name = "apc_recording"

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
        "Recording and playback of apc's runs: a rosbag2-compatible MCAP recorder and player, "
        "crash recovery, and runs read back as numpy arrays."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder = apc_recording.recorder:main",
            "player = apc_recording.player:main",
            "bag_recover = apc_recording.bag.recovery:main",
        ],
    },
)
