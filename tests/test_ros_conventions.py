"""The node fits a robot's ROS graph: TF, the ROS clock, best-effort inputs and gripper motion from TF,
each over DDS with the node in its own process."""
from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
tf2_msgs = pytest.importorskip("tf2_msgs.msg")

from geometry_msgs.msg import AccelStamped, TransformStamped  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from grapefmu import Solver, load_scene  # noqa: E402
from grapefmu.recording import frames  # noqa: E402
from grapefmu.recording.stamps import stamp_seconds  # noqa: E402
from grapefmu.scenefile import default_scene_path  # noqa: E402

from .test_ros_node import QOS, Controller, drive, ros, signal_rows, sim_node  # noqa: E402,F401

LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
BEST_EFFORT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)


def _matrix(tr: TransformStamped) -> np.ndarray:
    """4x4 homogeneous matrix of a transform (child in parent)."""
    q, p = tr.transform.rotation, tr.transform.translation
    x, y, z, w = q.x, q.y, q.z, q.w
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (p.x, p.y, p.z)
    return T


class TfListener:
    """A minimal tf2 buffer (tf2_ros is not on the package index): the latest transform per child frame,
    composed up to the root."""

    def __init__(self, node):
        self.edges = {}
        node.create_subscription(tf2_msgs.TFMessage, "/tf", self._take, QOS)
        node.create_subscription(tf2_msgs.TFMessage, "/tf_static", self._take, LATCHED)

    def _take(self, msg):
        for tr in msg.transforms:
            self.edges[tr.child_frame_id] = tr

    def lookup(self, target: str, source: str) -> np.ndarray:
        """The pose of `source` in `target`, by walking the tree (raises KeyError when not connected)."""
        T, frame = np.eye(4), source
        while frame != target:
            tr = self.edges[frame]
            T = _matrix(tr) @ T
            frame = tr.header.frame_id
        return T


def test_a_tf_listener_resolves_world_to_every_berry_and_the_urdf_names_the_same_frames(ros, tmp_path):
    rows = signal_rows(60)
    with sim_node(tmp_path, record=False) as (proc, _):
        ctl = Controller("tf_controller")
        tf = TfListener(ctl.node)
        urdf = []
        ctl.node.create_subscription(String, "robot_description", urdf.append, LATCHED)
        ctl.connect()
        drive(ctl, rows)
        ctl.spin(0.5)
        ctl.close()
    scene = load_scene(default_scene_path())
    solver = Solver(scene)
    for (_, a), (t1, _) in zip(rows, rows[1:]):
        solver.advance(stamp_seconds(0, int(round(t1 * 1e9))) - solver.t, (a, 0.0))
    snap = solver.snapshot()
    p = snap.observation.position[0]
    d = snap.base_displacement[0]
    for i, name in enumerate(scene.model.names):
        T = tf.lookup("world", f"grape_cluster/{name}")
        np.testing.assert_allclose(T[:3, 3], p[i] + (d[0], 0.0, d[1]), atol=1e-12)
        hinge = tf.lookup("world", f"grape_cluster/{name}_hinge")[:3, 3]
        twig = hinge - T[:3, 3]
        np.testing.assert_allclose(T[:3, 2], twig / np.linalg.norm(twig), atol=1e-9)  # z along the twig
        assert abs(np.linalg.norm(twig) - scene.model.berries[i].twig_length) < 1e-9
    assert urdf and urdf[-1].data == frames.urdf(scene.model)
    for name in scene.model.names:
        assert f'<link name="grape_cluster/{name}">' in urdf[-1].data


def test_real_time_stamps_follow_the_ros_clock(ros, tmp_path):
    lags = []
    with sim_node(tmp_path, mode="realtime", record=False) as (proc, _):
        ctl = Controller("clock_controller")
        clock = ctl.node.get_clock()

        def take(m: JointState):
            lags.append(clock.now().nanoseconds * 1e-9 - stamp_seconds(m.header.stamp.sec, m.header.stamp.nanosec))

        ctl.node.create_subscription(JointState, "joint_states", take, QOS)
        ctl.wait_for(lambda: len(lags) > 500)
        ctl.close()
    lags = np.array(lags[100:])
    assert np.all(np.abs(lags) < 0.05), (lags.min(), lags.max())  # stamps are wall time, not seconds since start
    assert np.median(np.abs(lags)) < 0.01


def test_a_best_effort_publisher_drives_the_node(ros, tmp_path):
    with sim_node(tmp_path, record=False) as (proc, _):
        ctl = Controller("best_effort_controller")
        ctl.pub = ctl.node.create_publisher(AccelStamped, "rachis/accel", BEST_EFFORT)
        ctl.connect()
        rows = signal_rows(20)
        for t, a in rows:  # best effort may drop a message: resend until the node answers
            ctl.wait_for(lambda t=t, a=a: ctl.send(t, a) or ctl.spin(0.02) or ctl.state_at(t) is not None)
        ctl.close()
    assert ctl.state_at(rows[-1][0]) is not None


def test_the_gripper_motion_comes_from_a_tf_frame_of_another_process(ros, tmp_path):
    """The node looks up `gripper` in `world` on /tf; a constant 2 m/s² carry along x must reach the solver
    as (almost) 2 m/s², after the pose filter settles."""
    import json
    import subprocess
    import sys
    from .test_ros_node import ENV
    publisher = """
import time, rclpy
from tf2_msgs.msg import TFMessage
from geometry_msgs.msg import TransformStamped
rclpy.init()
node = rclpy.create_node("robot_tf")
pub = node.create_publisher(TFMessage, "/tf", 100)
time.sleep(2.0)
for k in range(400):
    t = 0.01 * (k + 1)
    tr = TransformStamped()
    tr.header.frame_id, tr.child_frame_id = "world", "gripper"
    ns = int(round(t * 1e9))
    tr.header.stamp.sec, tr.header.stamp.nanosec = ns // 10**9, ns % 10**9
    tr.transform.translation.x = 0.5 * 2.0 * t * t
    tr.transform.rotation.w = 1.0
    pub.publish(TFMessage(transforms=[tr]))
    time.sleep(0.01)
"""
    applied = []
    with sim_node(tmp_path, record=False, extra=["-p", "gripper_frame:=gripper"]) as (proc, _):
        ctl = Controller("tf_input_listener")
        ctl.node.create_subscription(AccelStamped, "rachis/accel_applied", applied.append, QOS)
        ctl.connect()
        robot = subprocess.Popen([sys.executable, "-c", publisher], env=ENV)
        ctl.wait_for(lambda: robot.poll() is not None, timeout=60)
        ctl.spin(0.5)
        ctl.close()
    assert robot.returncode == 0
    ax = np.array([m.accel.linear.x for m in applied])
    assert len(ax) > 200, json.dumps(len(ax))
    np.testing.assert_allclose(ax[-50:], 2.0, rtol=0.05)


def test_the_gripper_motion_comes_from_twist_messages(ros, tmp_path):
    """TwistStamped on rachis/twist: a velocity rising at 3 m/s² along z reaches the solver as (almost) 3 m/s²
    once the filter settles, and is recorded as the held acceleration of every interval."""
    from geometry_msgs.msg import TwistStamped

    applied = []
    with sim_node(tmp_path, record=False) as (proc, _):
        ctl = Controller("twist_input")
        twist = ctl.node.create_publisher(TwistStamped, "rachis/twist", QOS)
        ctl.node.create_subscription(AccelStamped, "rachis/accel_applied", applied.append, QOS)
        ctl.connect()
        ctl.wait_for(lambda: twist.get_subscription_count() > 0)
        for k in range(300):
            m = TwistStamped()
            ns = int(round(0.01 * (k + 1) * 1e9))
            m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9
            m.twist.linear.z = 3.0 * 0.01 * (k + 1)
            twist.publish(m)
            ctl.spin(0.01)
        ctl.spin(0.5)
        ctl.close()
    az = np.array([m.accel.linear.z for m in applied])
    assert len(az) > 100
    np.testing.assert_allclose(az[-50:], 3.0, rtol=0.05)
    assert np.all(np.abs([m.accel.linear.x for m in applied]) < 1e-12)
