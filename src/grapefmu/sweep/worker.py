"""One run of a sweep, as a row. Importable by worker processes and Dask workers alike."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ..errors import GrapefmuError

#: the row's result columns, in order (inputs come first, one column per swept key)
#: summary key -> column (units as suffixes); status and wall_time_s are the row's own
SUMMARY_COLUMNS = {"collision_count": "collision_count", "peak_contact_force": "peak_contact_force_n",
                   "peak_pedicel_tension": "peak_pedicel_tension_n",
                   "berries_over_detachment_force": "berries_over_detachment_force",
                   "detachment_risk": "detachment_risk", "bruising_impacts": "bruising_impacts",
                   "fatigue_impacts": "fatigue_impacts", "max_impact_energy": "max_impact_energy_j",
                   "dissipated_energy": "dissipated_energy_j", "max_dissipated_per_berry": "max_dissipated_per_berry_j",
                   "max_active_pairs": "max_active_pairs", "steps": "steps"}
RESULT_COLUMNS = ("status", *SUMMARY_COLUMNS.values(), "wall_time_s")


def run_one(run_id: int, doc: dict[str, Any], base_dir: str) -> dict[str, Any]:
    """Simulate one scene document; a scene the validator refuses, or a run the solver cannot finish,
    becomes a row whose status says why (nothing is lost, the sweep goes on)."""
    from ..scenefile import scene_from_dict
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
    row.update({"status": "ok", **{col: s[key] for key, col in SUMMARY_COLUMNS.items()},
                "wall_time_s": time.perf_counter() - wall})
    return row
