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


def labelled(labels: list[str], values, rows: int | None = None) -> Float64MultiArray:
    """values in rows of len(labels) fields; one row unless told (the field names label the dimension)."""
    m = Float64MultiArray()
    m.layout.dim = [MultiArrayDimension(label=",".join(labels), size=len(labels) if rows is None else rows,
                                        stride=len(labels))]
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
    m.wrench.force = Vector3(x=float(force_vec[0]), y=float(force_vec[1]), z=float(force_vec[2]))
    return m


def impact_message(imp, k) -> Float64MultiArray:
    """One impact, its fields named in order in the dimension label (docs/ros.md)."""
    vals = [imp.pair[k], imp.onset[k], imp.end[k], imp.duration[k], imp.approach_speed[k], imp.separation_speed[k],
            imp.peak_force[k], imp.impulse[k], imp.dissipated[k]]
    return labelled(list(IMPACT_FIELDS), vals)


def _pt(v) -> Point:
    return Point(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def markers(t, origin, hinges, berries, radii, pairs, forces, force_scale=0.02) -> MarkerArray:
    """Rachis (origin to every hinge), twigs, berries and contact-force lines in the world frame
    (REP-103, z up) for Foxglove or RViz. Three markers plus one sphere per berry, however many
    pairs the cluster has."""
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
    rod = base_marker(0, Marker.LINE_LIST, "rachis")
    for h in hinges:
        rod.points += [_pt(origin), _pt(h)]
    rod.scale.x = 0.003
    rod.color = ColorRGBA(r=0.4, g=0.3, b=0.2, a=1.0)
    arr.markers.append(rod)
    twigs = base_marker(1, Marker.LINE_LIST, "twigs")
    twigs.scale.x = 0.0015
    twigs.color = ColorRGBA(r=0.2, g=0.6, b=0.2, a=1.0)
    for h, b in zip(hinges, berries):
        twigs.points += [_pt(h), _pt(b)]
    arr.markers.append(twigs)
    contact = base_marker(2, Marker.LINE_LIST, "contact")
    contact.scale.x = 0.002
    contact.color = ColorRGBA(r=0.9, g=0.2, b=0.1, a=1.0)
    for (i, j), f in zip(pairs, forces):
        if f > 0.0:
            mid = (berries[i] + berries[j]) / 2
            d = berries[j] - berries[i]
            contact.points += [_pt(mid), _pt(mid + d / max(float(np.linalg.norm(d)), 1e-12) * f * force_scale)]
    arr.markers.append(contact)
    for i, (b, r) in enumerate(zip(berries, radii)):
        s = base_marker(10 + i, Marker.SPHERE, "berries")
        s.pose.position = _pt(b)
        s.scale = Vector3(x=2 * r, y=2 * r, z=2 * r)
        s.color = ColorRGBA(r=0.45, g=0.1, b=0.5, a=0.9)
        arr.markers.append(s)
    return arr


def diagnostics(t, level: int, message: str, values: dict) -> DiagnosticArray:
    arr = DiagnosticArray()
    arr.header.stamp = stamp(t)
    st = DiagnosticStatus(level=bytes([level]), name="grapefmu: simulator", message=message, hardware_id="grapefmu")
    st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    arr.status = [st]
    return arr
