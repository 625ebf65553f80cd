"""The node's inputs, clock and parameters, driven in this process (its handlers called as the executor would call
them, its clock set as /clock would set it), and its parameter errors from its own process."""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.time import Time  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from grapefmu.recording import messages as msgs  # noqa: E402
from grapefmu.recording.replay import check, read_recording  # noqa: E402
from grapefmu.recording.stamps import to_ns  # noqa: E402
from grapefmu.recording.typestore import header, msg, serialize  # noqa: E402

from .conftest import one_planar_berry  # noqa: E402
from .test_ros_node import ENV, ros  # noqa: E402,F401


def node(**parameters):
    from grapefmu_ros.node import SimulatorNode
    return SimulatorNode(parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()])


def pose(n, t: float, z: float) -> None:
    n.on_pose(serialize(msg("geometry_msgs/msg/PoseStamped", header=header(to_ns(t), "world"),
                            pose={"position": {"x": 0.0, "y": 0.0, "z": z},
                                  "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}})))


def accel(n, t: float, ax: float) -> None:
    n.on_accel(serialize(msgs.accel(to_ns(t), (ax, 0.0, 0.0, 0.0, 0.0, 0.0))[1]))


def test_a_rejected_pose_leaves_no_trace_in_the_motion_the_node_derives(ros):
    """A pose glitch (2 mm for one frame, above max_accel once differentiated) is rejected; the node must then go on
    as a node that never received it: the glitch used to stay in the second difference and the low-pass filter, so
    the next pose was rejected too and a gripper at rest was held at 7.3 m/s² two frames later. A repeated stamp,
    rejected, used to get the next valid pose rejected as well."""
    glitched, clean, repeated = node(mode="lockstep", max_accel=10.0), node(mode="lockstep", max_accel=10.0), \
        node(mode="lockstep")
    try:
        for t, z in [(0.0, 0.0), (0.01, 0.0), (0.02, 0.0), (0.03, 0.002), (0.04, 0.0), (0.05, 0.0), (0.06, 0.0)]:
            pose(glitched, t, z)
            if t != 0.03:
                pose(clean, t, z)
        assert glitched.rejected == 1 and clean.rejected == 0
        assert glitched.solver.t == clean.solver.t == 0.06
        assert glitched.accel == clean.accel == (0.0,) * 6
        np.testing.assert_array_equal(glitched.solver.angles, clean.solver.angles)
        for t in (0.0, 0.01, 0.02, 0.02, 0.03, 0.04):
            pose(repeated, t, 0.0)
        assert repeated.rejected == 1 and repeated.solver.t == 0.04
    finally:
        for n in (glitched, clean, repeated):
            n.close()
            n.destroy_node()


def test_replay_restarts_at_a_lockstep_reset_whose_next_stamps_run_on(ros, tmp_path):
    """After a reset the node starts again at t = 0; inputs stamped after the time reached before it (0.5 s after
    0.2 s) integrate from 0. `replay --check` spotted a reset only where the time went back, and failed such a
    recording (0.39 rad). A reset is now in the file (sim_time 0): the replay matches it exactly."""
    rec = tmp_path / "reset.mcap"
    n = node(mode="lockstep", record=str(rec))
    try:
        for t, ax in [(0.0, 0.0), (0.1, 5.0), (0.2, 0.0)]:
            accel(n, t, ax)
        n.on_reset(None, Trigger.Response())
        for t, ax in [(0.5, -3.0), (0.6, 0.0)]:
            accel(n, t, ax)
        assert n.solver.t == 0.6
    finally:
        n.close()
        n.destroy_node()
    result = check(rec)
    assert result.ok and result.max_deviation == 0.0 and result.compared == 4  # the intervals ending 0.1 … 0.6 s


def test_a_real_time_factor_changed_while_running_goes_on_from_where_the_run_is(ros):
    """At 100× from 1×, the next tick integrated every wall second since the start at 100× (80 s in one step); back
    at 0.01× the run froze until the clock caught up with it."""
    n = node(mode="realtime")
    try:  # bounds from the wall time each stretch took, so that a stalled test process cannot fail them
        time.sleep(0.2)
        a0 = time.monotonic()
        n.on_tick()
        t1 = n.solver.t
        n.set_parameters([Parameter("real_time_factor", value=100.0)])
        n.on_tick()
        assert n.solver.t - t1 <= 100.0 * (time.monotonic() - a0) + 0.05  # since the change at 100×, not 0.2 s
        time.sleep(0.1)
        n.on_tick()
        assert 100.0 * 0.1 * 0.9 < n.solver.t - t1 <= 100.0 * (time.monotonic() - a0) + 0.05
        a2 = time.monotonic()
        n.on_tick()
        t2 = n.solver.t
        n.set_parameters([Parameter("real_time_factor", value=0.01)])
        time.sleep(0.3)
        n.on_tick()
        # on, slowly: up to the change at 100×, then at 0.01× (the run froze until the clock caught up with it)
        assert t2 < n.solver.t <= t2 + 100.0 * (time.monotonic() - a2) + 0.05
    finally:
        n.close()
        n.destroy_node()


def test_real_time_under_use_sim_time_runs_on_the_clock_topic(ros, tmp_path):
    """With use_sim_time the node's clock is /clock: before the first message it reads 0 and the run waits; then it
    follows that clock, not the computer's, and stamps the newest state with the clock's time (it used to take its
    origin from the clock at start, 0, and run on the wall clock: stamped 2.1 s where /clock read 1001 s)."""
    rec = tmp_path / "sim_time.mcap"
    n = node(mode="realtime", use_sim_time=True, record=str(rec))
    clock = n.get_clock()
    try:
        time.sleep(0.05)
        n.on_tick()
        assert n.solver.t == 0.0  # no /clock yet
        clock.set_ros_time_override(Time(seconds=1000.0))
        n.on_tick()
        assert n.solver.t == 0.0
        clock.set_ros_time_override(Time(seconds=1000.25))
        time.sleep(0.05)  # wall time passes: it does not count
        n.on_tick()
        assert n.solver.t == 0.25
    finally:
        n.close()
        n.destroy_node()
    states = read_recording(rec).topics["joint_states"]
    assert states[-1][0] == to_ns(1000.25) and states[-1][1].header.stamp.sec == 1000
    # a factor set while the run waits for /clock is taken as it is (it made the first tick integrate clock × factor)
    n = node(mode="realtime", use_sim_time=True)
    try:
        n.get_clock().set_ros_time_override(Time(seconds=1000.0))
        n.set_parameters([Parameter("real_time_factor", value=2.0)])
        n.on_tick()
        n.get_clock().set_ros_time_override(Time(seconds=1000.25))
        n.on_tick()
        assert n.solver.t == 0.5
    finally:
        n.close()
        n.destroy_node()


@pytest.mark.parametrize("value, words", [("rate_hz:=500", "parameter rate_hz"), ("rate_hz:=0.0", "from 1 to 10000"),
                                          ("record:={tmp}", "parameter record: cannot write"),
                                          ("world_frame:=/map", "parameter world_frame: expected a TF frame name")])
def test_a_bad_parameter_is_one_line_naming_it(tmp_path, value, words):
    """An integer for a floating-point parameter, a value outside its range or a recording path that is a directory:
    one line on stderr and exit 2, as a missing scene (they were tracebacks, exit 1)."""
    r = subprocess.run([sys.executable, "-m", "grapefmu_ros", "--ros-args", "-p", value.format(tmp=tmp_path)],
                       env=ENV, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert words in r.stderr and "Traceback" not in r.stderr
    assert [line for line in r.stderr.splitlines() if line.startswith("grapefmu_ros: error:")]


@pytest.mark.parametrize("args, words", [(["-p", "use_sim_time:=maybe"], "use_sim_time"),
                                         (["--params-file", "/nonexistent/params.yaml"], "ROS arguments")])
def test_a_bad_ros_argument_is_one_line(args, words):
    """rclpy's own parameter (use_sim_time) of the wrong type, and a parameters file that cannot be read, were
    tracebacks with exit 1 (found by an audit)."""
    r = subprocess.run([sys.executable, "-m", "grapefmu_ros", "--ros-args", *args], env=ENV, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert any(line.startswith("grapefmu_ros: error:") and words in line for line in r.stderr.splitlines()), r.stderr


def test_diagnostics_warn_of_berries_pressed_past_any_contact_law(ros, tmp_path):
    """A controller that drives the gripper down through the crate floor drags the berries into it: /diagnostics
    turns WARN and names the berry, its depth and the bound, 0.2 of its radius (results/trust.py, the rule a run's
    warnings use), where before it said "ok" throughout. Hanging, it says "ok". Lifted out again before the next
    diagnostics, the berries were still that deep at the states published in between: WARN names the deepest, with
    its time (diagnostics that judged the state when sent gave the next warning, "bruising impacts"); the next
    diagnostics give that."""
    from grapefmu.scenefile.toml_out import dumps

    from .conftest import dual
    floor = {"name": "floor", "point": [0.0, 0.0, -0.05], "normal": [0.0, 0.0, 1.0], "law": "hunt-crossley",
             "stiffness": 2e4, "restitution": 0.3}
    path = tmp_path / "floor.toml"
    path.write_text(dumps(dual(angles=(0.0, 0.0), obstacles=[floor])))
    n = node(mode="lockstep", scene=str(path))
    said = []
    emit = n.emit
    n.emit = lambda topic, m, ns: (said.append(m.status[0]) if topic == "/diagnostics" else None, emit(topic, m, ns))
    try:
        n.on_diagnostics()
        for k in range(13):  # 20 m/s² down for 0.12 s: 0.14 m down, the berries' bottoms 43.5 mm below the hinges
            n.on_accel(serialize(msgs.accel(to_ns(0.01 * k), (0.0, 0.0, -20.0, 0.0, 0.0, 0.0))[1]))
        n.on_diagnostics()
        depth = float(n.solver.observe().penetration[0].max())
        for k in range(13, 31):  # 60 m/s² up for 0.1 s, then held: 0.22 m up by 0.3 s, out of the floor
            n.on_accel(serialize(msgs.accel(to_ns(0.01 * k), (0.0, 0.0, 60.0 if k < 23 else 0.0, 0.0, 0.0, 0.0))[1]))
        out = float(n.solver.observe().penetration[0].max())
        n.on_diagnostics()
        n.on_diagnostics()
    finally:
        n.close()
        n.destroy_node()
    assert said[0].level == 0 and said[0].message == "ok"
    deepest = [float(kv.value) for s in said for kv in s.values if kv.key == "deepest_overlap_of_radius"]
    assert deepest[0] == 0.0 and deepest[1] == pytest.approx(depth / 0.0135, rel=1e-3)  # the berries' radius
    assert said[1].level == 1 and "inside obstacle 'floor'" in said[1].message, said[1].message
    assert f"was {depth * 1e3:.3g} mm inside" in said[1].message and "beyond 2.7 mm (0.2 of the berry radius)" in \
        said[1].message and depth > 0.05
    assert out == 0.0 and said[2].level == 1 and "inside obstacle 'floor'" in said[2].message, said[2].message
    when = float(said[2].message.split(" at t = ")[1].split(" s")[0])
    named = float(said[2].message.split(" was ")[1].split(" mm")[0]) * 1e-3
    assert deepest[2] == pytest.approx(named / 0.0135, rel=3e-3) and deepest[3] == 0.0  # named to 3 digits
    assert 0.12 < when < 0.3, said[2].message  # while it was lifted, before the diagnostics
    assert said[3].message == "bruising impacts"  # the next: the drop into the floor bruised them, nothing is deep


def test_a_stamp_the_node_cannot_take_does_not_lock_out_the_inputs_after_it(ros):
    """Lockstep: an input stamped 1e6 s, or with the wall clock's 1.7e9 s, is rejected as a stamp beyond the longest
    step (it was refused as a step whose 2.5e8 solver steps a hinge too stiff would need, which named the hinge, not
    the stamp); the valid inputs after it used to be rejected as going back before it, and the node stayed stuck
    until a reset. Real time: an input stamped an hour ahead was taken, and every correctly stamped one after it
    rejected while the stale acceleration was held."""
    import types

    n = node(mode="lockstep")
    said = []
    n.get_logger = lambda: types.SimpleNamespace(warning=lambda m, **_: said.append(m), error=said.append)
    try:
        for t in (0.01, 0.02, 0.03):
            accel(n, t, 1.0)
        accel(n, 1e6, 2.0)
        accel(n, 1.7e9, 2.0)
        assert n.rejected == 2 and n.failures == 0 and n.solver.t == 0.03
        assert len(said) == 1 and "lockstep stamps are simulated time from 0 s (a wall-clock stamp?)" in said[0], said
        for t in (0.04, 0.05):
            accel(n, t, 3.0)
        assert n.solver.t == 0.05 and n.rejected == 2 and n.accel[0] == 3.0
    finally:
        n.close()
        n.destroy_node()
    n = node(mode="realtime")
    try:
        now = n.get_clock().now().nanoseconds * 1e-9
        accel(n, now + 3600.0, 2.0)
        assert n.rejected == 1 and n.accel[0] == 0.0
        accel(n, now + 0.001, 3.0)
        assert n.rejected == 1 and n.accel[0] == 3.0
    finally:
        n.close()
        n.destroy_node()


def test_real_time_goes_on_when_the_clock_goes_back(ros):
    """Under use_sim_time a /clock that restarts (a simulator reset) or is replayed goes back; the node used to wait,
    publishing nothing and saying nothing, until the clock passed its old reading (hours after a reset). It now
    goes on from where it is at the new clock, logs it and says it in /diagnostics (WARN)."""
    n = node(mode="realtime", use_sim_time=True)
    clock = n.get_clock()
    diags = []
    n.emit = lambda topic, m, ns: diags.append(m) if topic == "/diagnostics" else None
    try:
        for t in (1000.0, 1000.5):
            clock.set_ros_time_override(Time(seconds=t))
            n.on_tick()
        assert n.solver.t == 0.5
        for t in (500.0, 500.25):  # back: the run goes on from 0.5 s
            clock.set_ros_time_override(Time(seconds=t))
            n.on_tick()
        assert n.solver.t == 0.75 and n.clock_jumps == 1
        n.on_diagnostics()
        status = diags[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert status.level == 1 and "clock went back" in status.message and values["clock_jumps_back"] == "1"
        n.on_diagnostics()  # said once
        assert diags[-1].status[0].level == 0
    finally:
        n.close()
        n.destroy_node()


def test_a_burst_of_lockstep_inputs_is_answered_in_full(ros):
    """A controller that streams its inputs without waiting for each answer: the node's input queue kept the last 100
    of a burst, dropped the rest without a word, and two runs of the same inputs ended apart. Here 600 inputs
    published at once (reliably) into a node that is not spinning yet must all be answered, in order."""
    import rclpy.executors
    from geometry_msgs.msg import AccelStamped
    from sensor_msgs.msg import JointState

    from .test_ros_node import QOS

    n = node(mode="lockstep")
    ctl = rclpy.create_node("burst_controller", namespace="/grape_cluster")
    answered = []
    ctl.create_subscription(JointState, "joint_states", lambda m: answered.append(m.header.stamp.nanosec), QOS)
    pub = ctl.create_publisher(AccelStamped, "rachis/accel", QOS)
    executor = rclpy.executors.SingleThreadedExecutor()
    try:
        for x in (n, ctl):
            executor.add_node(x)
        deadline = time.monotonic() + 20
        while (pub.get_subscription_count() == 0 or n.count_publishers("/grape_cluster/rachis/accel") == 0) \
                and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for k in range(1, 601):
            m = AccelStamped()
            m.header.stamp.nanosec, m.header.frame_id, m.accel.linear.x = k * 1_000_000, "world", float(k % 7 - 3)
            pub.publish(m)
        while n.solver.t < 0.6 and time.monotonic() < deadline + 60:
            executor.spin_once(timeout_sec=0.05)
        assert n.solver.t == 0.6 and n.rejected == 0
        for _ in range(40):
            executor.spin_once(timeout_sec=0.02)
        assert sorted(set(answered))[-600:] == [k * 1_000_000 for k in range(1, 601)]
    finally:
        executor.shutdown()
        for x in (n, ctl):
            x.destroy_node()


def test_the_fixed_frame_is_the_robots(ros):
    """REP-105: a robot's fixed frame may be map or odom. `world` was written into the node: inputs in the robot's
    fixed frame were rejected and the rachis could not hang from it. With world_frame := odom the inputs are taken
    in odom (and no longer in world), and the rachis' transform, the markers and the applied inputs are in odom."""
    n = node(mode="lockstep", world_frame="odom", marker_rate_hz=1000.0)
    said = []
    n.emit = lambda topic, m, ns: said.append((topic, m))
    try:
        for t, frame in ((0.01, "odom"), (0.02, "world"), (0.03, "")):
            n.on_accel(serialize(msgs.accel(to_ns(t), (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), frame=frame)[1]))
        assert n.solver.t == 0.03 and n.rejected == 1
        tf = [tr for topic, m in said if topic == "/tf" for tr in m.transforms]
        assert tf and {tr.header.frame_id for tr in tf if tr.child_frame_id == "grape_cluster/rachis"} == {"odom"}
        assert "world" not in {tr.header.frame_id for tr in tf}
        assert {m.header.frame_id for topic, m in said if topic == "rachis/accel_applied"} == {"odom"}
        assert {mk.header.frame_id for topic, m in said if topic == "markers" for mk in m.markers} == {"odom"}
    finally:
        n.close()
        n.destroy_node()


def test_each_reason_for_a_rejection_is_logged_once_a_second(ros):
    """Rejections were throttled to one line a second whatever their reason, so a flood of NaN inputs hid a
    too-large acceleration behind it (found by an audit). Each reason now has its own line once a second, naming
    the values (the NaN's too); all are counted."""
    import types

    n = node(mode="lockstep")
    said = []
    n.get_logger = lambda: types.SimpleNamespace(warning=lambda m, **_: said.append(m), error=said.append)
    try:
        for t, ax in ((0.01, float("nan")), (0.02, float("nan")), (0.03, 5e3), (0.04, float("nan")), (0.05, 6e3)):
            accel(n, t, ax)
        assert n.rejected == 5 and len(said) == 2, said
        assert "values must be finite, got (a, α) = (nan, 0.0, 0.0, 0.0, 0.0, 0.0)" in said[0]
        assert "linear acceleration |a| = 5000 m/s² above max_accel" in said[1]
    finally:
        n.close()
        n.destroy_node()


def _scene_file(tmp_path, yaw: float) -> str:
    path = tmp_path / f"yaw_{yaw:g}.toml"
    path.write_text(one_planar_berry(yaw))
    return str(path)


@pytest.mark.parametrize("topic", ["rachis/pose", "rachis/twist"])
def test_a_planar_scene_turned_about_z_follows_a_turn_about_its_y_axis(ros, tmp_path, topic):
    """A planar scene started with a yaw turns about its y axis n = (−sin yaw, cos yaw, 0). A gripper that turns about
    n (ω rising to 0.3 rad/s, then steady) on rachis/pose, or on rachis/twist as a robot gives it (its body rate
    turned into the world, R(t) (0, ω, 0)), had its samples rejected once it turned steadily: the second difference
    of the poses (the first of the twists) is α = 0 up to rounding, 1e-13 rad/s² that is all across n, so the node
    said the gripper turned about another axis and stopped (lockstep t stuck at 0.6 s of 2 s, 140 poses rejected).
    Gravity is along z, so the same berry in a scene without the yaw, turned about the world's y axis, is the
    reference: it must swing exactly alike."""
    from scipy.spatial.transform import Rotation

    runs = []
    for yaw in (0.0, 0.5):
        n = node(mode="lockstep", scene=_scene_file(tmp_path, yaw), pose_filter_hz=200.0)
        start = Rotation.from_euler("z", yaw)
        axis = start.apply([0.0, 1.0, 0.0])
        turned, angles = 0.0, []
        try:
            for k in range(201):
                t, w = 0.01 * k, min(0.5 * 0.01 * k, 0.3)
                turned += w * 0.01
                pose = Rotation.from_rotvec(turned * axis) * start
                if topic == "rachis/pose":
                    q = pose.as_quat()
                    n.on_pose(serialize(msg("geometry_msgs/msg/PoseStamped", header=header(to_ns(t), "world"),
                                            pose={"position": {"x": 0.0, "y": 0.0, "z": 0.0},
                                                  "orientation": dict(zip("xyzw", q.tolist()))})))
                else:
                    n.on_twist(serialize(msg("geometry_msgs/msg/TwistStamped", header=header(to_ns(t), "world"),
                                             twist={"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                                                    "angular": dict(zip("xyz", pose.apply([0.0, w, 0.0]).tolist()))})))
                angles.append(n.solver.angles[0])
            assert n.rejected == 0 and n.solver.t == 2.0, (n.rejected, n.solver.t)
            runs.append(np.array(angles))
        finally:
            n.close()
            n.destroy_node()
    assert np.abs(runs[0]).max() > 0.01  # the turn swings the berry
    np.testing.assert_allclose(runs[1], runs[0], rtol=0, atol=1e-9)


def test_real_time_input_times_out_to_zero_acceleration(ros, tmp_path):
    """A controller that falls silent: its last acceleration used to act for ever (the rachis sped on without
    bound). After input_timeout on the node's clock the held acceleration drops to zero at the simulated time the
    timeout ran out, and the rachis coasts: 2 m/s² accepted at clock 1000 s then silence, at 1001 s it has moved
    ½·2·0.5² + (2·0.5)·0.5 = 0.75 m at 1 m/s, where without the timeout it has moved 1 m. The states are a
    Solver.advance loop's over the same intervals bit for bit, and replay --check reproduces the recording."""
    from grapefmu import Solver
    moved = {}
    for timeout in (0.5, 0.0):
        rec = tmp_path / f"timeout{timeout}.mcap"
        n = node(mode="realtime", use_sim_time=True, input_timeout=timeout, record=str(rec))
        diags = []
        emit = n.emit
        n.emit = lambda topic, m, ns: diags.append(m) if topic == "/diagnostics" else emit(topic, m, ns)
        clock = n.get_clock()
        try:
            clock.set_ros_time_override(Time(seconds=1000.0))
            n.on_tick()
            accel(n, 1000.0, 2.0)
            for t in (1000.2, 1001.0):
                clock.set_ros_time_override(Time(seconds=t))
                n.on_tick()
            assert n.solver.t == 1.0
            snap = n.solver.snapshot()
            moved[timeout] = float(snap.base_displacement[0, 0])
            n.on_diagnostics()
            values = {kv.key: kv.value for kv in diags[-1].status[0].values}
            if timeout:
                assert n.accel == (0.0,) * 6 and n.timeouts == 1 and values["inputs_timed_out"] == "1"
                assert diags[-1].status[0].level == 1 and "input timed out" in diags[-1].status[0].message
                s = Solver(n.scene, driven=True)
                for dt, a in ((0.2, 2.0), (0.3, 2.0), (0.5, 0.0)):
                    s.advance(dt, (a, 0.0, 0.0, 0.0, 0.0, 0.0))
                np.testing.assert_array_equal(n.solver.angles, s.angles)
                accel(n, 1001.0, 1.0)  # an input re-arms it
                assert n.accel[0] == 1.0 and n.timeouts == 1
            else:
                assert n.accel[0] == 2.0 and n.timeouts == 0 and values["inputs_timed_out"] == "0"
        finally:
            n.close()
            n.destroy_node()
        assert check(rec).max_deviation == 0.0
    assert moved[0.5] == pytest.approx(0.75, rel=1e-9) and moved[0.0] == pytest.approx(1.0, rel=1e-9)


def test_poses_after_a_timeout_are_not_differenced_against_those_before(ros):
    """A gripper at rest whose poses stop for 2 s and come back 0.5 m away (moved while its publisher was down):
    the second difference across the silence was a spurious acceleration; after the timeout the poses start afresh
    and the rachis, at rest, stays so. (The timeout is set while the node runs, as `ros2 param set` would.)"""
    n = node(mode="realtime", use_sim_time=True, input_timeout=0.0)
    clock = n.get_clock()
    try:
        n.set_parameters([Parameter("input_timeout", value=0.5)])
        for t, z in [(1000.0, 0.0), (1000.01, 0.0), (1000.02, 0.0), (1002.0, 0.5), (1002.01, 0.5), (1002.02, 0.5)]:
            clock.set_ros_time_override(Time(seconds=t))
            n.on_tick()
            pose(n, t, z)
        assert n.timeouts == 1 and n.rejected == 0 and n.accel == (0.0,) * 6
        np.testing.assert_array_equal(n._motion_acc, np.zeros(6))
    finally:
        n.close()
        n.destroy_node()
