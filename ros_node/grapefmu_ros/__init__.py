"""grapefmu as a ROS 2 node: the same simulator, driven by `rachis/accel`, publishing berry states,
contact forces, collision events, markers and diagnostics, and recording every run to MCAP."""
