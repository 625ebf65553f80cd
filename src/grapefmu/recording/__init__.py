"""Recording runs to MCAP (profile ros2, ros2msg schemas, cdr encoding) with standard messages."""
