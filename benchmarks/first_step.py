"""How a run starts (docs/solver.md, "The first step"): for each benchmark scene and each scene in scenes/ of at most
12 berries, at rtol 1e-3, 1e-6, 1e-9 and 1e-12 (atol rtol/100, as `grapefmu bench`): the first accepted step, the
trials rejected before it, and the whole run's accepted steps and rejections (to the scene's end, at most 2 s).
Run under two versions to compare them: PYTHONPATH=<other checkout>/src .venv/bin/python benchmarks/first_step.py
Run: .venv/bin/python benchmarks/first_step.py"""
from __future__ import annotations

import glob

from grapefmu.bench.scenes import bench_scenes, build
from grapefmu.scenefile import load_scene
from grapefmu.solver.solver import Solver

RTOLS = (1e-3, 1e-6, 1e-9, 1e-12)


def main() -> None:
    scenes = {name: build(doc) for name, doc in bench_scenes().items()}
    scenes |= {f: load_scene(f) for f in sorted(glob.glob("scenes/**/*.toml", recursive=True))}
    print("| scene | rtol | first step (s) | rejected before it | steps | rejected |")
    print("|---|---|---|---|---|---|")
    totals = [0, 0, 0]
    for name, sc in scenes.items():
        if sc.model.n_berries > 12:
            continue
        for rtol in RTOLS:
            s = Solver(sc, rtol=rtol, atol=rtol * 1e-2)
            s.step()
            first, before = s.t, s.stats["rejected"]
            s.run(min(sc.solver.t_end, 2.0), 1e-3)
            st = s.stats
            totals[0] += before
            totals[1] += st["steps"]
            totals[2] += st["rejected"]
            print(f"| {name} | {rtol:g} | {first:.3g} | {before} | {st['steps']} | {st['rejected']} |")
    print(f"all: {totals[0]} trials rejected before a first step, {totals[1]} steps, {totals[2]} rejected")


if __name__ == "__main__":
    main()
