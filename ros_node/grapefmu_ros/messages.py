"""Solver state → standard ROS messages. Stamps are simulation time (s from the start of the run)."""
from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Vector3, WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64MultiArray, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray

from grapefmu.recording.mcap_writer import IMPACT_FIELDS
from grapefmu.recording.stamps import to_ns

FRAME = "rachis"
WORLD = "world"


def stamp(t: float) -> Time:
    ns = to_ns(t)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def labelled(labels: list[str], values) -> Float64MultiArray:
    m = Float64MultiArray()
    m.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels), stride=len(labels))]
    m.data = [float(v) for v in values]
    return m


def joint_state(t, names, q, w, effort) -> JointState:
    m = JointState()
    m.header.stamp = stamp(t)
    m.header.frame_id = FRAME
    m.name = [f"twig_{n}" for n in names]
    m.position = [float(x) for x in q]
    m.velocity = [float(x) for x in w]
    m.effort = [float(x) for x in effort]
    return m


def tension(t, names, values) -> JointState:
    """Pedicel tension per berry: one joint per twig, the tension (N, + pulling) in `effort`."""
    m = JointState()
    m.header.stamp = stamp(t)
    m.header.frame_id = FRAME
    m.name = [f"twig_{n}" for n in names]
    m.effort = [float(x) for x in values]
    return m


def wrench(t, force_vec) -> WrenchStamped:
    m = WrenchStamped()
    m.header.stamp = stamp(t)
    m.header.frame_id = FRAME
    m.wrench.force = Vector3(x=float(force_vec[0]), y=float(force_vec[1]), z=0.0)
    return m


def impact_message(imp, k) -> Float64MultiArray:
    """One impact, its fields named in order in the dimension label (docs/ros.md)."""
    vals = [imp.pair[k], imp.onset[k], imp.end[k], imp.duration[k], imp.approach_speed[k], imp.separation_speed[k],
            imp.peak_force[k], imp.impulse[k], imp.dissipated[k]]
    return labelled(list(IMPACT_FIELDS), vals)


def markers(t, base, hinges, berries, radii, pairs, forces, force_scale=0.02) -> MarkerArray:
    """Rod, twigs, berries and contact-force arrows in the world frame (x right, y up)."""
    arr = MarkerArray()

    def base_marker(mid, mtype, ns):
        m = Marker()
        m.header.stamp = stamp(t)
        m.header.frame_id = WORLD
        m.ns = ns
        m.id = mid
        m.type = mtype
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        return m
    rod = base_marker(0, Marker.LINE_STRIP, "rachis")
    xs = [h[0] for h in hinges]
    rod.points = [Point(x=float(min(xs) - 0.01), y=float(base[1])), Point(x=float(max(xs) + 0.01), y=float(base[1]))]
    rod.scale.x = 0.004
    rod.color = ColorRGBA(r=0.4, g=0.3, b=0.2, a=1.0)
    arr.markers.append(rod)
    twigs = base_marker(1, Marker.LINE_LIST, "twigs")
    twigs.scale.x = 0.0015
    twigs.color = ColorRGBA(r=0.2, g=0.6, b=0.2, a=1.0)
    for h, b in zip(hinges, berries):
        twigs.points += [Point(x=float(h[0]), y=float(h[1])), Point(x=float(b[0]), y=float(b[1]))]
    arr.markers.append(twigs)
    for i, (b, r) in enumerate(zip(berries, radii)):
        s = base_marker(10 + i, Marker.SPHERE, "berries")
        s.pose.position = Point(x=float(b[0]), y=float(b[1]))
        s.scale = Vector3(x=2 * r, y=2 * r, z=2 * r)
        s.color = ColorRGBA(r=0.45, g=0.1, b=0.5, a=0.9)
        arr.markers.append(s)
    for p, ((i, j), f) in enumerate(zip(pairs, forces)):
        a = base_marker(100 + p, Marker.ARROW, "contact")
        if f <= 0.0:
            a.action = Marker.DELETE
        else:
            mid = (berries[i] + berries[j]) / 2
            d = berries[j] - berries[i]
            n = d / max(math.hypot(*d), 1e-12)
            a.points = [Point(x=float(mid[0]), y=float(mid[1])),
                        Point(x=float(mid[0] + n[0] * f * force_scale), y=float(mid[1] + n[1] * f * force_scale))]
            a.scale = Vector3(x=0.002, y=0.004, z=0.004)
            a.color = ColorRGBA(r=0.9, g=0.2, b=0.1, a=1.0)
        arr.markers.append(a)
    return arr


def diagnostics(t, level: int, message: str, values: dict) -> DiagnosticArray:
    arr = DiagnosticArray()
    arr.header.stamp = stamp(t)
    st = DiagnosticStatus(level=bytes([level]), name="grapefmu: simulator", message=message, hardware_id="grapefmu")
    st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    arr.status = [st]
    return arr


def positions(y, berry, base):
    """World positions of hinges and berry centres (N, 2) each."""
    n = berry.shape[0]
    q = y[:n]
    hinges = np.column_stack([berry[:, 3] + base[0], np.full(n, base[1])])
    centres = hinges + np.column_stack([berry[:, 2] * np.sin(q), -berry[:, 2] * np.cos(q)])
    return hinges, centres
