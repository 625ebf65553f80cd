"""The damage and detachment predicates (docs/parameters.md gives the thresholds' sources).

Compiled so that the solver's live counters and every table of impacts test exactly the same thing;
each works on numbers and on arrays alike."""
from __future__ import annotations

from .compiled import inline


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
