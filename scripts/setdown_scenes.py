"""Write the set-down examples: a 20-berry cluster lifted 7 cm while the gripper tilts it by TILT about y, carried
25 cm over a crate's wall, and lowered into it while it turns back level: a foam floor 3 cm below where the
cluster started and hard plastic walls (boxes, 8 cm high) 1 cm from the cluster on either side, so that its
lowest berries would sink 1 cm into the floor if nothing gave. Fast and gentle: the same path in
0.4 + 0.4 + 0.25 s or in 0.8 + 1.0 + 1.0 s (the generated tilt-carry-set-down: pick-and-place moves with a
rotation each).
Run: .venv/bin/python scripts/setdown_scenes.py   -> scenes/setdown_fast.toml, scenes/setdown_gentle.toml"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from grapefmu import Solver
from grapefmu.cluster import ClusterSpec, cluster_scene
from grapefmu.scenefile import scene_from_dict
from grapefmu.scenefile.toml_out import dumps

HERE = Path(__file__).resolve().parents[1] / "scenes"
LIFT, CARRY, DROP, PRESS, GAP = 0.07, 0.25, 0.03, 0.01, 0.01  # m
TILT = 0.3  # rad, about y: the gripper's wrist turns the cluster on the way up, and back on the way down
WALL = (0.01, 0.3, 0.08)  # m: thickness, length, height of a crate wall
FOAM = {"law": "hunt-crossley", "stiffness": 3e4, "restitution": 0.2, "bruise_force": 2.5, "bruise_energy": 2e-3}
PLASTIC = {"law": "hunt-crossley", "stiffness": 1e6, "restitution": 0.6, "bruise_force": 1.2, "bruise_energy": 5e-4}


def scene(lifting: float, carrying: float, lowering: float, name: str) -> dict:
    doc = cluster_scene(ClusterSpec(berries=20, seed=7, name=name))
    start = Solver(scene_from_dict(doc, HERE)).snapshot().observation.position[0]
    radius = np.array([b["radius"] for b in doc["berries"]])
    floor = float((start[:, 2] - radius).min()) - DROP
    x_lo, x_hi = float((start[:, 0] - radius).min()), float((start[:, 0] + radius).max())
    wall = {"kind": "box", "size": list(WALL), **PLASTIC}
    doc["obstacles"] = [
        {"name": "floor", "point": [CARRY, 0.0, floor], "normal": [0.0, 0.0, 1.0], **FOAM},
        {"name": "near_wall", "centre": [CARRY + x_lo - GAP - WALL[0] / 2, 0.0, floor + WALL[2] / 2], **wall},
        {"name": "far_wall", "centre": [CARRY + x_hi + GAP + WALL[0] / 2, 0.0, floor + WALL[2] / 2], **wall},
    ]
    doc["excitation"] = {"kind": "pick-and-place", "start": 0.1, "moves": [
        {"displacement": [0.0, 0.0, LIFT], "rotation": [0.0, TILT, 0.0], "duration": lifting},
        {"displacement": [CARRY, 0.0, 0.0], "duration": carrying},
        {"displacement": [0.0, 0.0, -(LIFT + DROP + PRESS)], "rotation": [0.0, -TILT, 0.0], "duration": lowering}]}
    doc["solver"] = {**doc["solver"], "t_end": round(0.1 + lifting + carrying + lowering + 0.6, 3)}
    return doc


if __name__ == "__main__":
    for name, durations in (("setdown_fast", (0.4, 0.4, 0.25)), ("setdown_gentle", (0.8, 1.0, 1.0))):
        path = HERE / f"{name}.toml"
        path.write_text("# written by scripts/setdown_scenes.py (a 20-berry cluster set down into a padded crate)\n"
                        + dumps(scene(*durations, name)),
                        encoding="utf-8")
        print(f"wrote {path}")
