"""The kinematics' sin and cos (physics/kinematics.sincos, docs/solver.md "sin and cos from a table") against libm's,
each in the same compiled loop over 200 angles of a swinging berry (|x| ≤ 0.5 rad), minimum of several repeats,
interleaved: ns per angle, both values.
Run: .venv/bin/python benchmarks/sincos.py"""
from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from grapefmu.physics.kinematics import sincos


@njit
def table(x, out):
    for _ in range(100):
        for i in range(x.shape[0]):
            s, c = sincos(x[i])
            out[i, 0] += s
            out[i, 1] += c


@njit
def libm(x, out):
    for _ in range(100):
        for i in range(x.shape[0]):
            s, c = math.sin(x[i]), math.cos(x[i])
            out[i, 0] += s
            out[i, 1] += c


def main() -> None:
    x = np.random.default_rng(1).uniform(-0.5, 0.5, 200)
    out = np.zeros((200, 2))
    best = {f.__name__: np.inf for f in (table, libm)}
    for f in (table, libm):
        f(x, out)  # compiled
    for _ in range(5):
        for f in (table, libm):
            for _ in range(20):
                t = time.perf_counter()
                f(x, out)
                best[f.__name__] = min(best[f.__name__], (time.perf_counter() - t) / (100 * x.shape[0]))
    print(f"sin and cos of one angle: table {1e9 * best['table']:.1f} ns, libm {1e9 * best['libm']:.1f} ns "
          f"({best['libm'] / best['table']:.2f}x)")


if __name__ == "__main__":
    main()
