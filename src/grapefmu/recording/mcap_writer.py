"""Write a finished run to MCAP with the same topics and messages the ROS node publishes (messages.py).

A metadata record `grapefmu` holds the scene TOML, solver settings and version, so the run can be
re-simulated (`grapefmu replay run.mcap --check`)."""
from __future__ import annotations

import json
from pathlib import Path

from .. import __version__
from ..model.model import ISLANDS_FROM
from ..results import trust
from ..results.run import Run
from ..results.writers import atomic_path
from ..scenefile import scene_toml
from . import messages
from .stamps import to_ns
from .typestore import McapWriter


def run_metadata(run: Run) -> dict[str, str]:
    s = run.scene.solver
    return {"grapefmu_version": __version__, "scene_name": run.scene.name, "scene_toml": scene_toml(run.scene),
            "method": str(run.stats.get("method", s.method)), "input_source": "scene",
            "namespace": messages.NAMESPACE,
            "solver": json.dumps({"rtol": run.stats.get("rtol", s.rtol), "atol": run.stats.get("atol", s.atol),
                                  "t_end": float(run.t[-1]), "output_interval": s.output_interval,
                                  "islands_from": ISLANDS_FROM, "integrator": run.stats.get("integrator")}),
            # why the results cannot be trusted, one line each: the summary's `warnings`, without the rest of it
            "warnings": json.dumps(trust.warnings(run))}


#: markers and /tf in a simulate recording, Hz (a 3D panel needs far fewer than the state topics' samples)
MARKER_RATE = 30.0
TF_RATE = 100.0


def write_mcap(run: Run, path: str | Path, *, chunk_size: int = 1 << 20) -> None:
    """`chunk_size`: uncompressed bytes per chunk (a torn file reads back up to its last complete chunk).
    Topics are named as the node under its default namespace publishes them, with /tf, /tf_static,
    robot_description, markers and /clock, so a 3D panel shows the run as it would the live node."""
    model = run.scene.model
    meta = run_metadata(run)  # refuses a scene its TOML no longer describes before a file is opened
    snap = run.snapshot()
    summary = messages.summary_table(snap)
    timed = []  # (ns, order, topic, message): state topics first at each stamp, impacts last
    t0 = to_ns(float(run.t[0]))
    timed += [(t0, 0, topic, m) for topic, m in messages.tf_static(model, t0)]
    last_marker = last_tf = -float("inf")
    for k, t in enumerate(run.t):
        ns = to_ns(float(t))
        markers = t - last_marker >= 1.0 / MARKER_RATE - 1e-12
        last_marker = t if markers else last_marker
        tf = t - last_tf >= 1.0 / TF_RATE - 1e-12
        last_tf = t if tf else last_tf
        timed.append((ns, 0, *messages.clock(ns)))
        timed.append((ns, 0, *messages.accel(ns, run.accel[k])))
        timed += [(ns, 1, topic, m) for topic, m in messages.state_messages(model, snap, k, ns, summary,
                                                                            markers=markers, tf=tf)]
    timed += [(ns, 2, topic, m) for ns, topic, m in messages.impact_messages(model, run.impacts)]
    timed.sort(key=lambda x: (x[0], x[1]))
    with atomic_path(path) as tmp, McapWriter(tmp, chunk_size=chunk_size) as wr:
        wr.add_metadata("grapefmu", meta)
        for ns, _, topic, m in timed:
            wr.write(messages.absolute(topic), m, ns)
