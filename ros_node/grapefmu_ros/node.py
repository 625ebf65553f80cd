"""The simulator node: `python -m grapefmu_ros --ros-args -p scene:=SCENE.toml [-p mode:=lockstep] ...`

Real-time mode: a timer at `rate_hz` integrates exactly the simulated time that should have passed by
the wall clock (scaled by `real_time_factor`), so a late tick integrates a longer interval and the run
never drifts. Lockstep mode: each `rachis/accel` message advances the simulation to its stamp with the
previous acceleration held, then holds the new one; the node publishes `/clock` for `use_sim_time`.
Either way every interval integrated is recorded as `rachis/accel_applied` (stamp = interval end), which
is what `grapefmu replay --check` needs to reproduce the run exactly."""
from __future__ import annotations

import math
import time

import numpy as np
import rclpy
import rclpy.executors
from geometry_msgs.msg import AccelStamped, PoseStamped
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped

from grapefmu import GrapefmuError, Solver, load_scene
from grapefmu.cli import default_scene_path
from grapefmu.physics.dynamics import centres, observe
from grapefmu.recording import topics as T
from grapefmu.recording.stamps import seconds, stamp_seconds, to_ns
from grapefmu.solver import core

from . import messages as M
from .recorder import McapRecorder, metadata

EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)


def _range(lo, hi):
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


class SimulatorNode(Node):
    def __init__(self, **kwargs):
        super().__init__("grapefmu", **kwargs)
        ro = dict(read_only=True)
        self.declare_parameter("scene", str(default_scene_path()),
                               ParameterDescriptor(description="Scene TOML (structure: read-only)", **ro))
        self.declare_parameter("mode", "realtime", ParameterDescriptor(
            description="realtime (wall-clock locked timer) or lockstep (advance to each input stamp)", **ro))
        self.declare_parameter("rate_hz", 1000.0, ParameterDescriptor(
            description="Real-time mode: simulation and joint_states rate, Hz", floating_point_range=_range(1, 10000), **ro))
        self.declare_parameter("real_time_factor", 1.0, ParameterDescriptor(
            description="Simulated seconds per wall second in real-time mode", floating_point_range=_range(0.01, 100)))
        self.declare_parameter("max_accel", 100.0, ParameterDescriptor(
            description="Inputs above this acceleration (m/s²) are rejected", floating_point_range=_range(0, 1000)))
        self.declare_parameter("marker_rate_hz", 30.0, ParameterDescriptor(
            description="MarkerArray rate, Hz (0: none)", floating_point_range=_range(0, 1000)))
        self.declare_parameter("pose_filter_hz", 20.0, ParameterDescriptor(
            description="Low-pass cutoff for accelerations differentiated from rachis/pose, Hz",
            floating_point_range=_range(0.1, 1000)))
        self.declare_parameter("record", "", ParameterDescriptor(
            description="MCAP file to record every topic to ('' for none)", **ro))
        gp = lambda n: self.get_parameter(n).value  # noqa: E731
        self.mode = gp("mode")
        if self.mode not in ("realtime", "lockstep"):
            raise GrapefmuError(f"parameter mode: expected 'realtime' or 'lockstep', got {self.mode!r}")
        self.rate = gp("rate_hz")
        self.scene = load_scene(gp("scene"))
        m = self.scene.model
        self.names = m.names
        self.joints = m.dof_names  # joint_state() names them twig_<angle>
        self.pairs = [(p.i, p.j) for p in m.pairs]
        self.pair_topics = [f"contact/{m.pair_name(p)}/wrench" for p in range(len(m.pairs))] if T.per_pair_topics(m) else []
        self.recorder = McapRecorder(gp("record"), metadata(self.scene, self.mode, self.rate)) if gp("record") else None
        self.pub_js = self.create_publisher(JointState, "joint_states", STATE_QOS)
        self.pub_wrench = [self.create_publisher(WrenchStamped, t, STATE_QOS) for t in self.pair_topics]
        self.pub_contacts = self.create_publisher(Float64MultiArray, "contacts", STATE_QOS)
        self.pub_tension = self.create_publisher(JointState, "pedicel_tension", STATE_QOS)
        self.pub_summary = self.create_publisher(Float64MultiArray, "summary", STATE_QOS)
        self.pub_events = self.create_publisher(Float64MultiArray, "collision_events", EVENTS_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, "markers", 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.pub_applied = self.create_publisher(AccelStamped, "rachis/accel_applied", STATE_QOS)
        self.pub_clock = self.create_publisher(Clock, "/clock", 10) if self.mode == "lockstep" else None
        self.create_subscription(AccelStamped, "rachis/accel", self.on_accel, STATE_QOS)
        self.create_subscription(PoseStamped, "rachis/pose", self.on_pose, STATE_QOS)
        self.create_service(Trigger, "reset", self.on_reset)
        self.create_service(SetBool, "pause", self.on_pause)
        self.paused = False
        self.rejected = 0
        self.overruns = 0
        self.failures = 0
        self._reset_sim()
        if self.mode == "realtime":
            self.create_timer(1.0 / self.rate, self.on_tick)
        self.create_timer(1.0, self.on_diagnostics)
        self._diag_last = (time.monotonic(), time.process_time(), 0.0)

    # --- simulation ---------------------------------------------------------------------------------
    def _reset_sim(self):
        self.solver = Solver(self.scene)
        self.accel = (0.0, 0.0)
        self.last_stamp = -math.inf
        self.wall0 = time.monotonic()
        self.sim0 = 0.0
        self.last_tick = None
        self.collisions = 0
        self.bruising = 0
        self._last_marker = -math.inf
        self._pose = []
        self._pose_acc = np.zeros(2)
        m = self.scene.model
        self._fext = np.zeros((m.n_berries, 3))
        self._pos = np.zeros((m.n_berries, 3))
        self._obs = np.zeros(2 * m.n_dof + m.n_berries + 3 * len(m.pairs) + 3)
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
        t = self.solver.t
        applied = AccelStamped()
        applied.header.stamp = M.stamp(t)
        applied.header.frame_id = M.FRAME
        applied.accel.linear.x, applied.accel.linear.z = self.accel
        self.emit(self.pub_applied, "rachis/accel_applied", applied, t)
        self.publish_state()
        imp = self.solver.take_impacts()
        th = self.scene.thresholds
        for k in range(len(imp)):
            self.collisions += 1
            self.bruising += int(imp.peak_force[k] >= th.bruise_force or imp.dissipated[k] >= th.bruise_energy)
            self.emit(self.pub_events, "collision_events", M.impact_message(imp, k), float(imp.end[k]))
        return True

    def publish_state(self):
        s, t = self.solver, self.solver.t
        S = s.state
        b = s.M.berry
        observe(S.y, S.mode, S.v_onset, S.smooth, self.accel[0], self.accel[1], s.M, S.peak_force, S.peak_tension,
                self._fext, self._obs)
        model = self.scene.model
        n, d, npair = model.n_berries, model.n_dof, len(model.pairs)
        q, w = S.y[:d], S.y[d: 2 * d]
        effort = T.hinge_effort(model, q, w)
        self.emit(self.pub_js, "joint_states", M.joint_state(t, self.joints, q, w, effort), t)
        o = 2 * d + n
        tension = self._obs[2 * d: o]
        self.emit(self.pub_tension, "pedicel_tension", M.tension(t, self.names, tension), t)
        forces, pen, touching = self._obs[o: o + npair], self._obs[o + npair: o + 2 * npair], S.mode != 0
        rate = self.get_parameter("marker_rate_hz").value
        markers_due = rate > 0 and t - self._last_marker >= 1.0 / rate - 1e-12
        if self.pair_topics or markers_due:  # berry positions: only for wrench directions and markers
            base = S.y[s.layout.base]
            centres(S.y, s.M, self._pos)
            origin = np.array([base[0], 0.0, base[1]])
            berries = self._pos + origin
        for p, topic in enumerate(self.pair_topics):
            i, j = self.pairs[p]
            dv = berries[j] - berries[i]
            self.emit(self.pub_wrench[p], topic, M.wrench(t, forces[p] * dv / max(np.linalg.norm(dv), 1e-12)), t)
        self.emit(self.pub_contacts, "contacts", M.labelled(list(T.CONTACT_FIELDS), T.contact_values(forces, pen, touching),
                                                            rows=int(touching.sum())), t)
        peak_f, peak_t, dissipated = self._obs[o + 3 * npair: o + 3 * npair + 3]
        self.emit(self.pub_summary, "summary", M.labelled(list(T.SUMMARY_FIELDS), T.summary_values(
            t, forces, tension, peak_f, peak_t, dissipated, touching)), t)
        if markers_due:
            self._last_marker = t
            self.emit(self.pub_markers, "markers",
                      M.markers(t, origin, b[:, [3, 6, 7]] + origin, berries, b[:, 1], self.pairs, forces), t)
        if self.pub_clock is not None:
            self.emit(self.pub_clock, "/clock", Clock(clock=M.stamp(t)), t)

    def emit(self, pub, topic, msg, t):
        pub.publish(msg)
        if self.recorder:
            self.recorder.write(topic, msg, to_ns(t))

    # --- inputs ---------------------------------------------------------------------------------
    def _valid(self, ax, ay, what) -> bool:
        bound = self.get_parameter("max_accel").value
        if not (math.isfinite(ax) and math.isfinite(ay) and abs(ax) <= bound and abs(ay) <= bound):
            self.rejected += 1
            self.get_logger().warning(f"{what}: acceleration ({ax!r}, {ay!r}) m/s² rejected: must be finite and "
                                      f"within ±{bound:g} m/s²", throttle_duration_sec=1.0)
            return False
        return True

    def on_accel(self, msg: AccelStamped):
        t_in = stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec)
        if self.recorder:
            self.recorder.write("rachis/accel", msg, to_ns(max(t_in, 0.0)))
        self._input(msg.accel.linear.x, msg.accel.linear.z, t_in, "rachis/accel")

    def _input(self, ax, ay, t_in, what):
        if not self._valid(ax, ay, what):
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
        self.accel = (float(ax), float(ay))

    def on_pose(self, msg: PoseStamped):
        """Acceleration from poses: second difference, then a first-order low-pass at pose_filter_hz."""
        t = stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec)
        if self.recorder:
            self.recorder.write("rachis/pose", msg, to_ns(max(t, 0.0)))
        p = np.array([msg.pose.position.x, msg.pose.position.z])
        if not np.all(np.isfinite(p)):
            self._valid(math.nan, math.nan, "rachis/pose")
            return
        self._pose = (self._pose + [(t, p)])[-3:]
        if len(self._pose) < 3:
            return
        (t0, p0), (t1, p1), (t2, p2) = self._pose
        if not (t0 < t1 < t2):
            self._valid(math.nan, math.nan, "rachis/pose (stamps must increase)")
            return
        v1, v2 = (p1 - p0) / (t1 - t0), (p2 - p1) / (t2 - t1)
        raw = (v2 - v1) / (0.5 * (t2 - t0))
        alpha = 1.0 - math.exp(-2 * math.pi * self.get_parameter("pose_filter_hz").value * (t2 - t1))
        self._pose_acc += alpha * (raw - self._pose_acc)
        self._input(self._pose_acc[0], self._pose_acc[1], t, "rachis/pose")

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
            self.wall0, self.sim0 = time.monotonic(), self.solver.t
        resp.success, resp.message = True, "paused" if self.paused else "running"
        return resp

    def on_diagnostics(self):
        now, cpu, sim_prev = time.monotonic(), time.process_time(), self._diag_last[2]
        wall_prev, cpu_prev = self._diag_last[0], self._diag_last[1]
        t = self.solver.t
        self._diag_last = (now, cpu, t)
        S = self.solver.state
        th = self.scene.thresholds
        peak_t = float(S.peak_tension.max())
        detach = peak_t > th.detachment_force
        values = {
            "sim_time_s": f"{t:.6f}", "real_time_factor": f"{(t - sim_prev) / max(now - wall_prev, 1e-9):.4f}",
            "cpu_percent": f"{100 * (cpu - cpu_prev) / max(now - wall_prev, 1e-9):.1f}", "overruns": self.overruns,
            "rejected_inputs": self.rejected, "refused_steps": self.failures, "collision_count": self.collisions,
            "peak_contact_force_N": f"{float(S.peak_force.max()) if S.peak_force.size else 0.0:.6g}",
            "peak_pedicel_force_N": f"{peak_t:.6g}", "detachment_risk": detach, "bruising_impacts": self.bruising,
            "zeno_guard_activations": int(S.it[core.N_ZENO]), "paused": self.paused, "mode": self.mode,
        }
        warn = detach or self.bruising or self.rejected or self.failures
        level = 2 if self.failures else (1 if warn else 0)
        msg = "detachment risk" if detach else ("bruising impacts" if self.bruising else
                                                ("inputs rejected" if self.rejected else "ok"))
        self.emit(self.pub_diag, "/diagnostics", M.diagnostics(t, level, msg, values), t)

    def close(self):
        if self.recorder:
            self.recorder.close()


def main(args=None):
    """Run until SIGINT or SIGTERM, then finish the recording before the context goes away."""
    import signal
    import sys

    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    node = None
    try:
        node = SimulatorNode()
        executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        while not stop:
            executor.spin_once(timeout_sec=0.05)
    except GrapefmuError as e:
        print(f"grapefmu_ros: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
