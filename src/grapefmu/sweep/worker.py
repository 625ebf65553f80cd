"""One run of a sweep, as a row. Importable by worker processes and Dask workers alike."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ..errors import GrapefmuError

#: the row's result columns, in order (inputs come first, one column per swept key)
RESULT_COLUMNS = ("status", "collision_count", "peak_contact_force_n", "peak_pedicel_force_n",
                  "n_berries_over_detachment_force", "detachment_risk", "bruising_impacts", "fatigue_impacts",
                  "max_impact_energy_j", "energy_dissipated_j", "max_dissipated_per_berry_j", "max_active_pairs",
                  "steps", "wall_time_s")


def run_one(run_id: int, doc: dict[str, Any], base_dir: str) -> dict[str, Any]:
    """Simulate one scene document; a scene the validator refuses, or a run the solver cannot finish,
    becomes a row whose status says why (nothing is lost, the sweep goes on)."""
    from ..model.scene import scene_from_dict
    from ..solver.api import simulate

    row: dict[str, Any] = {"run_id": run_id}
    wall = time.perf_counter()
    try:
        run = simulate(scene_from_dict(doc, Path(base_dir)))
    except GrapefmuError as e:
        row.update({c: None for c in RESULT_COLUMNS})
        row["status"] = f"error: {e}"
        row["wall_time_s"] = time.perf_counter() - wall
        return row
    s = run.summary()
    row.update({"status": "ok", "collision_count": s["collision_count"], "peak_contact_force_n": s["peak_contact_force"],
                "peak_pedicel_force_n": s["peak_pedicel_force"],
                "n_berries_over_detachment_force": s["n_berries_over_detachment_force"],
                "detachment_risk": s["detachment_risk"], "bruising_impacts": s["bruising_impacts"],
                "fatigue_impacts": s["fatigue_impacts"], "max_impact_energy_j": s["max_impact_energy"],
                "energy_dissipated_j": s["energy_dissipated"], "max_dissipated_per_berry_j": s["max_dissipated_per_berry"],
                "max_active_pairs": s["max_active_pairs"], "steps": s["steps"],
                "wall_time_s": time.perf_counter() - wall})
    return row
