"""Every ROS 2 message grapefmu records or publishes, built once from the output catalogue.

`state_messages` turns one sample of a `Snapshot` into the messages of every state topic; the MCAP
writer calls it for every sample of a run and the ROS node for every state it reaches, and both
serialize through the one typestore (typestore.py). Topics (relative to the node's namespace,
/grape_cluster by default; frames in frames.py, REP-103: x along the rod, y left, z up; docs/ros.md):

  joint_states               sensor_msgs/JointState       twig_<angle>: angle, angular velocity, hinge torque
  pedicel_tension            grapefmu_msgs/PedicelTension berry names and pedicel tension, N
  contact/<a>_<b>/wrench     geometry_msgs/WrenchStamped  force on berry b from berry a, N (up to PER_PAIR_LIMIT pairs)
  contacts                   grapefmu_msgs/Contacts       both bodies, point, normal, depth and force of each contact
  summary                    grapefmu_msgs/Summary        simulated time and the catalogue's summary channels, named
  collision_events           grapefmu_msgs/CollisionEvent one message per finished impact
  rachis/accel_applied       geometry_msgs/AccelStamped   the rachis acceleration held over the interval ending at the
                                                          stamp, linear (m/s²) and angular (rad/s²), world frame
  rachis/twist_applied       geometry_msgs/TwistStamped   the rachis' angular velocity (rad/s, world) set at the start
                                                          of that interval (the node, only when an input set it)
  markers                    visualization_msgs/MarkerArray  rachis, twigs, berries and contact forces, frame `world`
  /tf, /tf_static            tf2_msgs/TFMessage           world → rachis → berries and hinges (frames.py)
  robot_description          std_msgs/String              URDF of the cluster, consistent with /tf
"""
from __future__ import annotations

import numpy as np

from ..model.model import Model
from ..results import catalogue
from ..results.impacts import Impacts
from . import frames
from .stamps import to_ns
from .typestore import header, msg, stamp

WORLD = frames.WORLD
#: the node's default namespace; recordings name topics absolutely under it, as rosbag2 does
NAMESPACE = "/grape_cluster"
#: the summary topic's fields, in order
SUMMARY_FIELDS = ("time", *(c.name for c in catalogue.on_topic("summary")))
#: the type of every topic this module builds
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState", "pedicel_tension": "grapefmu_msgs/msg/PedicelTension",
    "contacts": "grapefmu_msgs/msg/Contacts", "summary": "grapefmu_msgs/msg/Summary",
    "collision_events": "grapefmu_msgs/msg/CollisionEvent", "rachis/accel": "geometry_msgs/msg/AccelStamped",
    "rachis/accel_applied": "geometry_msgs/msg/AccelStamped", "rachis/twist_applied": "geometry_msgs/msg/TwistStamped",
    "markers": "visualization_msgs/msg/MarkerArray",
    "/clock": "rosgraph_msgs/msg/Clock", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "rachis/pose": "geometry_msgs/msg/PoseStamped", "rachis/twist": "geometry_msgs/msg/TwistStamped",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage", "robot_description": "std_msgs/msg/String",
    "sim_time": "rosgraph_msgs/msg/Clock",
}
WRENCH = "geometry_msgs/msg/WrenchStamped"


def wrench_topics(model: Model) -> list[str]:
    """One wrench topic per pair, for scenes with up to PER_PAIR_LIMIT pairs (a cluster gets `contacts` only)."""
    if len(model.pairs) > catalogue.PER_PAIR_LIMIT:
        return []
    return [f"contact/{model.pair_name(p)}/wrench" for p in range(len(model.pairs))]


def topic_type(topic: str) -> str:
    return WRENCH if topic.endswith("/wrench") else TOPIC_TYPES[topic]


def absolute(topic: str, namespace: str = NAMESPACE) -> str:
    """The full name of a topic of this module under `namespace` (global names like /tf stay as they are)."""
    return topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"


def relative(topic: str, namespace: str = NAMESPACE) -> str:
    """The inverse of absolute (a recording made before topics were namespaced has them relative already)."""
    head = namespace.rstrip("/") + "/"
    return topic[len(head):] if head != "/" and topic.startswith(head) else topic


def _transform(ns: int, parent: str, child: str, xyz, q):
    return msg("geometry_msgs/msg/TransformStamped", header=header(ns, parent), child_frame_id=child,
               transform={"translation": {"x": float(xyz[0]), "y": float(xyz[1]), "z": float(xyz[2])},
                          "rotation": {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}})


def tf_static(model: Model, ns: int, prefix: str = frames.PREFIX):
    """("/tf_static", message) of the transforms that never change, and ("robot_description", URDF)."""
    return [("/tf_static", msg("tf2_msgs/msg/TFMessage", transforms=[
                _transform(ns, *t) for t in frames.static_transforms(model, prefix)])),
            ("robot_description", msg("std_msgs/msg/String", data=frames.urdf(model, prefix)))]


_MSG_TYPES = {"real": "float64", "integer": "int64", "boolean": "bool"}
_CAST = {"real": float, "integer": int, "boolean": bool}


def summary_msg() -> str:
    """grapefmu_msgs/msg/Summary, written from the output catalogue's summary channels: the text of
    recording/msg/Summary.msg (tests/test_outputs.py keeps the file equal to this)."""
    lines = ["# The cluster's summary at the header's stamp: the output catalogue's summary channels",
             "# (docs/outputs.md). Generated by grapefmu.recording.messages.summary_msg(); do not edit.",
             "std_msgs/Header header", f"{'float64 time':<40}# s, simulated time"]
    for c in catalogue.on_topic("summary"):
        unit = f"{c.unit}, " if c.unit else ""
        lines.append(f"{_MSG_TYPES[c.type] + ' ' + c.name:<40}# {unit}{c.description}")
    return "\n".join(lines) + "\n"


def _summary(ns: int, frame: str, row) -> object:
    fields = {"time": float(row[0])}
    fields.update({c.name: _CAST[c.type](row[k]) for k, c in enumerate(catalogue.on_topic("summary"), start=1)})
    return msg("grapefmu_msgs/msg/Summary", header=header(ns, frame), **fields)


def _vector(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def accel(ns: int, a, topic: str = "rachis/accel", frame: str = frames.WORLD):
    """The rachis acceleration a (ACCEL_COMPONENTS: linear, then angular) as an AccelStamped in `frame`."""
    return topic, msg("geometry_msgs/msg/AccelStamped", header=header(ns, frame),
                      accel={"linear": _vector(a[:3]), "angular": _vector(a[3:6])})


def twist(ns: int, angular, topic: str = "rachis/twist", frame: str = frames.WORLD, linear=(0.0, 0.0, 0.0)):
    """The rachis' angular velocity (and linear velocity, m/s) as a TwistStamped in `frame`."""
    return topic, msg("geometry_msgs/msg/TwistStamped", header=header(ns, frame),
                      twist={"linear": _vector(linear), "angular": _vector(angular)})


def clock(ns: int):
    return "/clock", msg("rosgraph_msgs/msg/Clock", clock=header(ns).stamp)


def summary_table(snap: catalogue.Snapshot) -> np.ndarray:
    """(S, len(SUMMARY_FIELDS)): the summary topic's rows, each channel evaluated once over all samples."""
    return np.column_stack([snap.t, *(np.asarray(c.value(snap), dtype=float) for c in catalogue.on_topic("summary"))])


def joint_names(model: Model) -> list[str]:
    """The joint_states topic's joint names, one per angle (a viewer places each value at the joint its name says)."""
    return [f"twig_{n}" for n in model.dof_names]


def state_messages(model: Model, snap: catalogue.Snapshot, k: int, ns: int, summary: np.ndarray, *,
                   markers: bool = False, tf: bool = True, prefix: str = frames.PREFIX,
                   world: str = frames.WORLD) -> list:
    """(topic, message) of every state topic at sample k of snap, stamped ns; `summary` is summary_table(snap).
    Markers and /tf only when asked: a 3D view needs far fewer of them than the state topics' rate. `world`: the
    fixed frame they are placed in."""
    obs = snap.observation
    out = [("joint_states", msg("sensor_msgs/msg/JointState", header=header(ns, frames.rachis(prefix)),
                                name=joint_names(model), position=snap.angles[k], velocity=snap.angular_velocities[k],
                                effort=obs.hinge_torque[k])),
           ("pedicel_tension", msg("grapefmu_msgs/msg/PedicelTension", header=header(ns, frames.rachis(prefix)),
                                   berry=list(model.names), tension=obs.pedicel_tension[k]))]
    force, normal = obs.contact_force[k], obs.contact_normal[k]
    for p, topic in enumerate(wrench_topics(model)):
        f = force[p] * normal[p]
        out.append((topic, msg(WRENCH, header=header(ns, frames.rachis(prefix)),
                               wrench={"force": {"x": f[0], "y": f[1], "z": f[2]}})))
    out.append(("contacts", msg("grapefmu_msgs/msg/Contacts", header=header(ns, frames.rachis(prefix)),
                                contacts=contacts(model, obs, k, np.flatnonzero(snap.in_contact[k])))))
    out.append(("summary", _summary(ns, frames.rachis(prefix), summary[k])))
    if tf:
        out.append(("/tf", msg("tf2_msgs/msg/TFMessage", transforms=[
            _transform(ns, *t) for t in frames.transforms(model, snap, k, prefix, world)])))
    if markers:
        out.append(("markers", marker_array(model, snap, k, ns, world=world)))
    return out


def contact_point(model: Model, obs, k: int, p: int) -> np.ndarray:
    """Where pair p touches at sample k (rachis frame): midway through the overlap, along the normal from its
    berry toward the other body (a berry or an obstacle)."""
    pr = model.pairs[p]
    return obs.position[k, pr.i] + (model.berries[pr.i].radius - 0.5 * float(obs.penetration[k, p])) * \
        obs.contact_normal[k, p]


def contacts(model: Model, obs, k: int, touching) -> list:
    """grapefmu_msgs/Contact of each pair in `touching` at sample k: the point midway through the overlap."""
    out = []
    bodies = model.body_names
    for p in touching:
        pr = model.pairs[p]
        n, depth = obs.contact_normal[k, p], float(obs.penetration[k, p])
        point = contact_point(model, obs, k, p)
        out.append(msg("grapefmu_msgs/msg/Contact", body_a=bodies[pr.i], body_b=bodies[pr.j],
                       position={"x": point[0], "y": point[1], "z": point[2]},
                       normal={"x": n[0], "y": n[1], "z": n[2]}, depth=depth, force=float(obs.contact_force[k, p])))
    return out


def impact_messages(model: Model, impacts: Impacts, origin: int = 0, prefix: str = frames.PREFIX) -> list:
    """(end stamp in ns, "collision_events", message) of every impact; stamps are `origin` + simulated time."""
    out = []
    bodies = model.body_names
    for r in impacts.records():
        pr = model.pairs[int(r["pair"])]
        end = origin + to_ns(float(r["end"]))
        out.append((end, "collision_events", msg(
            "grapefmu_msgs/msg/CollisionEvent", header=header(end, frames.rachis(prefix)),
            body_a=bodies[pr.i], body_b=bodies[pr.j], onset=stamp(origin + to_ns(float(r["onset"]))),
            peak_time=stamp(origin + to_ns(float(r["peak_time"]))), approach_speed=float(r["approach_speed"]),
            separation_speed=float(r["separation_speed"]), peak_force=float(r["peak_force"]),
            impulse=float(r["impulse"]), dissipated_energy=float(r["dissipated"]), bruising=bool(r["bruising"]))))
    return out


def marker_array(model: Model, snap: catalogue.Snapshot, k: int, ns: int, force_scale: float = 0.02,
                 world: str = frames.WORLD):
    """Rachis (origin to every hinge), twigs, berries and contact-force lines in the fixed frame `world` (z up) for
    Foxglove or RViz: three line lists plus one sphere per berry, however many pairs the cluster has."""
    M = model.arrays
    rachis = np.column_stack([M.berry["hinge_x"], M.berry["hinge_y"], M.berry["hinge_z"]])
    frame = snap._replace(base_displacement=snap.base_displacement[k: k + 1],
                          base_orientation=snap.base_orientation[k: k + 1])
    origin, *hinges = catalogue.world(frame, np.vstack([np.zeros(3), rachis])[None])[0]
    berries = catalogue.world(frame, snap.observation.position[k: k + 1])[0]

    def marker(mid, mtype, ns_, scale, color, points=(), pose=None):
        return msg("visualization_msgs/msg/Marker", header=header(ns, world), ns=ns_, id=mid, type=mtype, action=0,
                   pose=pose or {"orientation": {"w": 1.0}}, scale=scale, color=color,
                   points=[_vector(p) for p in points])
    line = 5  # LINE_LIST
    force = snap.observation.contact_force[k]
    normal = snap.observation.contact_normal[k]
    contact_pts = []
    for p in np.flatnonzero(force > 0.0):
        mid = catalogue.world(frame, contact_point(model, snap.observation, k, p)[None, None])[0, 0]
        contact_pts += [mid, mid - normal[p] * force[p] * force_scale]  # the force on the pair's first berry
    arr = [marker(0, line, "rachis", {"x": 0.003}, {"r": 0.4, "g": 0.3, "b": 0.2, "a": 1.0},
                  [x for h in hinges for x in (origin, h)]),
           marker(1, line, "twigs", {"x": 0.0015}, {"r": 0.2, "g": 0.6, "b": 0.2, "a": 1.0},
                  [x for h, b in zip(hinges, berries) for x in (h, b)]),
           marker(2, line, "contact", {"x": 0.002}, {"r": 0.9, "g": 0.2, "b": 0.1, "a": 1.0}, contact_pts)]
    for i, (b, r) in enumerate(zip(berries, M.berry["radius"])):
        arr.append(marker(10 + i, 2, "berries", {"x": 2 * r, "y": 2 * r, "z": 2 * r},
                          {"r": 0.45, "g": 0.1, "b": 0.5, "a": 0.9},
                          pose={"position": _vector(b), "orientation": {"w": 1.0}}))
    for k_, o in enumerate(model.obstacles):
        mtype, scale = _obstacle_shape(o)
        arr.append(marker(100000 + k_, mtype, "obstacles", scale, {"r": 0.6, "g": 0.6, "b": 0.6, "a": 0.4},
                          pose=_obstacle_pose(o, frame)))
    return msg("visualization_msgs/msg/MarkerArray", markers=arr)


def _obstacle_shape(o) -> tuple[int, dict]:
    """(Marker type, scale) of an obstacle: a 0.5 m square of a plane, the box, a capsule's cylinder."""
    if o.kind == "plane":
        return 1, {"x": 0.5, "y": 0.5, "z": 0.001}
    if o.kind == "box":
        return 1, dict(zip("xyz", map(float, o.size)))
    return 3, {"x": 2 * o.radius, "y": 2 * o.radius, "z": float(np.linalg.norm(np.subtract(o.end, o.point)))}


def _obstacle_pose(o, frame: catalogue.Snapshot) -> dict:
    """An obstacle's marker pose in the world frame (one attached to the gripper moves with the rachis)."""
    centre = np.array(o.point) if o.kind != "capsule" else (np.array(o.point) + np.array(o.end)) / 2
    if o.kind == "plane":
        q = frames.quaternion_z_to(np.array(o.normal))
    elif o.kind == "box":
        q = np.array([0.0, 0.0, np.sin(o.yaw / 2), np.cos(o.yaw / 2)])
    else:
        q = frames.quaternion_z_to(np.subtract(o.end, o.point))
    if o.attached:  # carried, and turned, with the rachis
        centre = catalogue.world(frame, centre[None, None])[0, 0]
        q = frames.compose(frame.base_orientation[0], q)
    return {"position": dict(zip("xyz", map(float, centre))), "orientation": dict(zip("xyzw", map(float, q)))}


def diagnostics(ns: int, level: int, message: str, values: dict):
    status = msg("diagnostic_msgs/msg/DiagnosticStatus", level=level, name="grapefmu: simulator",
                 message=message, hardware_id="grapefmu",
                 values=[{"key": k, "value": str(v)} for k, v in values.items()])
    return "/diagnostics", msg("diagnostic_msgs/msg/DiagnosticArray", header=header(ns), status=[status])
