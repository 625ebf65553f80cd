"""How small a cluster's interacting groups are over a time window (the case for multirate islands, issue 14 item 4):
runs the Scale section's cluster (pick-and-place, rtol 1e-6, 1 s) and, for each window of H seconds, joins two
berries whose gap came within `--reach` of closing at some 1 ms sample of the window; prints the largest group's
size (mean and most over the windows) and the groups of more than one berry.
Run: .venv/bin/python benchmarks/islands.py [N] [--reach 2e-4]"""
from __future__ import annotations

import argparse

import numpy as np

import grapefmu
from grapefmu.bench.scale import scene
from grapefmu.physics.kinematics import penetrations


def groups(n: int, links: np.ndarray) -> np.ndarray:
    """Each berry's group (its smallest member) for berry pairs `links` (K, 2)."""
    parent = np.arange(n)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in links:
        a, b = root(i), root(j)
        if a != b:
            parent[max(a, b)] = min(a, b)
    return np.array([root(i) for i in range(n)])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("n", nargs="?", type=int, default=100)
    ap.add_argument("--reach", type=float, default=2e-4, help="m: a gap this close to closing joins two berries")
    a = ap.parse_args()
    sc = scene("cluster", a.n)
    run = grapefmu.simulate(sc)
    berry_pairs = np.array([(p.i, p.j) for p in sc.model.pairs if p.j < a.n])
    pen = np.empty((len(run.t), len(sc.model.pairs)))
    for k in range(len(run.t)):
        penetrations(run.y[k], sc.model.arrays, pen[k])
    pen = pen[:, [k for k, p in enumerate(sc.model.pairs) if p.j < a.n]]
    print(f"{a.n}-berry cluster, {run.t[-1]:g} s: {run.stats['steps']} steps, {len(run.impacts.onset)} impacts")
    for window in (0.005, 0.01, 0.02, 0.05):
        w = round(window / 1e-3)
        largest, multi, sizes = [], [], []
        for s in range(0, len(run.t) - 1, w):
            close = pen[s:s + w + 1].max(axis=0) > -a.reach
            _, counts = np.unique(groups(a.n, berry_pairs[close]), return_counts=True)
            largest.append(counts.max())
            multi.append((counts > 1).sum())
            sizes.extend(counts[counts > 1])
        print(f"  windows of {window * 1e3:g} ms: largest group {np.mean(largest):.1f} berries on average "
              f"({max(largest)} at most); {np.mean(multi):.1f} groups of more than one berry, "
              f"{np.mean(sizes) if sizes else 0:.1f} berries each; the rest alone")


if __name__ == "__main__":
    main()
