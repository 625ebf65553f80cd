"""The ROS node's real-time mode (achieved rate, jitter, CPU at 1 kHz, with and without recording) and
lockstep throughput (simulated seconds per wall second with a controller answering every state).
Run: .venv/bin/python benchmarks/ros_node_rates.py"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

DOMAIN = str(random.randint(60, 90))  # ≤ 101: DDS ports stay out of the ephemeral range
os.environ.update({"ROS_DOMAIN_ID": DOMAIN, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import AccelStamped  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)


def start(mode, record=None, scene=None):
    args = [sys.executable, "-m", "grapefmu_ros", "--ros-args", "-p", f"mode:={mode}"]
    if record:
        args += ["-p", f"record:={record}"]
    if scene:
        args += ["-p", f"scene:={scene}"]
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def stop(p):
    p.send_signal(signal.SIGTERM)
    p.wait(timeout=30)


def realtime(node, record, seconds=6.0, scene=None):
    p = start("realtime", record, scene)
    arrivals, diags = [], []
    node.create_subscription(JointState, "joint_states", lambda m: arrivals.append(time.monotonic()), QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, QOS)
    end = time.monotonic() + seconds + 2.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.01)
    stop(p)
    a = np.array(arrivals)
    a = a[a > a[0] + 1.0]  # skip start-up
    gaps = np.diff(a) * 1e3
    last = {kv.key: kv.value for kv in diags[-1].status[0].values}
    return {"rate_hz": len(a) / (a[-1] - a[0]), "gap_ms_p50": np.percentile(gaps, 50),
            "gap_ms_p99": np.percentile(gaps, 99), "gap_ms_max": gaps.max(), "rtf": float(last["real_time_factor"]),
            "cpu": float(last["cpu_percent"]), "overruns": int(last["overruns"]),
            **{k: float(last[k]) for k in ("tick_cost_ms_p50", "tick_cost_ms_p99", "tick_cost_ms_max")}}


def lockstep(node, steps=2000, dt=1e-3):
    p = start("lockstep")
    pub = node.create_publisher(AccelStamped, "rachis/accel", QOS)
    got = []
    node.create_subscription(JointState, "joint_states", got.append, QOS)
    while pub.get_subscription_count() == 0 or node.count_publishers("joint_states") == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    for _ in range(20):
        rclpy.spin_once(node, timeout_sec=0.05)

    def send(k):
        m = AccelStamped()
        ns = k * int(dt * 1e9)
        m.header.stamp.sec, m.header.stamp.nanosec = ns // 10**9, ns % 10**9
        m.accel.linear.x = 3.0 * np.sin(k * 0.01)
        pub.publish(m)
    w = time.monotonic()
    for k in range(steps):
        n = len(got)
        send(k)
        while len(got) == n:
            rclpy.spin_once(node, timeout_sec=0.01)
    wall = time.monotonic() - w
    stop(p)
    return {"steps_per_s": steps / wall, "sim_s_per_wall_s": steps * dt / wall}


def main():
    rclpy.init()
    node = rclpy.create_node("bench", namespace="/grape_cluster")
    print("real-time mode, 1 kHz, 6 s (tick cost: the node's own wall time per tick, last 1000 ticks):")
    with tempfile.TemporaryDirectory() as d:
        subprocess.run([sys.executable, "-m", "grapefmu", "cluster", "--berries", "100", "--seed", "1", "-o",
                        f"{d}/cluster100.toml"], check=True, capture_output=True)
        for label, rec, scene in (("default scene", None, None), ("default, recording", f"{d}/r.mcap", None),
                                  ("100-berry cluster", None, f"{d}/cluster100.toml")):
            r = realtime(node, rec, scene=scene)
            print(f"  {label:<19} rate {r['rate_hz']:7.1f} Hz, joint_states gap p50 {r['gap_ms_p50']:.3f} ms, "
                  f"p99 {r['gap_ms_p99']:.3f} ms, max {r['gap_ms_max']:.2f} ms; tick cost p50 "
                  f"{r['tick_cost_ms_p50']:.3f} ms, p99 {r['tick_cost_ms_p99']:.3f} ms, max "
                  f"{r['tick_cost_ms_max']:.2f} ms; real-time factor {r['rtf']:.4f}; node CPU {r['cpu']:.0f} %; "
                  f"overruns {r['overruns']}")
    r = lockstep(node)
    print(f"lockstep, 1 ms inputs answered one at a time: {r['steps_per_s']:.0f} steps/s = "
          f"{r['sim_s_per_wall_s']:.3f} simulated s per wall s")
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
