"""One run of a sweep, as a row. Importable by worker processes and Dask workers alike."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ..errors import GrapefmuError

#: the row's result columns, in order (inputs come first, one column per swept key): `Run.summary()` keys, which
#: carry their units as suffixes (`peak_contact_force_n`), with `warnings` (results/trust.py: why a row's results
#: cannot be trusted, one line each), then the row's own status and times
SUMMARY_COLUMNS = ("collision_count", "peak_contact_force_n", "peak_pedicel_tension_n", "berries_over_detachment_force",
                   "detachment_risk", "bruising_impacts", "fatigue_impacts", "max_impact_energy_j",
                   "dissipated_energy_j", "max_dissipated_per_berry_j", "max_active_pairs", "steps",
                   "bruised_berries", "detached_berries", "warnings")
#: wall_time_s: the solver alone; compile_time_s: numba's compile or cache load, paid by a worker's first run
RESULT_COLUMNS = ("status", *SUMMARY_COLUMNS, "wall_time_s", "compile_time_s")


def run_one(run_id: int, doc: dict[str, Any], base_dir: str) -> dict[str, Any]:
    """Simulate one scene document; a scene the validator refuses, or a run the solver cannot finish,
    becomes a row whose status says why (nothing is lost, the sweep goes on)."""
    from ..scenefile import scene_from_dict
    from ..solver.api import simulate
    from ..solver.warmup import prepare

    row: dict[str, Any] = {"run_id": run_id}
    compile_s = 0.0
    wall = time.perf_counter()
    try:
        scene = scene_from_dict(doc, Path(base_dir))
        compile_s = prepare(scene, say=False).seconds  # 0 after this worker's first run
        wall = time.perf_counter()
        run = simulate(scene)
    except Exception as e:  # noqa: BLE001 - ours says why; anything else is a bug, kept in its row, not the sweep's end
        why = str(e) if isinstance(e, GrapefmuError) else f"{type(e).__name__}: {e} (a grapefmu bug: please report it)"
        row.update({c: None for c in RESULT_COLUMNS})
        row.update(status=f"error: {why}", wall_time_s=time.perf_counter() - wall, compile_time_s=compile_s)
        return row
    s = run.summary()
    row.update({"status": "ok", **{col: s[col] for col in SUMMARY_COLUMNS},
                "wall_time_s": time.perf_counter() - wall, "compile_time_s": compile_s})
    return row
