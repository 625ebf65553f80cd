"""Read a grapefmu MCAP recording back and re-simulate it (`grapefmu replay run.mcap --check`).

A recording from `grapefmu simulate` is re-simulated from the scene and solver settings in its metadata;
one from the ROS node is re-simulated from `rachis/accel_applied`, the exact intervals and held
accelerations the node integrated. Either way the recorded joint states are compared with the new run.
A file that ends abruptly (a killed recorder) is read up to its last complete chunk and reported."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import RecordingError
from ..scenefile import parse_scene
from .stamps import seconds, stamp_seconds, to_ns


@dataclass
class Recording:
    path: Path
    metadata: dict[str, str]
    topics: dict[str, list] = field(default_factory=dict)  # topic -> [(log_time_ns, decoded message)]
    truncated: str | None = None
    count: int = 0

    @property
    def last_time(self) -> float:
        return max((m[-1][0] for m in self.topics.values() if m), default=0) / 1e9


def iter_messages(fh, on_metadata=None):
    """(schema, channel, message record) for every message, streamed record by record, so a file with a
    torn end yields every complete chunk before the reader raises at the tear."""
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    schemas, channels = {}, {}
    for r in StreamReader(fh).records:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
        elif isinstance(r, Metadata) and on_metadata:
            on_metadata(r)
        elif isinstance(r, Message):
            ch = channels[r.channel_id]
            yield schemas[ch.schema_id], ch, r


def read_recording(path: str | Path, topics: set[str] | None = None) -> Recording:
    """Every message (of the given topics), decoded through the typestore that wrote it."""
    from .typestore import deserialize

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    rec = Recording(path, {})

    def keep_metadata(r):
        if r.name == "grapefmu":
            rec.metadata.update(r.metadata)
    with open(path, "rb") as fh:
        try:
            for schema, ch, r in iter_messages(fh, keep_metadata):
                if topics and ch.topic not in topics:
                    continue
                rec.topics.setdefault(ch.topic, []).append((r.log_time, deserialize(r.data, schema.name)))
                rec.count += 1
        except Exception as e:  # noqa: BLE001 - mcap raises several types at a torn end
            rec.truncated = (f"{path} ends abruptly ({type(e).__name__}: the recorder did not close it, probably "
                             f"killed); {rec.count} messages read, up to t = {rec.last_time:.6f} s")
    if "scene_toml" not in rec.metadata:
        raise RecordingError(f"{path}: no grapefmu metadata record (scene and solver settings); not a grapefmu recording")
    return rec


@dataclass
class CheckResult:
    compared: int
    max_angle_deviation: float
    max_rate_deviation: float
    source: str
    truncated: str | None

    @property
    def max_deviation(self) -> float:
        return max(self.max_angle_deviation, self.max_rate_deviation)


def check(path: str | Path) -> CheckResult:
    rec = read_recording(path, {"joint_states", "rachis/accel_applied"})
    scene = parse_scene(rec.metadata["scene_toml"], name=rec.metadata.get("scene_name", "scene"))
    solver_cfg = json.loads(rec.metadata.get("solver", "{}"))
    recorded = {}
    for _, m in rec.topics.get("joint_states", []):
        recorded[stamp_seconds(m.header.stamp.sec, m.header.stamp.nanosec)] = (np.array(m.position),
                                                                               np.array(m.velocity))
    if not recorded:
        raise RecordingError(f"{path}: no joint_states to compare")
    source = rec.metadata.get("input_source", "scene")
    dq = dw = 0.0
    n = 0
    if source == "scene":
        from ..solver.api import simulate
        run = simulate(scene, solver_cfg.get("t_end"), method=rec.metadata.get("method"), rtol=solver_cfg.get("rtol"),
                       atol=solver_cfg.get("atol"), output_interval=solver_cfg.get("output_interval"))
        for k, t in enumerate(run.t):
            key = seconds(to_ns(t))
            if key in recorded:
                q, w = recorded[key]
                dq = max(dq, float(np.abs(run.angles[k] - q).max()))
                dw = max(dw, float(np.abs(run.angular_velocities[k] - w).max()))
                n += 1
    else:
        from ..solver.solver import Solver
        solver = Solver(scene)
        for _, m in rec.topics.get("rachis/accel_applied", []):
            t_end = stamp_seconds(m.header.stamp.sec, m.header.stamp.nanosec)
            if t_end < solver.t:  # the node was reset
                solver = Solver(scene)
            solver.advance(t_end - solver.t, (m.accel.linear.x, m.accel.linear.z))
            if t_end in recorded:
                q, w = recorded[t_end]
                dq = max(dq, float(np.abs(solver.angles - q).max()))
                dw = max(dw, float(np.abs(solver.angular_velocities - w).max()))
                n += 1
    if n == 0:
        raise RecordingError(f"{path}: no recorded joint state matches a re-simulated time")
    return CheckResult(n, dq, dw, source, rec.truncated)
