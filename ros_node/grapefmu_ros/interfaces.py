"""The rclpy side of grapefmu's messages: rclpy only carries them (its classes give the DDS type support);
every message is built and serialized by grapefmu's typestore (grapefmu.recording)."""
from __future__ import annotations

import importlib


def message_class(typename: str):
    """The rclpy class of a ROS type name such as "sensor_msgs/msg/JointState"."""
    pkg, _, name = typename.partition("/msg/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)
