"""How deep the shipped and benchmark scenes press their pairs: the deepest overlap at a sample over each pair's
bound (the smaller radius, a berry's own against an obstacle), against MAX_OVERLAP_FRACTION, beyond which a run is
warned (results/trust.py, overlap_warning). docs/reliability.md quotes the deepest.
Run: .venv/bin/python benchmarks/overlap_depths.py"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import grapefmu
from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.model.model import MAX_OVERLAP_FRACTION
from grapefmu.scenefile import load_scene

SHIPPED = Path(grapefmu.__file__).parent / "scenes"


def deepest(run) -> tuple[float, str]:
    """(δ / radius, pair name) of the run's deepest overlap at a sample."""
    m = run.scene.model
    if not len(m.pairs):
        return 0.0, "-"
    q = (run.penetration / m.contact_radius).max(axis=0)
    p = int(np.argmax(q))
    return float(q[p]), m.pair_name(p)


def main() -> None:
    scenes = {name: build(spec) for name, spec in bench_scenes().items()}
    scenes |= {str(f.relative_to(SHIPPED)): load_scene(f) for f in sorted(SHIPPED.rglob("*.toml"))}
    print(f"deepest overlap at a sample, over the pair's radius (warned beyond {MAX_OVERLAP_FRACTION:g})")
    for name, sc in scenes.items():
        ratio, pair = deepest(grapefmu.simulate(sc))
        print(f"  {name:28s} {ratio:6.3f}  {pair}")


if __name__ == "__main__":
    main()
