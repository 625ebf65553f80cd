"""Write a finished run to MCAP with the same topics and messages the ROS node publishes (messages.py).

A metadata record `grapefmu` holds the scene TOML, solver settings and version, so the run can be
re-simulated (`grapefmu replay run.mcap --check`)."""
from __future__ import annotations

import json
from pathlib import Path

from .. import __version__
from ..results.run import Run
from ..results.writers import atomic_path
from . import messages
from .stamps import to_ns
from .typestore import McapWriter


def run_metadata(run: Run) -> dict[str, str]:
    s = run.scene.solver
    return {"grapefmu_version": __version__, "scene_name": run.scene.name, "scene_toml": run.scene.source,
            "method": str(run.stats.get("method", s.method)), "input_source": "scene",
            "solver": json.dumps({"rtol": run.stats.get("rtol", s.rtol), "atol": run.stats.get("atol", s.atol),
                                  "t_end": float(run.t[-1]), "output_interval": s.output_interval})}


def write_mcap(run: Run, path: str | Path, *, chunk_size: int = 1 << 20) -> None:
    """`chunk_size`: uncompressed bytes per chunk (a torn file reads back up to its last complete chunk)."""
    model = run.scene.model
    snap = run.snapshot()
    summary = messages.summary_table(snap)
    timed = []  # (ns, order, topic, message): state topics first at each stamp, impacts last
    for k, t in enumerate(run.t):
        ns = to_ns(float(t))
        timed.append((ns, 0, *messages.accel(ns, run.accel[k])))
        timed += [(ns, 1, topic, m) for topic, m in messages.state_messages(model, snap, k, ns, summary)]
    timed += [(ns, 2, topic, m) for ns, topic, m in messages.impact_messages(run.impacts)]
    timed.sort(key=lambda x: (x[0], x[1]))
    with atomic_path(path) as tmp, McapWriter(tmp, chunk_size=chunk_size) as wr:
        wr.add_metadata("grapefmu", run_metadata(run))
        for ns, _, topic, m in timed:
            wr.write(topic, m, ns)
