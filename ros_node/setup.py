"""ament_python build of the node, for a colcon workspace (docs/ros.md); the simulator (`grapefmu`) is
installed with pip. Run: ros2 run grapefmu_ros grapefmu_node --ros-args -p mode:=realtime"""
from setuptools import setup

setup(
    name="grapefmu_ros",
    version="0.1.0",
    packages=["grapefmu_ros"],
    data_files=[("share/ament_index/resource_index/packages", ["resource/grapefmu_ros"]),
                ("share/grapefmu_ros", ["package.xml"])],
    install_requires=["setuptools"],
    zip_safe=True,
    license="MIT",
    entry_points={"console_scripts": ["grapefmu_node = grapefmu_ros.node:main",
                                      "grapefmu_controller = grapefmu_ros.controller:main",
                                      "grapefmu_demo = grapefmu_ros.demo:main"]},
)
