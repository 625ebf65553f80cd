"""Write a finished run to MCAP with the same topics the ROS node publishes.

Topics (relative names, frame `rachis`, z up; see topics.py):
  rachis/accel                     geometry_msgs/AccelStamped   the input a(t) in linear.x and linear.z, m/s²
  joint_states                     sensor_msgs/JointState       twig_<angle>: angle, rate, hinge torque (effort)
  contact/<a>_<b>/wrench           geometry_msgs/WrenchStamped  force on berry b from berry a, N (small scenes)
  contacts                         std_msgs/Float64MultiArray   pair, force, penetration of each pair in contact
  pedicel_tension                  sensor_msgs/JointState       twig_<berry>: tension in effort, N
  summary                          std_msgs/Float64MultiArray   cluster totals (topics.SUMMARY_FIELDS)
  collision_events                 std_msgs/Float64MultiArray   one message per impact, fields in dim labels
A metadata record `grapefmu` holds the scene TOML, solver settings and version, so the run can be re-simulated.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import __version__
from ..results.run import Run
from ..results.writers import atomic_path
from .msgdefs import MSGDEFS
from .topics import CONTACT_FIELDS, SUMMARY_FIELDS, contact_values, hinge_effort, joint_names, per_pair_topics

FRAME = "rachis"
IMPACT_FIELDS = ("pair_index", "onset_s", "end_s", "duration_s", "approach_speed_mps", "separation_speed_mps",
                 "peak_force_n", "impulse_ns", "dissipated_j")


def _stamp(t: float) -> dict:
    ns = int(round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(t: float) -> dict:
    return {"stamp": _stamp(t), "frame_id": FRAME}


def labelled_array(labels: list[str], values) -> dict:
    dims = [{"label": ",".join(labels), "size": len(labels), "stride": len(labels)}]
    return {"layout": {"dim": dims, "data_offset": 0}, "data": [float(v) for v in values]}


def impact_messages(run: Run) -> list[tuple[float, dict]]:
    imp = run.impacts
    out = []
    for k in range(len(imp)):
        vals = [imp.pair[k], imp.onset[k], imp.end[k], imp.duration[k], imp.approach_speed[k],
                imp.separation_speed[k], imp.peak_force[k], imp.impulse[k], imp.dissipated[k]]
        out.append((float(imp.end[k]), labelled_array(list(IMPACT_FIELDS), vals)))
    return out


def run_metadata(run: Run) -> dict[str, str]:
    s = run.scene.solver
    return {"grapefmu_version": __version__, "scene_name": run.scene.name, "scene_toml": run.scene.source,
            "method": str(run.stats.get("method", s.method)), "input_source": "scene",
            "solver": json.dumps({"rtol": run.stats.get("rtol", s.rtol), "atol": run.stats.get("atol", s.atol),
                                  "t_end": float(run.t[-1]), "output_interval": s.output_interval})}


def write_mcap(run: Run, path: str | Path) -> None:
    from mcap_ros2.writer import Writer

    m = run.scene.model
    joints = joint_names(m)
    berry_joints = [f"twig_{n}" for n in m.names]
    q, w = run.angles, run.angular_velocities
    effort = hinge_effort(m, q, w)
    wrenches = per_pair_topics(m)
    pos = run.positions if wrenches else None
    in_contact = run.mode != 0
    e = run.energy
    dissipated = e["dissipated_hinge"] + e["dissipated_coupling"] + e["dissipated_contact"]
    peak_f = np.maximum.accumulate(run.contact_force.max(axis=1, initial=0.0))
    peak_t = np.maximum.accumulate(run.pedicel_force.max(axis=1))
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        wr = Writer(fh)
        schema = {k: wr.register_msgdef(k, v) for k, v in MSGDEFS.items()}
        wr.add_metadata("grapefmu", run_metadata(run))
        messages = []
        for s, t in enumerate(run.t):
            ns = int(round(t * 1e9))
            messages.append((ns, 0, "rachis/accel", "geometry_msgs/msg/AccelStamped",
                             {"header": _header(t), "accel": {"linear": {"x": run.accel[s, 0], "y": 0.0, "z": run.accel[s, 1]},
                                                              "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}}))
            messages.append((ns, 1, "joint_states", "sensor_msgs/msg/JointState",
                             {"header": _header(t), "name": joints, "position": q[s].tolist(),
                              "velocity": w[s].tolist(), "effort": effort[s].tolist()}))
            for p in range(len(m.pairs)) if wrenches else ():
                i, j = m.pairs[p].i, m.pairs[p].j
                d = pos[s, j] - pos[s, i]
                f = run.contact_force[s, p] * d / max(float(np.linalg.norm(d)), 1e-300)
                messages.append((ns, 2, f"contact/{m.pair_name(p)}/wrench", "geometry_msgs/msg/WrenchStamped",
                                 {"header": _header(t), "wrench": {"force": {"x": f[0], "y": f[1], "z": f[2]},
                                                                   "torque": {"x": 0.0, "y": 0.0, "z": 0.0}}}))
            vals = contact_values(run.contact_force[s], run.penetration[s], in_contact[s])
            msg = labelled_array(list(CONTACT_FIELDS), vals)
            msg["layout"]["dim"][0]["size"] = len(vals) // 3
            messages.append((ns, 2, "contacts", "std_msgs/msg/Float64MultiArray", msg))
            messages.append((ns, 3, "pedicel_tension", "sensor_msgs/msg/JointState",
                             {"header": _header(t), "name": berry_joints, "position": [], "velocity": [],
                              "effort": run.pedicel_force[s].tolist()}))
            messages.append((ns, 3, "summary", "std_msgs/msg/Float64MultiArray", labelled_array(list(SUMMARY_FIELDS), [
                t, in_contact[s].sum(), run.contact_force[s].max(initial=0.0), run.pedicel_force[s].max(),
                peak_f[s], peak_t[s], dissipated[s]])))
        for t, msg in impact_messages(run):
            messages.append((int(round(t * 1e9)), 4, "collision_events", "std_msgs/msg/Float64MultiArray", msg))
        messages.sort(key=lambda x: (x[0], x[1]))
        seq: dict[str, int] = {}
        for ns, _, topic, dtype, msg in messages:
            seq[topic] = seq.get(topic, -1) + 1
            wr.write_message(topic, schema[dtype], msg, log_time=ns, publish_time=ns, sequence=seq[topic])
        wr.finish()
