"""The records a run reports, as the compiled solver writes them: finished impacts, the totals of what the
run has done to the berries so far (every face reports the same totals), and the solver's work counters."""
from __future__ import annotations

import math

import numpy as np

#: a finished impact, from the pair's first touch (δ = 0, closing) to its separation
IMPACT = np.dtype([("pair", "i8"), ("onset", "f8"), ("end", "f8"), ("approach_speed", "f8"), ("peak_force", "f8"),
                   ("peak_time", "f8"), ("impulse", "f8"), ("dissipated", "f8"), ("separation_speed", "f8"),
                   ("bruising", "?")])
#: so far: impacts begun, impacts that bruise, berries whose pedicel tension passed the detachment force,
#: and the largest contact force and pedicel tension (refined on the dense output)
TOTALS = np.dtype([("collision_count", "i8"), ("bruising_impacts", "i8"), ("berries_over_detachment_force", "i8"),
                   ("peak_contact_force", "f8"), ("peak_pedicel_tension", "f8")])
#: a run's work as the compiled loop counts it: Run.stats holds each under its name, near_pairs_sum as
#: near_pairs_mean (near pairs per step)
COUNTERS = np.dtype([("steps", "i8"), ("rejected", "i8"), ("rhs_evaluations", "i8"), ("switches", "i8"),
                     ("zeno_guard_activations", "i8"), ("near_pairs_sum", "i8"), ("near_list_rebuilds", "i8"),
                     ("quiet_steps", "i8"), ("spared_steps", "i8")])
#: the counters Run.stats holds as counted (they add up over parts of a scene run apart)
WORK = tuple(f for f in COUNTERS.names if f != "near_pairs_sum")
#: TOTALS over parts of a scene (islands, groups): the counts add up, the peaks take the largest
COUNTS = tuple(f for f in TOTALS.names if TOTALS[f].kind == "i")
PEAKS = tuple(f for f in TOTALS.names if TOTALS[f].kind == "f")


def concat(arrays) -> np.ndarray:
    """np.concatenate along the first axis for record arrays of one dtype, through bytes: numpy promotes
    record dtypes field by field on every call, which costs more than a short run's whole integration."""
    if len(arrays) == 1:
        return arrays[0]
    arrays = [np.ascontiguousarray(a) for a in arrays]
    dtype, tail = arrays[0].dtype, arrays[0].shape[1:]
    if not dtype.names:
        return np.concatenate(arrays)
    row = dtype.itemsize * math.prod(tail)
    raw = np.concatenate([a.view(np.uint8).reshape(len(a), row) for a in arrays])
    if row == 0:
        return np.zeros((len(raw), *tail), dtype)
    return raw.view(dtype).reshape((len(raw), *tail))
