"""A Foxglove Studio layout for grapefmu's topics: a 3D panel (TF frames, URDF, berries, twigs and contact
arrows) beside plots of the angles, contact force, pedicel tension and dissipated energy.

`recordings/grapefmu.foxglove.json` is layout(default scene); open a recording in Foxglove, then
Layouts → Import from file. Regenerate it with
`.venv/bin/python -m grapefmu.recording.foxglove recordings/grapefmu.foxglove.json`."""
from __future__ import annotations

from ..model.model import Model
from .messages import absolute, wrench_topics


def _plot(title: str, paths: list[tuple[str, str]]) -> dict:
    return {"title": title, "paths": [{"value": v, "enabled": True, "timestampMethod": "headerStamp", "label": label}
                                      for v, label in paths],
            "showLegend": True, "legendDisplay": "floating", "isSynced": True}


def layout(model: Model) -> dict:
    js, tension = absolute("joint_states"), absolute("pedicel_tension")
    summary = absolute("summary")
    angles = [(f"{js}.position[{k}]", f"{d} (rad)") for k, d in enumerate(model.dof_names)]
    tensions = [(f"{tension}.tension[{k}]", f"{b} (N)") for k, b in enumerate(model.names)]
    forces = ([(f"{absolute(t)}.wrench.force.x", f"{t.split('/')[1]} x (N)") for t in wrench_topics(model)]
              or [(f"{summary}.max_contact_force", "largest contact force (N)")])
    energy = [(f"{summary}.dissipated_energy", "dissipated (J)")]
    config = {
        "3D!grapes": {"followTf": "world", "scene": {"transforms": {"showLabel": False}},
                      "topics": {absolute("markers"): {"visible": True},
                                 absolute("robot_description"): {"visible": True}},
                      "layers": {"grid": {"layerId": "foxglove.Grid", "visible": True, "size": 1, "divisions": 20}},
                      "cameraState": {"distance": 0.4, "targetOffset": [0, 0, 0], "thetaOffset": 45, "phi": 60}},
        "Plot!angles": _plot("Twig angles", angles),
        "Plot!force": _plot("Contact force", forces),
        "Plot!tension": _plot("Pedicel tension", tensions),
        "Plot!energy": _plot("Energy dissipated", energy),
    }
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1.0},
            "layout": {"direction": "row", "first": "3D!grapes", "splitPercentage": 50,
                       "second": {"direction": "column",
                                  "first": {"direction": "column", "first": "Plot!angles", "second": "Plot!force"},
                                  "second": {"direction": "column", "first": "Plot!tension", "second": "Plot!energy"}}}}


def topics(layout_: dict) -> set[str]:
    """Every topic a layout names (plot paths and 3D topics)."""
    out = set()
    for cfg in layout_["configById"].values():
        out |= {p["value"].split(".", 1)[0] for p in cfg.get("paths", [])}
        out |= set(cfg.get("topics", {}))
    return out


if __name__ == "__main__":
    import json
    import sys

    from ..scenefile import default_scene_path, load_scene

    with open(sys.argv[1], "w", encoding="utf-8") as f:
        json.dump(layout(load_scene(default_scene_path()).model), f, indent=2)
        f.write("\n")
