"""How many island systems (solver/islands.py `_System`: an island's compiled side, made for a shape not seen free
before) a cluster's islands run makes, and how many it would make if systems were pooled more coarsely: by berries
and angles (any number of pairs and couplings, room for the most), or by berries alone. Replays the run's sequence
of islands formed and retired (Scale section's pick-and-place cluster, rtol 1e-6, 1 s). Fewer systems pooled by
capacity than by exact shape would mean islands differ in shape; about as many means islands live side by side.
Run: .venv/bin/python benchmarks/island_systems.py [N ...]"""
from __future__ import annotations

import collections
import sys

from grapefmu.bench.scale import scene
from grapefmu.solver import islands as isl


def events(n: int) -> list[tuple[str, tuple[int, int, int, int]]]:
    """("form" | "retire", the system's shape (berries, angles, couplings, pairs)) in the order the run made them."""
    out = []
    islands, retire = isl.Islands._islands, isl.Islands._retire

    def formed(self, *args):
        segs, formation = islands(self, *args)
        out.extend(("form", seg.system.shape) for seg in segs)
        return segs, formation

    def retired(self, segs, *args):
        out.extend(("retire", seg.system.shape) for seg in segs)
        return retire(self, segs, *args)

    isl.Islands._islands, isl.Islands._retire = formed, retired
    try:
        isl.Islands(scene("cluster", n)).run()
    finally:
        isl.Islands._islands, isl.Islands._retire = islands, retire
    return out


def made(seq, key) -> int:
    """Systems a pool keyed by key(shape) makes over the sequence."""
    free: collections.Counter = collections.Counter()
    count = 0
    for kind, shape in seq:
        k = key(shape)
        if kind == "retire":
            free[k] += 1
        elif free[k]:
            free[k] -= 1
        else:
            count += 1
    return count


def main(sizes: list[int]) -> None:
    for n in sizes:
        seq = events(n)
        formed = sum(kind == "form" for kind, _ in seq)
        print(f"{n}-berry cluster: {formed} islands formed; systems made pooled by exact shape "
              f"{made(seq, lambda s: s)}, by berries and angles {made(seq, lambda s: s[:2])}, "
              f"by berries {made(seq, lambda s: s[0])}")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [100, 300])
