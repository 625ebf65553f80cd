"""ros2msg definitions of the standard messages grapefmu records (dependencies appended, as MCAP's
ros2msg schema encoding requires), so recordings need no ROS installation to write or read."""
from __future__ import annotations

SEP = "\n" + "=" * 80 + "\n"

_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z"


def _join(main: str, *deps: str) -> str:
    return main + "".join(SEP + d for d in deps)


MSGDEFS = {
    "sensor_msgs/msg/JointState": _join(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort",
        _HEADER, _TIME),
    "geometry_msgs/msg/AccelStamped": _join(
        "std_msgs/Header header\ngeometry_msgs/Accel accel", _HEADER, _TIME,
        "MSG: geometry_msgs/Accel\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular", _VECTOR3),
    "geometry_msgs/msg/WrenchStamped": _join(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench", _HEADER, _TIME,
        "MSG: geometry_msgs/Wrench\ngeometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque", _VECTOR3),
    "std_msgs/msg/Float64MultiArray": _join(
        "std_msgs/MultiArrayLayout layout\nfloat64[] data",
        "MSG: std_msgs/MultiArrayLayout\nstd_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
        "MSG: std_msgs/MultiArrayDimension\nstring label\nuint32 size\nuint32 stride"),
}
