"""The simulator node: `python -m grapefmu_ros --ros-args -p scene:=SCENE.toml [-p mode:=lockstep] ...`

Real-time mode: a timer at `rate_hz` integrates exactly the simulated time that should have passed by
the wall clock (scaled by `real_time_factor`), so a late tick integrates a longer interval and the run
never drifts. Lockstep mode: each input message advances the simulation to its stamp with the previous
input held, then holds the new one; the node publishes `/clock` for `use_sim_time`.

Inputs give the gripper's full motion in the world frame: `rachis/accel` its linear and angular acceleration,
`rachis/twist` its velocities (differentiated; the angular velocity is also set at the start of the next
interval), `rachis/pose` or a TF frame its pose (differentiated twice). Every interval integrated is recorded
as `rachis/accel_applied` (stamp = interval end), and the angular velocity an input set at its start as
`rachis/twist_applied`: what `grapefmu replay --check` needs to reproduce the run exactly."""
from __future__ import annotations

import collections
import math
import re
import time

import numpy as np
import rclpy
import rclpy.executors
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from scipy.spatial.transform import Rotation
from std_srvs.srv import SetBool, Trigger

from grapefmu import GrapefmuError, Solver, load_scene
from grapefmu.model.model import off_axis
from grapefmu.scenefile import default_scene_path
from grapefmu.model.excitation import MAX_ACCEL, MAX_ANGULAR_ACCEL, MAX_ANGULAR_VELOCITY
from grapefmu.solver.warmup import notice
from grapefmu.solver.solver import LONGEST_STEP
from grapefmu.recording import frames, messages as msgs
from grapefmu.recording.stamps import seconds, stamp_seconds, to_ns
from grapefmu.recording.typestore import deserialize, serialize
from grapefmu.results.trust import overlap_of_radius, overlap_words, pressed_too_deep

from .interfaces import message_class
from .qos import INPUT_QOS, STATE_QOS, TOPIC_QOS
from .recorder import McapRecorder, metadata

#: (name, default, description, (low, high) or None, read-only): declared by the node, listed by --help
PARAMETERS = [
    ("scene", str(default_scene_path()), "Scene TOML (structure: read-only)", None, True),
    ("mode", "realtime", "realtime (wall-clock locked timer) or lockstep (advance to each input stamp)", None, True),
    ("rate_hz", 1000.0, "Real-time mode: simulation and joint_states rate, Hz", (1, 10000), True),
    ("real_time_factor", 1.0, "Simulated seconds per wall second in real-time mode", (0.01, 100), False),
    ("input_timeout", 0.5, "Real-time mode: after this long without an accepted input (s, the node's clock) the "
     "held acceleration drops to zero, so the rachis coasts on at its velocity, and motion inputs are differenced "
     "afresh (0: hold the last input for ever)", (0, 3600), False),
    ("max_accel", MAX_ACCEL, "Inputs whose linear acceleration exceeds this magnitude (m/s²) are rejected (at most "
     "the solver's own bound)", (0, MAX_ACCEL), False),
    ("max_angular_accel", MAX_ANGULAR_ACCEL, "Inputs whose angular acceleration exceeds this magnitude (rad/s²) are "
     "rejected (at most the solver's own bound)", (0, MAX_ANGULAR_ACCEL), False),
    ("marker_rate_hz", 30.0, "MarkerArray rate, Hz (0: none)", (0, 1000), False),
    ("tf_rate_hz", 100.0, "/tf rate, Hz (TF listeners interpolate between transforms)", (1, 10000), False),
    ("pose_filter_hz", 20.0, "Low-pass cutoff for accelerations differentiated from rachis/pose, rachis/twist or "
     "the gripper's TF frame, Hz", (0.1, 1000),
     False),
    ("record", "", "MCAP file to record every topic to ('' for none)", None, True),
    ("gripper_frame", "", "TF frame of the gripper holding the rachis, read on /tf as the transform world_frame → "
     "it, rotation included ('' for none: inputs come on rachis/accel, rachis/pose or rachis/twist)", None, True),
    ("world_frame", msgs.WORLD, "The fixed frame (REP-105: world, map or odom) the rachis moves in and the inputs "
     "are given in; the node's own frames hang from it", None, True),
]


#: rad: a pose input this far from the simulated rachis' orientation is warned about
ORIENTATION_WARNING = 0.1
#: a number in a message (a value, a stamp), left out of the reason a rejection is throttled by
_NUMBER = re.compile(r"[-+]?(?:\d[\d.]*(?:e[-+]?\d+)?|nan|inf)")
#: s: in real time, an input stamped further ahead of the node's clock is rejected: taken, it would make every input
#: stamped right afterwards look older than it and be rejected (clocks of a robot's computers agree far closer)
FUTURE_STAMP = 1.0


def _difference(a: np.ndarray, b: np.ndarray, order: int) -> np.ndarray:
    """b − a of two motion samples: velocities (order 1) subtract; poses (order 2: position, quaternion x, y, z, w)
    give the displacement and the rotation vector of the turn from a to b in the world frame (R_b R_aᵀ)."""
    if order == 1:
        return b - a
    turn = Rotation.from_quat(b[3:]) * Rotation.from_quat(a[3:]).inv()
    return np.concatenate([b[:3] - a[:3], turn.as_rotvec()])


def usage() -> str:
    lines = ["usage: python -m grapefmu_ros [--help] --ros-args [-p NAME:=VALUE ...] [-r __ns:=/NAMESPACE]", "",
             "The grapefmu simulator as a ROS 2 node: berries on hinged twigs that swing and collide while the",
             "gripper moves the rachis (topics, frames and time: docs/ros.md). Ctrl-C or SIGTERM stop it and",
             f"finish its recording. Namespace: {msgs.NAMESPACE}.", "", "options: (ROS parameters, -p NAME:=VALUE)"]
    for name, default, description, bounds, read_only in PARAMETERS:
        extra = (f", {bounds[0]:g} to {bounds[1]:g}" if bounds else "") + (", read-only" if read_only else "")
        lines.append(f"  {name:<18} {description} (default: {default!r}{extra})")
    return "\n".join(lines)


def _allowed(name: str) -> str:
    """What a parameter accepts, as an error states it."""
    default, bounds = next((d, b) for n, d, _, b, _ in PARAMETERS if n == name)
    kind = "a floating-point number (write 500.0, not 500)" if isinstance(default, float) else "a string"
    return kind + (f" from {bounds[0]:g} to {bounds[1]:g}" if bounds else "")


def _range(lo, hi):
    return [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]


def _planar_why(axis, frame: str, got: str) -> str:
    """Why a planar scene rejects a turn about another axis than `axis` (its y axis, in `frame`): `got` says what."""
    return (f"the scene has planar berries, which swing in the rachis' x–z plane: the rachis may turn only about its "
            f"y axis ({', '.join(f'{c:.6g}' for c in axis)} in {frame}); {got} (a scene of spherical berries follows "
            "any rotation)")


class SimulatorNode(Node):
    def __init__(self, **kwargs):
        kwargs.setdefault("namespace", msgs.NAMESPACE)  # `-r __ns:=/other` moves everything, frames included
        super().__init__("grapefmu", **kwargs)
        for name, default, description, bounds, read_only in PARAMETERS:
            try:
                self.declare_parameter(name, default, ParameterDescriptor(
                    description=description, read_only=read_only,
                    floating_point_range=_range(*bounds) if bounds else []))
            except ParameterException as e:  # a -p value of the wrong type or outside its range: main's one line
                raise GrapefmuError(f"parameter {name}: expected {_allowed(name)}; {e}") from None
        gp = lambda n: self.get_parameter(n).value  # noqa: E731
        self.mode = gp("mode")
        if self.mode not in ("realtime", "lockstep"):
            raise GrapefmuError(f"parameter mode: expected 'realtime' or 'lockstep', got {self.mode!r}")
        self.rate = gp("rate_hz")
        self.scene = load_scene(gp("scene"))
        m = self.scene.model
        ns = self.get_namespace()
        self.prefix = "" if ns == "/" else ns.strip("/") + "/"  # of every TF frame
        self.world = gp("world_frame")
        if not (self.world and self.world[0] != "/" and all(c.isalnum() or c in "_/" for c in self.world)) or (
                self.prefix and self.world.startswith(self.prefix)):
            raise GrapefmuError(f"parameter world_frame: expected a TF frame name of letters, digits, _ and / (not "
                                f"starting with / nor with the node's own {self.prefix!r}), got {self.world!r}")
        self.recorder = McapRecorder(gp("record"), metadata(self.scene, self.mode, self.rate, ns, Solver(
            self.scene, driven=True).integrator)) if gp("record") else None
        topics = ["joint_states", "pedicel_tension", *msgs.wrench_topics(m), "contacts", "summary", "collision_events",
                  "markers", "/diagnostics", "rachis/accel_applied", "rachis/twist_applied", "sim_time", "/tf",
                  "/tf_static", "robot_description"] + (["/clock"] if self.mode == "lockstep" else [])
        # no per-publisher QoS-event handlers: rclpy's executor walks every one of them on every spin, which cost
        # more than the simulation at 1 kHz (incompatible subscribers still get the middleware's own warning)
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self.pubs = {t: self.create_publisher(message_class(msgs.topic_type(t)), t, TOPIC_QOS.get(t, STATE_QOS),
                                              event_callbacks=quiet) for t in topics}
        self.full_names = {t: pub.topic_name for t, pub in self.pubs.items()}  # as recordings name them
        for topic, handler in (("rachis/accel", self.on_accel), ("rachis/pose", self.on_pose),
                               ("rachis/twist", self.on_twist)):
            self.create_subscription(message_class(msgs.topic_type(topic)), topic, handler, INPUT_QOS[self.mode],
                                     raw=True)
        self.gripper_frame = gp("gripper_frame")
        self.rachis_frame = frames.rachis(self.prefix)
        #: a planar scene's rachis turns about its y axis only: this world direction (None: spherical berries only)
        self.plane_normal = m.plane_normal(self.scene.excitation)
        if self.gripper_frame:
            self.create_subscription(message_class(msgs.topic_type("/tf")), "/tf", self.on_tf, INPUT_QOS[self.mode],
                                     raw=True)
        self.create_service(Trigger, "reset", self.on_reset)
        self.create_service(SetBool, "pause", self.on_pause)
        self.paused = False
        self.rejected = 0
        self._said: dict[str, float] = {}  # a rejection's reason -> when it was last logged (_reject)
        self.overruns = 0
        self.clock_jumps = self._jumps_seen = 0  # times the node's clock went back (on_tick); of them, said
        self.tick_costs = collections.deque(maxlen=1000)  # s: the last ticks' wall time (diagnostics' percentiles)
        self.failures = 0
        self.deepest = None  # (pair, δ, bound, t) pressed deepest past its bound since the last diagnostics
        self.deepest_of_radius = 0.0  # the deepest overlap over its pair's radius since the last diagnostics
        self.real_time_factor = gp("real_time_factor")
        self.input_timeout = to_ns(gp("input_timeout"))  # ns, 0: none
        self.input_clock: int | None = None  # ns, the node's clock when the input held was accepted (real time)
        self.timeouts = self._timeouts_seen = 0  # times input_timeout zeroed the held acceleration; of them, said
        self.add_post_set_parameters_callback(self._on_parameters_set)
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
        """Real time runs on the node's ROS clock (wall time, or /clock under use_sim_time): simulated time sim0 at
        clock0; the stamps' origin makes the newest state's stamp the clock's time. A clock at 0 (use_sim_time
        before the first /clock) is not yet running: the first tick that reads it running restarts from there."""
        self.clock0, self.sim0 = self.get_clock().now().nanoseconds, self.solver.t
        self.last_clock = self.clock0
        if self.input_clock is not None:  # the timeout counts the clock running from here (a resume, a jump back)
            self.input_clock = self.clock0
        self.origin = 0 if self.mode == "lockstep" else self.clock0 - to_ns(self.solver.t)

    def _sim_target(self, clock_ns: int) -> float:
        """The simulated time the clock's reading asks for (whole nanoseconds, so an interval can be recomputed bit
        for bit from the recorded stamps)."""
        return seconds(to_ns(self.sim0 + seconds(clock_ns - self.clock0) * self.real_time_factor))

    def _on_parameters_set(self, params) -> None:
        """real_time_factor: the run goes on from where the old factor has brought it, at the new one (a run still
        waiting for /clock just takes it); use_sim_time: the clock changes, so the run restarts from where it is."""
        for p in params:
            if p.name == "real_time_factor":
                now = self.get_clock().now().nanoseconds
                if self.mode == "realtime" and self.clock0 != 0:
                    self.sim0, self.clock0 = self._sim_target(now), now
                self.real_time_factor = p.value
            elif p.name == "input_timeout":
                self.input_timeout = to_ns(p.value)
            elif p.name == "use_sim_time" and self.mode == "realtime":
                self._restart_clock()

    def _reset_sim(self):
        self.solver = Solver(self.scene, driven=True)  # whatever the scene does, inputs may move and turn the rachis
        self.accel = (0.0,) * 6  # held: ACCEL_COMPONENTS, world frame
        self.omega = None        # ω (world, rad/s) an input gave, set at the start of the next interval
        self.last_stamp = -math.inf
        self.accel_stamp = -math.inf  # of the last rachis/accel: its acceleration wins over a motion input's there
        self.orientation_offset = math.nan  # rad, between the last pose input's orientation and the rachis'
        self._restart_clock()
        self.last_tick = None
        self._last = {}  # rate parameter -> simulated time its topic was last published
        self._motion = {2: [], 1: []}  # the last poses (order 2) and velocities (order 1) received
        self._motion_acc = np.zeros(6)
        self.input_clock = None
        stamp = self._stamp(self.solver.t)
        for topic, m in msgs.tf_static(self.scene.model, stamp, self.prefix):
            self.emit(topic, m, stamp)
        # a (re)start: sim_time 0, which no interval ends at, tells replay --check to start its solver again
        self.emit("sim_time", msgs.clock(0)[1], stamp)
        self.publish_state()

    def advance(self, dt: float) -> bool:
        """Integrate dt with the held input; publish states and the impacts that ended."""
        if dt <= 0:
            return True
        try:
            self.solver.advance(dt, self.accel, self.omega)
        except GrapefmuError as e:
            self.failures += 1
            self.get_logger().error(f"step of {dt:.6g} s refused: {e}", throttle_duration_sec=1.0)
            return False
        ns = self._stamp(self.solver.t)
        self.emit(*msgs.accel(ns, self.accel, "rachis/accel_applied", self.world), ns)
        if self.omega is not None:  # set at this interval's start, once
            self.emit(*msgs.twist(ns, self.omega, "rachis/twist_applied", self.world), ns)
            self.omega = None
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
        if self.solver.touching:  # the deepest pair since the last diagnostics, which say so (on_diagnostics)
            pen = snap.observation.penetration
            self.deepest_of_radius = max(self.deepest_of_radius, overlap_of_radius(self.scene.model, pen))
            hit = pressed_too_deep(self.scene.model, pen)
            if hit and (self.deepest is None or hit[2] - hit[3] > self.deepest[1] - self.deepest[2]):
                self.deepest = (*hit[1:], t)
        summary = msgs.summary_table(snap)
        for topic, m in msgs.state_messages(self.scene.model, snap, 0, ns, summary, markers=markers_due, tf=tf_due,
                                            prefix=self.prefix, world=self.world):
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
    def _reject(self, what: str, why: str) -> None:
        """Count and log a rejected input: at most once a second for each topic and reason (the numbers in it aside),
        so that one reason's flood does not hide another's (rclpy's throttle is one per call site: this one)."""
        self.rejected += 1
        key = f"{what}: {_NUMBER.sub('#', why)}"
        now = time.monotonic()
        if now - self._said.get(key, -math.inf) >= 1.0:
            if len(self._said) > 100:
                self._said.clear()
            self._said[key] = now
            self.get_logger().warning(f"{what}: {why}; rejected")

    def _frame(self, frame_id: str, what: str, allowed: tuple[str, ...]) -> str | None:
        """"world": the fixed frame world_frame (also for an empty frame_id), or "rachis": the rachis frame, if
        `allowed`; None (rejected) otherwise."""
        frame = {"": "world", self.world: "world", self.rachis_frame: "rachis"}.get(frame_id)
        if frame not in allowed:
            known = " or ".join(repr(f) for f in ((self.world, self.rachis_frame) if "rachis" in allowed
                                                 else (self.world,)))
            self._reject(what, f"frame_id {frame_id!r}: expected {known} (the node looks up no other frame)")
            return None
        return frame

    def _valid(self, a, omega, what, frame="world") -> bool:
        """Finite, within max_accel and max_angular_accel (magnitudes, so in any frame), ω within the solver's
        bound, and in a planar scene no turn about any axis but the rachis' y axis (the model's own test)."""
        lin, ang = math.hypot(*a[:3]), math.hypot(*a[3:])
        w = (0.0, 0.0, 0.0) if omega is None else omega
        bound, angular_bound = self.get_parameter("max_accel").value, self.get_parameter("max_angular_accel").value
        axis = self.plane_normal if self.plane_normal is None or frame == "world" else (0.0, 1.0, 0.0)
        if not all(math.isfinite(v) for v in (*a, *w)):
            why = f"values must be finite, got (a, α) = {tuple(a)}" + ("" if omega is None else f", ω = {tuple(w)}")
        elif lin > bound:
            why = f"linear acceleration |a| = {lin:.6g} m/s² above max_accel = {bound:g}"
        elif ang > angular_bound:
            why = f"angular acceleration |α| = {ang:.6g} rad/s² above max_angular_accel = {angular_bound:g}"
        elif math.hypot(*w) > MAX_ANGULAR_VELOCITY:
            why = f"angular velocity |ω| = {math.hypot(*w):.6g} rad/s above {MAX_ANGULAR_VELOCITY:g}"
        elif axis is not None and (any(a[3:]) or any(w)) and (off_axis(a[3:], axis) or off_axis(w, axis)):
            why = _planar_why(axis, frame, f"got α = {tuple(a[3:])} rad/s², ω = {tuple(w)} rad/s")
        else:
            return True
        self._reject(what, why)
        return False

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
        frame = self._frame(msg.header.frame_id, "rachis/accel", ("world", "rachis"))
        if frame:
            a = msg.accel
            self._input(t_in, (a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y, a.angular.z),
                        "rachis/accel", frame=frame, explicit=True)

    def _input(self, t_in, a, what, omega=None, frame="world", explicit=False) -> bool:
        """Advance to t_in (lockstep) with the input held so far, then hold `a` (ACCEL_COMPONENTS) and set ω at the
        next interval's start (if given). An input in the rachis frame is turned into the world frame with the
        rachis' orientation when it starts to act; the world-frame value is held, and recorded. An explicit
        acceleration (rachis/accel) wins over one derived from a motion input with the same stamp."""
        if not self._valid(a, omega, what, frame):
            return False
        if t_in < self.last_stamp:
            self._reject(what, f"stamp {t_in:.9f} s goes back before {self.last_stamp:.9f} s")
            return False
        now = seconds(self.get_clock().now().nanoseconds) if self.mode == "realtime" else math.inf
        if t_in > now + FUTURE_STAMP:
            self._reject(what, f"stamp {t_in:.9f} s is more than {FUTURE_STAMP:g} s ahead of the node's clock "
                               f"({now:.9f} s): a clock set wrong, or another time base (use_sim_time)")
            return False
        if self.mode == "lockstep" and not self.paused:
            if t_in - self.solver.t > LONGEST_STEP:
                self._reject(what, f"stamp {t_in:.9f} s is {t_in - self.solver.t:.6g} s after the simulated time "
                                   f"{self.solver.t:.9f} s, more than the longest step ({LONGEST_STEP:g} s): lockstep "
                                   "stamps are simulated time from 0 s (a wall-clock stamp?)")
                return False
            if t_in > self.solver.t:
                if not self.advance(t_in - self.solver.t):
                    return False  # refused: the stamp is not taken, so the next input may still come before it
            else:
                self.publish_state()  # an input at the current time still gets its answer
        self.last_stamp = t_in
        if self.mode == "realtime":
            self.input_clock = self.get_clock().now().nanoseconds
        if frame == "rachis":
            turn = Rotation.from_quat(self.solver.snapshot().base_orientation[0])
            a = (*turn.apply(a[:3]), *turn.apply(a[3:]))
        if explicit or t_in != self.accel_stamp:
            self.accel = tuple(float(v) for v in a)
        if explicit:
            self.accel_stamp = t_in
        if omega is not None:
            self.omega = tuple(float(v) for v in omega)
        return True

    def on_pose(self, data: bytes):
        msg, t = self._received("rachis/pose", data)
        if self._frame(msg.header.frame_id, "rachis/pose", ("world",)):
            p, q = msg.pose.position, msg.pose.orientation
            self._pose_input(t, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), "rachis/pose")

    def on_twist(self, data: bytes):
        msg, t = self._received("rachis/twist", data)
        if self._frame(msg.header.frame_id, "rachis/twist", ("world",)):
            v, w = msg.twist.linear, msg.twist.angular
            self._motion_input(t, np.array([v.x, v.y, v.z, w.x, w.y, w.z]), 1, "rachis/twist")

    def on_tf(self, data: bytes):
        """The gripper frame's pose in `world`, from another node's /tf (this node's own frames are skipped)."""
        msg = deserialize(data, msgs.topic_type("/tf"))
        for tr in msg.transforms:
            if tr.child_frame_id != self.gripper_frame:
                continue
            what = f"/tf {self.gripper_frame}"
            if tr.header.frame_id != self.world:
                self._reject(what, f"given in {tr.header.frame_id!r}; the node reads the transform {self.world} → "
                                   f"{self.gripper_frame} only (it composes no TF chain: publish that transform, or "
                                   f"the gripper's pose on rachis/pose)")
                continue
            t = stamp_seconds(tr.header.stamp.sec, tr.header.stamp.nanosec)
            if self.recorder:
                self.recorder.write("/tf", msg.__msgtype__, data, to_ns(max(t, 0.0)))
            p, q = tr.transform.translation, tr.transform.rotation
            self._pose_input(t, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), what)

    def _pose_input(self, t: float, position, quaternion, what: str):
        """A pose (world): differentiated twice; then how far the rachis' orientation is from it."""
        norm = math.sqrt(sum(c * c for c in quaternion))
        if not abs(norm - 1.0) < 1e-3:
            self._reject(what, f"orientation {tuple(quaternion)} is not a unit quaternion (norm {norm:.6g})")
            return
        q = np.array(quaternion) / norm
        if not self._motion_input(t, np.array([*position, *q]), 2, what):
            return
        here = self.solver.snapshot().base_orientation[0]
        self.orientation_offset = 2.0 * math.acos(min(1.0, abs(float(np.dot(q, here / np.linalg.norm(here))))))
        if self.orientation_offset > ORIENTATION_WARNING:
            self.get_logger().warning(
                f"{what}: the simulated rachis is turned {self.orientation_offset:.3g} rad from the gripper's pose "
                f"at {t:.6f} s, and gravity acts on the berries at the simulated orientation: start the scene at the "
                "gripper's orientation (excitation.orientation), or raise pose_filter_hz if the filter's lag is the "
                "cause",
                throttle_duration_sec=5.0)

    def _motion_input(self, t: float, x: np.ndarray, order: int, what: str) -> bool:
        """(a, α) from the gripper's poses (order 2: x = position, quaternion; second difference) or velocities
        (order 1: x = linear, angular velocity; first difference, and ω set at the next interval's start), then a
        first-order low-pass at pose_filter_hz. Turns are differenced as rotation vectors in the world frame.
        False if the input was rejected."""
        if not np.all(np.isfinite(x)):
            names = "position, orientation" if order == 2 else "linear, angular"
            self._reject(what, f"values must be finite, got {names} = {tuple(x.tolist())}")
            return False
        seen = (self._motion[order] + [(t, x)])[-(order + 1):]
        omega = tuple(x[3:]) if order == 1 else None
        if len(seen) <= order:  # no difference yet: advance to the stamp holding what is held (and set ω)
            acc = self._motion_acc
            held = self.accel
        else:
            times = [s[0] for s in seen]
            if not all(a < b for a, b in zip(times, times[1:])):
                self._reject(what, f"stamp {t:.9f} s: stamps must increase (last {times[-2]:.9f} s)")
                return False
            rates = [_difference(a, b, order) / (tb - ta) for (ta, a), (tb, b) in zip(seen, seen[1:])]
            n = self.plane_normal
            turn = next((w for w in (tuple(r[3:].tolist()) for r in rates) if off_axis(w, n)), None) if (
                n is not None and order == 2) else None  # a twist's ω is judged as sent (_valid)
            if turn is not None:
                self._reject(what, _planar_why(n, "world", f"the poses turn at ω = {turn} rad/s"))
                return False
            raw = rates[0] if order == 1 else (rates[1] - rates[0]) / (0.5 * (times[2] - times[0]))
            alpha = 1.0 - math.exp(-2 * math.pi * self.get_parameter("pose_filter_hz").value * (times[-1] - times[-2]))
            acc = self._motion_acc + alpha * (raw - self._motion_acc)
            if n is not None:  # turns about n alone (checked above, or ω by _valid): keep α along n, not its rounding
                axis = np.array(n)
                acc[3:] = float(np.dot(acc[3:], axis)) * axis
            held = tuple(acc)
        if not self._input(t, held, what, omega=omega):
            return False  # a rejected sample leaves no trace: not in the differences, not in the filter
        self._motion[order], self._motion_acc = seen, acc
        return True

    # --- real time ------------------------------------------------------------------------------
    def on_tick(self):
        now = time.monotonic()
        if self.last_tick is not None and now - self.last_tick > 1.5 / self.rate:
            self.overruns += 1
        self.last_tick = now
        if self.paused:
            return
        clock = self.get_clock().now().nanoseconds
        if self.clock0 == 0:  # use_sim_time and no /clock yet when the run (re)started
            if clock == 0:
                return
            self._restart_clock()
        elif clock < self.last_clock:  # /clock restarted or replayed, or the system clock set back
            self.clock_jumps += 1
            self.get_logger().warning(
                f"the clock went back from {seconds(self.last_clock):.9f} s to {seconds(clock):.9f} s: real time goes "
                f"on from simulated t = {self.solver.t:.6f} s at the new clock (call reset to start the scene again)",
                throttle_duration_sec=1.0)
            self._restart_clock()
        self.last_clock = clock
        timeout = self.input_timeout
        if self.input_clock is not None and timeout > 0 and clock - self.input_clock > timeout:
            self._time_out(self.input_clock + timeout)
        self.advance(self._sim_target(clock) - self.solver.t)
        self.tick_costs.append(time.monotonic() - now)

    def _time_out(self, clock_ns: int) -> None:
        """No input for input_timeout: integrate up to the simulated time of clock_ns (when it ran out) with the input
        held, then hold zero acceleration and forget the motion inputs (a pose after the silence is not differenced
        against one before it)."""
        self.advance(self._sim_target(clock_ns) - self.solver.t)
        self.accel, self.input_clock = (0.0,) * 6, None
        self._motion, self._motion_acc = {2: [], 1: []}, np.zeros(6)
        self.timeouts += 1
        self.get_logger().warning(
            f"no input for input_timeout = {seconds(self.input_timeout):g} s: zero acceleration held "
            f"from simulated t = {self.solver.t:.6f} s (the rachis coasts on at its velocity)",
            throttle_duration_sec=5.0)

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
        snap = self.solver.snapshot()
        summary = dict(zip(msgs.SUMMARY_FIELDS[1:], msgs.summary_table(snap)[0, 1:].tolist()))
        detach, bruising = bool(summary["detachment_risk"]), int(summary["bruising_impacts"])
        deep, self.deepest = self.deepest, None  # past any contact law at a published state since the last ones
        of_radius, self.deepest_of_radius = self.deepest_of_radius, 0.0
        values = {
            "sim_time_s": f"{t:.6f}", "real_time_factor": f"{(t - sim_prev) / max(now - wall_prev, 1e-9):.4f}",
            "cpu_percent": f"{100 * (cpu - cpu_prev) / max(now - wall_prev, 1e-9):.1f}", "overruns": self.overruns,
            "clock_jumps_back": self.clock_jumps, "inputs_timed_out": self.timeouts,
            "rejected_inputs": self.rejected, "refused_steps": self.failures, **summary,
            **({} if math.isnan(self.orientation_offset) else
               {"gripper_orientation_offset_rad": f"{self.orientation_offset:.6f}"}),
            "zeno_guard_activations": self.solver.stats["zeno_guard_activations"], "paused": self.paused,
            "deepest_overlap_of_radius": f"{of_radius:.4f}",
            "mode": self.mode,
            **({f"tick_cost_ms_{k}": f"{1e3 * v:.3f}" for k, v in
                zip(("p50", "p99", "max"), np.percentile(self.tick_costs, [50, 99, 100]))} if self.tick_costs else {}),
        }
        jumped, self._jumps_seen = self.clock_jumps > self._jumps_seen, self.clock_jumps
        timed_out, self._timeouts_seen = self.timeouts > self._timeouts_seen, self.timeouts
        warn = detach or bruising or self.rejected or self.failures or deep or jumped or timed_out
        level = 2 if self.failures else (1 if warn else 0)
        msg = ("steps refused (the log says why)" if self.failures else
               overlap_words(self.scene.model, *deep) if deep else "detachment risk" if detach else
               "bruising impacts" if bruising else "inputs rejected" if self.rejected else
               "the clock went back (the log says from when to when)" if jumped else
               "input timed out: zero acceleration held (input_timeout)" if timed_out else "ok")
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
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as e:  # a --params-file that cannot be read or parsed, a malformed --ros-args
        print(f"grapefmu_ros: error: ROS arguments: {str(e).splitlines()[0]}", file=sys.stderr)
        raise SystemExit(2) from None
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
    except (GrapefmuError, ParameterException) as e:  # ours, or rclpy's own (use_sim_time:=maybe)
        print(f"grapefmu_ros: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
