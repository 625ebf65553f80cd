"""Example harvesting controller: a jerk-limited pick, carry and place of the cluster, published as
`rachis/accel` to a simulator node in lockstep mode.

open_loop: the nominal profile. gentle: the same path, slowed down (time-scaled) while the contact
force or the pedicel tension is near its threshold: progress runs at a rate r in [r_min, 1] and the
commanded acceleration is r² a_nominal(s), so the gripper still ends where the move ends.

`python -m grapefmu_ros.controller --ros-args -p mode:=gentle`"""
from __future__ import annotations

import argparse
import signal
import sys

import numpy as np
import rclpy
import rclpy.executors
from geometry_msgs.msg import AccelStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from grapefmu_msgs.msg import CollisionEvent, PedicelTension, Summary

from grapefmu.model.excitation import pick_and_place
from grapefmu.physics.excitation import accel
from grapefmu.recording import messages as msgs
from grapefmu.recording.messages import NAMESPACE
from grapefmu.recording.stamps import to_ns
from grapefmu.recording.typestore import serialize

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
MOVES = [((0.0, 0.10), 0.4), ((0.30, 0.0), 0.6), ((0.0, -0.10), 0.4)]


def _t(msg_stamp) -> float:
    return msg_stamp.sec + msg_stamp.nanosec * 1e-9


class HarvestController(Node):
    def __init__(self):
        super().__init__("harvest_controller", namespace=NAMESPACE)  # the simulator node's default namespace
        d = ParameterDescriptor
        self.declare_parameter("mode", "open_loop", d(description="open_loop or gentle", read_only=True))
        self.declare_parameter("dt", 1e-3, d(description="command period, s", read_only=True))
        self.declare_parameter("contact_force_limit", 0.5, d(description="gentle: slow down above this contact force, N"))
        self.declare_parameter("tension_limit", 0.25, d(description="gentle: slow down above this pedicel tension, N"))
        self.declare_parameter("min_rate", 0.3, d(description="gentle: slowest progress rate (fraction of nominal)"))
        self.declare_parameter("settle", 0.5, d(description="time to keep commanding zero after the move, s"))
        self.mode = self.get_parameter("mode").value
        self.dt = self.get_parameter("dt").value
        self.profile = pick_and_place(MOVES, start=0.1)
        self.t_move_end = float(self.profile.arrays.table[-1, 0])
        self.pub = self.create_publisher(AccelStamped, "rachis/accel", QOS)
        self.create_subscription(PedicelTension, "pedicel_tension", self.on_tension, QOS)
        self.create_subscription(Clock, "/clock", self.on_clock, QOS)
        self.create_subscription(CollisionEvent, "collision_events", self.on_event,
                                 QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                                            reliability=ReliabilityPolicy.RELIABLE))
        self.create_subscription(Summary, "summary", self.on_summary, QOS)
        self.latest = {"tension": (None, 0.0), "clock": None, "force": (None, 0.0)}
        self.sent_t = None    # stamp of the last command sent
        self.s = 0.0          # progress along the nominal profile, s
        self.rate = 1.0
        self.next_t = 0.0     # stamp of the next command
        self.peak_force = 0.0
        self.peak_tension = 0.0
        self.collisions = 0
        self.done = False

    def on_tension(self, m):
        self.latest["tension"] = (_t(m.header.stamp), max(m.tension) if len(m.tension) else 0.0)
        self.try_command()

    def on_summary(self, m):
        """The node's summary: simulated time, the largest contact force right now, and the run's peaks (the node's
        booked peaks, refined between samples: the samples' largest would read up to 2 % low)."""
        self.latest["force"] = (m.time, m.max_contact_force)
        self.peak_force, self.peak_tension = m.peak_contact_force, m.peak_pedicel_tension
        self.try_command()

    def on_clock(self, m):
        self.latest["clock"] = _t(m.clock)
        self.try_command()

    def on_event(self, _m):
        self.collisions += 1

    def ready(self) -> bool:
        """The simulator has answered the last command: clock, tension and summary at its stamp."""
        tk = self.sent_t
        if tk is None or self.latest["clock"] is None or abs(self.latest["clock"] - tk) > 1e-9:
            return False
        if self.latest["tension"][0] is None or abs(self.latest["tension"][0] - tk) > 1e-9:
            return False
        tf = self.latest["force"][0]
        return tf is not None and abs(tf - tk) < 1e-9

    def try_command(self):
        if not self.done and self.ready():
            self.command()

    def command(self):
        t = self.next_t
        force = self.latest["force"][1]
        tension = self.latest["tension"][1]
        if self.mode == "gentle":
            lf, lt = self.get_parameter("contact_force_limit").value, self.get_parameter("tension_limit").value
            load = max(force / lf, tension / lt)
            target = 1.0 if load < 0.5 else max(self.get_parameter("min_rate").value, 1.0 - (load - 0.5))
            # fall fast, recover slowly: 20 ms and 200 ms time constants
            tau = 0.02 if target < self.rate else 0.2
            self.rate += (target - self.rate) * min(1.0, self.dt / tau)
        a = accel(self.profile, self.s) * self.rate**2 if self.s < self.t_move_end else np.zeros(6)
        self.pub.publish(serialize(msgs.accel(to_ns(t), a)[1]))  # world frame, the node's own message builder
        self.sent_t = t
        self.s += self.dt * (self.rate if self.mode == "gentle" else 1.0)
        self.next_t = round(t + self.dt, 9)
        if self.s >= self.t_move_end + self.get_parameter("settle").value:
            self.done = True

    def start(self, executor, stop=()) -> bool:
        """Wait for the simulator, then send the first command (stamp 0). False if stopped first (`stop`
        non-empty: SIGINT or SIGTERM arrived)."""
        while self.pub.get_subscription_count() == 0:
            if stop:
                return False
            executor.spin_once(timeout_sec=0.1)
        for _ in range(20):  # let the simulator's publishers match ours
            if stop:
                return False
            executor.spin_once(timeout_sec=0.05)
        self.command()
        return True


PROG = "python -m grapefmu_ros.controller"


def _parse(argv: list[str]) -> None:
    """--help (ROS arguments, after --ros-args, are rclpy's)."""
    from rclpy.utilities import remove_ros_args
    ap = argparse.ArgumentParser(
        prog=PROG, description="Example harvesting controller: a jerk-limited pick, carry and place of the cluster, "
        "sent as rachis/accel to a simulator node in lockstep mode (python -m grapefmu_ros --ros-args -p "
        "mode:=lockstep); prints one RESULT line when the move has ended.",
        epilog="ROS parameters (--ros-args -p NAME:=VALUE): mode open_loop | gentle (default open_loop), dt command "
               "period in s (default 0.001), contact_force_limit N (default 0.5), tension_limit N (default 0.25), "
               "min_rate (default 0.3), settle s (default 0.5). SIGINT or SIGTERM stops it at once.")
    ap.parse_args(remove_ros_args(argv)[1:])


def main(args=None):
    _parse(sys.argv if args is None else args)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = []
    signal.signal(signal.SIGINT, lambda signum, _: stop.append(signum))
    signal.signal(signal.SIGTERM, lambda signum, _: stop.append(signum))
    node = HarvestController()
    ex = rclpy.executors.SingleThreadedExecutor()
    ex.add_node(node)
    print(f"{PROG}: {node.mode}: waiting for a simulator node on rachis/accel", file=sys.stderr, flush=True)
    started = False
    try:
        started = node.start(ex, stop)
        while not stop and not node.done:
            ex.spin_once(timeout_sec=0.2)
        if node.done:
            for _ in range(10):  # collect the last events
                ex.spin_once(timeout_sec=0.05)
            print(f"RESULT mode={node.mode} peak_contact_force={node.peak_force:.6g} "
                  f"peak_pedicel_tension={node.peak_tension:.6g} collisions={node.collisions} "
                  f"move_time={node.next_t:.3f}", flush=True)
    finally:
        node.destroy_node()
        rclpy.shutdown()
    if not node.done:
        name = signal.Signals(stop[0]).name if stop else "a signal"
        where = f"at t = {node.next_t:.3f} s of the move" if started else "while waiting for a simulator node"
        print(f"{PROG}: stopped by {name} {where}; no result", file=sys.stderr, flush=True)
        return 128 + int(stop[0]) if stop else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
