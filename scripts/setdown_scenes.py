"""Write the set-down examples: a 20-berry cluster held over a crate (foam floor, hard plastic walls on
either side), carried 3 cm toward one wall and lowered 4 cm onto the floor, fast and gentle (the same path:
carried in 0.2 s and lowered in 0.25 s, or carried in 0.6 s and lowered in 1.0 s). Obstacles are planes, so the cluster starts between the walls.
Run: .venv/bin/python scripts/setdown_scenes.py   -> scenes/setdown_fast.toml, scenes/setdown_gentle.toml
The gripper only translates (a tilt on the way needs the 6-DoF rachis of issue 13, not built yet)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from grapefmu import Solver
from grapefmu.cluster import ClusterSpec, cluster_scene
from grapefmu.scenefile import scene_from_dict
from grapefmu.scenefile.toml_out import dumps

HERE = Path(__file__).resolve().parents[1] / "scenes"
CARRY, PRESS = 0.03, 0.01  # m: across, and how far the lowest berry would sink below the floor at the end
FOAM = {"law": "hunt-crossley", "stiffness": 3e4, "restitution": 0.2, "bruise_force": 2.5, "bruise_energy": 2e-3}
PLASTIC = {"law": "hunt-crossley", "stiffness": 1e6, "restitution": 0.6, "bruise_force": 1.2, "bruise_energy": 5e-4}


def scene(carrying: float, lowering: float, name: str) -> dict:
    doc = cluster_scene(ClusterSpec(berries=20, seed=7, name=name))
    start = Solver(scene_from_dict(doc, HERE)).snapshot().observation.position[0]
    radius = np.array([b["radius"] for b in doc["berries"]])
    floor = float((start[:, 2] - radius).min()) - 0.03           # 3 cm under the cluster at the start
    x_lo, x_hi = float((start[:, 0] - radius).min()), float((start[:, 0] + radius).max())
    doc["obstacles"] = [
        {"name": "floor", "point": [0.0, 0.0, floor], "normal": [0.0, 0.0, 1.0], **FOAM},
        {"name": "near_wall", "point": [x_lo - 0.003, 0.0, floor], "normal": [1.0, 0.0, 0.0], **PLASTIC},
        {"name": "far_wall", "point": [x_hi + CARRY + 0.003, 0.0, floor], "normal": [-1.0, 0.0, 0.0], **PLASTIC},
    ]
    doc["excitation"] = {"kind": "pick-and-place", "start": 0.1, "moves": [
        {"displacement": [CARRY, 0.0], "duration": carrying},
        {"displacement": [0.0, -(0.03 + PRESS)], "duration": lowering}]}
    doc["solver"] = {**doc["solver"], "t_end": round(0.1 + carrying + lowering + 0.6, 3)}
    return doc


if __name__ == "__main__":
    for name, carrying, lowering in (("setdown_fast", 0.2, 0.25), ("setdown_gentle", 0.6, 1.0)):
        path = HERE / f"{name}.toml"
        path.write_text("# written by scripts/setdown_scenes.py (a 20-berry cluster set down into a padded crate)\n"
                        + dumps(scene(carrying, lowering, name)),
                        encoding="utf-8")
        print(f"wrote {path}")
