"""Where each quantity sits in the state vector y.

y = [q (N) | q̇ (N) | hinge dissipation (N) | coupling dissipation (C) | contact dissipation (P)
     | contact impulse ∫F dt (P) | base work (1) | base velocity (2) | base displacement (2)]

The energy integrals ride along in y so that the same error control that keeps the
angles accurate keeps the energy ledger closed.
"""
from __future__ import annotations

from typing import NamedTuple


class Layout(NamedTuple):
    n: int
    c: int
    p: int
    q: slice
    w: slice
    d_hinge: slice
    d_coupling: slice
    d_contact: slice
    impulse: slice
    work: int
    base_velocity: slice
    base: slice
    size: int


def layout(n: int, c: int, p: int) -> Layout:
    o = 3 * n + c + 2 * p
    return Layout(n, c, p, slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n), slice(3 * n, 3 * n + c),
                  slice(3 * n + c, 3 * n + c + p), slice(3 * n + c + p, o), o, slice(o + 1, o + 3),
                  slice(o + 3, o + 5), o + 5)
