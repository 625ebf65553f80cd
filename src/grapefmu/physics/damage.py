"""The damage and detachment predicates (docs/parameters.md gives the thresholds' sources).

Compiled so that the solver's live counters and every table of impacts test exactly the same thing;
each works on numbers and on arrays alike."""
from __future__ import annotations

import numpy as np

from .compiled import inline, jit


@inline
def bruising(peak_force, dissipated, bruise_force, bruise_energy):
    """An impact bruises when its peak force or the energy it dissipates reaches the threshold."""
    return (peak_force >= bruise_force) | (dissipated >= bruise_energy)


@inline
def fatigue(peak_force, bruise_force, fatigue_fraction):
    """An impact counts toward fatigue above a fraction of the bruise force."""
    return peak_force >= fatigue_fraction * bruise_force


@inline
def detaching(tension, detachment_force):
    """A pedicel tension above the detachment force detaches the berry."""
    return tension > detachment_force


@inline
def bruise_thresholds(M, pr, scene_force, scene_energy):
    """(force N, energy J) at which an impact of contact pair pr bruises: the scene's between two berries,
    the obstacle's own against an obstacle."""
    nb = M.berry.shape[0]
    if pr.j < nb:
        return scene_force, scene_energy
    ob = M.obstacle[pr.j - nb]
    return ob.bruise_force, ob.bruise_energy


@jit
def pair_bruise_thresholds(M, scene_force, scene_energy):
    """(P, 2): bruise_thresholds of every pair, for tables of impacts made outside the solver."""
    out = np.empty((M.pair.shape[0], 2))
    for p in range(M.pair.shape[0]):
        out[p, 0], out[p, 1] = bruise_thresholds(M, M.pair[p], scene_force, scene_energy)
    return out
