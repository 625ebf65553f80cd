"""The simulator node: `python -m grapefmu_ros --ros-args -p scene:=SCENE.toml [-p mode:=lockstep] ...`

Real-time mode: a timer at `rate_hz` integrates exactly the simulated time that should have passed by
the wall clock (scaled by `real_time_factor`), so a late tick integrates a longer interval and the run
never drifts. Lockstep mode: each `rachis/accel` message advances the simulation to its stamp with the
previous acceleration held, then holds the new one; the node publishes `/clock` for `use_sim_time`.
Either way every interval integrated is recorded as `rachis/accel_applied` (stamp = interval end), which
is what `grapefmu replay --check` needs to reproduce the run exactly."""
from __future__ import annotations

import collections
import math
import time

import numpy as np
import rclpy
import rclpy.executors
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import SetBool, Trigger

from grapefmu import GrapefmuError, Solver, load_scene
from grapefmu.scenefile import default_scene_path
from grapefmu.solver.solver import MAX_ACCEL
from grapefmu.solver.warmup import notice
from grapefmu.recording import messages as msgs
from grapefmu.recording.stamps import seconds, stamp_seconds, to_ns
from grapefmu.recording.typestore import deserialize, serialize

from .interfaces import message_class
from .recorder import McapRecorder, metadata

EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: latched: a late subscriber (RViz, robot_state_publisher, a tf2 buffer) still gets them
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: inputs: a best-effort subscription matches both reliable and best-effort (sensor-data) publishers
INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
#: QoS per topic (default STATE_QOS)
TOPIC_QOS = {"collision_events": EVENTS_QOS, "markers": 10, "/diagnostics": 10, "/clock": 10, "/tf": 100,
             "/tf_static": LATCHED_QOS, "robot_description": LATCHED_QOS}


#: (name, default, description, (low, high) or None, read-only): declared by the node, listed by --help
PARAMETERS = [
    ("scene", str(default_scene_path()), "Scene TOML (structure: read-only)", None, True),
    ("mode", "realtime", "realtime (wall-clock locked timer) or lockstep (advance to each input stamp)", None, True),
    ("rate_hz", 1000.0, "Real-time mode: simulation and joint_states rate, Hz", (1, 10000), True),
    ("real_time_factor", 1.0, "Simulated seconds per wall second in real-time mode", (0.01, 100), False),
    ("max_accel", MAX_ACCEL, "Inputs above this acceleration (m/s²) are rejected (at most the solver's own bound)",
     (0, MAX_ACCEL), False),
    ("marker_rate_hz", 30.0, "MarkerArray rate, Hz (0: none)", (0, 1000), False),
    ("tf_rate_hz", 100.0, "/tf rate, Hz (TF listeners interpolate between transforms)", (1, 10000), False),
    ("pose_filter_hz", 20.0, "Low-pass cutoff for accelerations differentiated from rachis/pose, rachis/twist or "
     "the gripper's TF frame, Hz", (0.1, 1000),
     False),
    ("record", "", "MCAP file to record every topic to ('' for none)", None, True),
    ("gripper_frame", "", "TF frame of the gripper holding the rachis, looked up on /tf against `world` ('' for "
     "none: inputs come on rachis/accel, rachis/pose or rachis/twist)", None, True),
]


def usage() -> str:
    lines = ["usage: python -m grapefmu_ros [--help] --ros-args [-p NAME:=VALUE ...] [-r __ns:=/NAMESPACE]", "",
             "The grapefmu simulator as a ROS 2 node: berries on hinged twigs that swing and collide while the",
             "gripper moves the rachis (topics, frames and time: docs/ros.md). Ctrl-C or SIGTERM stop it and",
             f"finish its recording. Namespace: {msgs.NAMESPACE}.", "", "options: (ROS parameters, -p NAME:=VALUE)"]
    for name, default, description, bounds, read_only in PARAMETERS:
        extra = (f", {bounds[0]:g} to {bounds[1]:g}" if bounds else "") + (", read-only" if read_only else "")
        lines.append(f"  {name:<18} {description} (default: {default!r}{extra})")
    return "\n".join(lines)


def _range(lo, hi):
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


class SimulatorNode(Node):
    def __init__(self, **kwargs):
        kwargs.setdefault("namespace", msgs.NAMESPACE)  # `-r __ns:=/other` moves everything, frames included
        super().__init__("grapefmu", **kwargs)
        for name, default, description, bounds, read_only in PARAMETERS:
            self.declare_parameter(name, default, ParameterDescriptor(
                description=description, read_only=read_only,
                floating_point_range=_range(*bounds) if bounds else []))
        gp = lambda n: self.get_parameter(n).value  # noqa: E731
        self.mode = gp("mode")
        if self.mode not in ("realtime", "lockstep"):
            raise GrapefmuError(f"parameter mode: expected 'realtime' or 'lockstep', got {self.mode!r}")
        self.rate = gp("rate_hz")
        self.scene = load_scene(gp("scene"))
        m = self.scene.model
        ns = self.get_namespace()
        self.prefix = "" if ns == "/" else ns.strip("/") + "/"  # of every TF frame
        self.recorder = McapRecorder(gp("record"), metadata(self.scene, self.mode, self.rate, ns)) \
            if gp("record") else None
        topics = ["joint_states", "pedicel_tension", *msgs.wrench_topics(m), "contacts", "summary", "collision_events",
                  "markers", "/diagnostics", "rachis/accel_applied", "sim_time", "/tf", "/tf_static",
                  "robot_description"] + (["/clock"] if self.mode == "lockstep" else [])
        # no per-publisher QoS-event handlers: rclpy's executor walks every one of them on every spin, which cost
        # more than the simulation at 1 kHz (incompatible subscribers still get the middleware's own warning)
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.pubs = {t: self.create_publisher(message_class(msgs.topic_type(t)), t, TOPIC_QOS.get(t, STATE_QOS),
                                              event_callbacks=quiet) for t in topics}
        self.full_names = {t: pub.topic_name for t, pub in self.pubs.items()}  # as recordings name them
        for topic, handler in (("rachis/accel", self.on_accel), ("rachis/pose", self.on_pose),
                               ("rachis/twist", self.on_twist)):
            self.create_subscription(message_class(msgs.topic_type(topic)), topic, handler, INPUT_QOS, raw=True)
        self.gripper_frame = gp("gripper_frame")
        if self.gripper_frame:
            self.create_subscription(message_class(msgs.topic_type("/tf")), "/tf", self.on_tf, INPUT_QOS, raw=True)
        self.create_service(Trigger, "reset", self.on_reset)
        self.create_service(SetBool, "pause", self.on_pause)
        self.paused = False
        self.rejected = 0
        self.overruns = 0
        self.tick_costs = collections.deque(maxlen=1000)  # s: the last ticks' wall time (diagnostics' percentiles)
        self.failures = 0
        self._reset_sim()
        if self.mode == "realtime":
            self.create_timer(1.0 / self.rate, self.on_tick)
        self.create_timer(1.0, self.on_diagnostics)
        self._diag_last = (time.monotonic(), time.process_time(), 0.0)

    # --- simulation ---------------------------------------------------------------------------------
    def _stamp(self, t: float) -> int:
        """The ROS time of simulated time t, ns: the node's clock in real-time mode (the origin is set at every
        start and resume), the simulated time itself in lockstep mode (which publishes it on /clock)."""
        return self.origin + to_ns(t)

    def _restart_clock(self):
        self.wall0, self.sim0 = time.monotonic(), self.solver.t
        self.origin = 0 if self.mode == "lockstep" else self.get_clock().now().nanoseconds - to_ns(self.solver.t)

    def _reset_sim(self):
        self.solver = Solver(self.scene)
        self.accel = (0.0, 0.0)
        self.last_stamp = -math.inf
        self._restart_clock()
        self.last_tick = None
        self._last = {}  # rate parameter -> simulated time its topic was last published
        self._motion = {2: [], 1: []}  # the last poses (order 2) and velocities (order 1) received
        self._motion_acc = np.zeros(2)
        stamp = self._stamp(self.solver.t)
        for topic, m in msgs.tf_static(self.scene.model, stamp, self.prefix):
            self.emit(topic, m, stamp)
        self.publish_state()

    def advance(self, dt: float) -> bool:
        """Integrate dt with the held input; publish states and the impacts that ended."""
        if dt <= 0:
            return True
        try:
            self.solver.advance(dt, self.accel)
        except GrapefmuError as e:
            self.failures += 1
            self.get_logger().error(f"step of {dt:.6g} s refused: {e}", throttle_duration_sec=1.0)
            return False
        ns = self._stamp(self.solver.t)
        self.emit(*msgs.accel(ns, self.accel, "rachis/accel_applied", self.prefix), ns)
        self.emit("sim_time", msgs.clock(to_ns(self.solver.t))[1], ns)  # what replay --check re-simulates
        self.publish_state()
        for ns, topic, m in msgs.impact_messages(self.scene.model, self.solver.take_impacts(), self.origin,
                                                 self.prefix):
            self.emit(topic, m, ns)
        return True

    def publish_state(self):
        """Every state topic (messages.py) from the solver's snapshot; markers at marker_rate_hz."""
        t = self.solver.t
        ns = self._stamp(t)
        markers_due, tf_due = self._due("marker_rate_hz", t), self._due("tf_rate_hz", t)
        snap = self.solver.snapshot()
        summary = msgs.summary_table(snap)
        for topic, m in msgs.state_messages(self.scene.model, snap, 0, ns, summary, markers=markers_due, tf=tf_due,
                                            prefix=self.prefix):
            self.emit(topic, m, ns)
        if "/clock" in self.pubs:
            self.emit(*msgs.clock(ns), ns)

    def _due(self, rate_parameter: str, t: float) -> bool:
        """Whether the topic published at `rate_parameter` (Hz, 0: never) is due at simulated time t."""
        rate = self.get_parameter(rate_parameter).value
        if rate > 0 and t - self._last.get(rate_parameter, -math.inf) >= 1.0 / rate - 1e-12:
            self._last[rate_parameter] = t
            return True
        return False

    def emit(self, topic: str, message, ns: int):
        """Serialize once through the typestore; publish and record the same bytes."""
        data = serialize(message)
        self.pubs[topic].publish(data)
        if self.recorder:
            self.recorder.write(self.full_names[topic], message.__msgtype__, data, ns)

    # --- inputs ---------------------------------------------------------------------------------
    def _valid(self, ax, az, what) -> bool:
        bound = self.get_parameter("max_accel").value
        if not (math.isfinite(ax) and math.isfinite(az) and abs(ax) <= bound and abs(az) <= bound):
            self.rejected += 1
            self.get_logger().warning(f"{what}: acceleration ({ax!r}, {az!r}) m/s² rejected: must be finite and "
                                      f"within ±{bound:g} m/s²", throttle_duration_sec=1.0)
            return False
        return True

    def _received(self, topic: str, data: bytes):
        """Decode an input through the typestore and record it (re-serialized: the one type system)."""
        msg = deserialize(data, msgs.topic_type(topic))
        t = stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec)
        if self.recorder:
            self.recorder.write(msgs.absolute(topic, self.get_namespace()), msg.__msgtype__, serialize(msg),
                                to_ns(max(t, 0.0)))
        return msg, t

    def on_accel(self, data: bytes):
        msg, t_in = self._received("rachis/accel", data)
        self._input(msg.accel.linear.x, msg.accel.linear.z, t_in, "rachis/accel")

    def _input(self, ax, az, t_in, what):
        if not self._valid(ax, az, what):
            return
        if t_in < self.last_stamp:
            self.rejected += 1
            self.get_logger().warning(f"{what}: stamp {t_in:.9f} s goes back before {self.last_stamp:.9f} s; rejected",
                                      throttle_duration_sec=1.0)
            return
        self.last_stamp = t_in
        if self.mode == "lockstep" and not self.paused:
            if t_in > self.solver.t:
                if not self.advance(t_in - self.solver.t):
                    return
            else:
                self.publish_state()  # an input at the current time still gets its answer
        self.accel = (float(ax), float(az))

    def on_pose(self, data: bytes):
        msg, t = self._received("rachis/pose", data)
        self._motion_input(t, np.array([msg.pose.position.x, msg.pose.position.z]), 2, "rachis/pose")

    def on_twist(self, data: bytes):
        msg, t = self._received("rachis/twist", data)
        self._motion_input(t, np.array([msg.twist.linear.x, msg.twist.linear.z]), 1, "rachis/twist")

    def on_tf(self, data: bytes):
        """The gripper frame's pose in `world`, from another node's /tf (this node's own frames are skipped)."""
        msg = deserialize(data, msgs.topic_type("/tf"))
        for tr in msg.transforms:
            if tr.child_frame_id == self.gripper_frame and tr.header.frame_id == msgs.WORLD:
                t = stamp_seconds(tr.header.stamp.sec, tr.header.stamp.nanosec)
                if self.recorder:
                    self.recorder.write("/tf", msg.__msgtype__, data, to_ns(max(t, 0.0)))
                p = tr.transform.translation
                self._motion_input(t, np.array([p.x, p.z]), 2, f"/tf {self.gripper_frame}")

    def _motion_input(self, t: float, x: np.ndarray, order: int, what: str):
        """Acceleration from the gripper's positions (order 2: second difference) or velocities (order 1:
        first difference), then a first-order low-pass at pose_filter_hz."""
        if not np.all(np.isfinite(x)):
            self._valid(math.nan, math.nan, what)
            return
        seen = self._motion[order] = (self._motion[order] + [(t, x)])[-(order + 1):]
        if len(seen) <= order:
            return
        times = [s[0] for s in seen]
        if not all(a < b for a, b in zip(times, times[1:])):
            self._valid(math.nan, math.nan, f"{what} (stamps must increase)")
            return
        rates = [(b - a) / (tb - ta) for (ta, a), (tb, b) in zip(seen, seen[1:])]
        raw = rates[0] if order == 1 else (rates[1] - rates[0]) / (0.5 * (times[2] - times[0]))
        alpha = 1.0 - math.exp(-2 * math.pi * self.get_parameter("pose_filter_hz").value * (times[-1] - times[-2]))
        self._motion_acc += alpha * (raw - self._motion_acc)
        self._input(self._motion_acc[0], self._motion_acc[1], t, what)

    # --- real time ------------------------------------------------------------------------------
    def on_tick(self):
        now = time.monotonic()
        if self.last_tick is not None and now - self.last_tick > 1.5 / self.rate:
            self.overruns += 1
        self.last_tick = now
        if self.paused:
            return
        # whole nanoseconds, so the interval can be recomputed bit for bit from the recorded stamps
        target = seconds(to_ns(self.sim0 + (now - self.wall0) * self.get_parameter("real_time_factor").value))
        self.advance(target - self.solver.t)
        self.tick_costs.append(time.monotonic() - now)

    # --- services -------------------------------------------------------------------------------
    def on_reset(self, _req, resp):
        self._reset_sim()
        resp.success = True
        resp.message = "simulation reset to the scene's initial state at t = 0"
        return resp

    def on_pause(self, req, resp):
        if req.data == self.paused:
            resp.success, resp.message = True, f"already {'paused' if self.paused else 'running'}"
            return resp
        self.paused = req.data
        if not self.paused:  # resume: the wall clock restarts from the current simulated time
            self._restart_clock()
        resp.success, resp.message = True, "paused" if self.paused else "running"
        return resp

    def on_diagnostics(self):
        now, cpu, sim_prev = time.monotonic(), time.process_time(), self._diag_last[2]
        wall_prev, cpu_prev = self._diag_last[0], self._diag_last[1]
        t = self.solver.t
        self._diag_last = (now, cpu, t)
        summary = dict(zip(msgs.SUMMARY_FIELDS[1:], msgs.summary_table(self.solver.snapshot())[0, 1:].tolist()))
        detach, bruising = bool(summary["detachment_risk"]), int(summary["bruising_impacts"])
        values = {
            "sim_time_s": f"{t:.6f}", "real_time_factor": f"{(t - sim_prev) / max(now - wall_prev, 1e-9):.4f}",
            "cpu_percent": f"{100 * (cpu - cpu_prev) / max(now - wall_prev, 1e-9):.1f}", "overruns": self.overruns,
            "rejected_inputs": self.rejected, "refused_steps": self.failures, **summary,
            "zeno_guard_activations": self.solver.stats["zeno_guard_activations"], "paused": self.paused,
            "mode": self.mode,
            **({f"tick_cost_ms_{k}": f"{1e3 * v:.3f}" for k, v in
                zip(("p50", "p99", "max"), np.percentile(self.tick_costs, [50, 99, 100]))} if self.tick_costs else {}),
        }
        warn = detach or bruising or self.rejected or self.failures
        level = 2 if self.failures else (1 if warn else 0)
        msg = "detachment risk" if detach else ("bruising impacts" if bruising else
                                                ("inputs rejected" if self.rejected else "ok"))
        self.emit(*msgs.diagnostics(self._stamp(t), level, msg, values), self._stamp(t))

    def close(self):
        if self.recorder:
            self.recorder.close()


def main(args=None):
    """Run until SIGINT or SIGTERM, then finish the recording before the context goes away."""
    import signal
    import sys

    from rclpy.signals import SignalHandlerOptions

    argv = sys.argv[1:] if args is None else list(args)
    ours = argv[:argv.index("--ros-args")] if "--ros-args" in argv else argv  # the rest is ROS's
    if any(a in ("-h", "--help") for a in ours):
        print(usage())
        return
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _: stop.append(signal.Signals(signum).name))
    node = None
    try:
        notice()  # one line before the core's first compile on this machine
        node = SimulatorNode()
        rec = node.get_parameter("record").value
        print(f"grapefmu_ros: simulating '{node.scene.name}' in {node.mode} mode under {node.get_namespace()}"
              f"{f', recording to {rec}' if rec else ''}; Ctrl-C stops", file=sys.stderr, flush=True)
        executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        while not stop:
            executor.spin_once(timeout_sec=0.05)
        print(f"grapefmu_ros: stopped by {stop[0]} at simulated t = {node.solver.t:.3f} s"
              f"{f'; {rec} is complete' if rec else ''}", file=sys.stderr, flush=True)
    except GrapefmuError as e:
        print(f"grapefmu_ros: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
