"""Compare this checkout's solver with another version of grapefmu: trajectories and cost, interleaved.

    git worktree add /tmp/grapefmu-old <rev>
    .venv/bin/python benchmarks/compare_versions.py --old /tmp/grapefmu-old [--repeats 5] [--quick]

Two worker processes, one per version (the other version's `src` first on its path), get the same
requests in turn, so both run on the same machine state:
- every scene in scenes/ (the paper's tests included) and every benchmark scene at rtol 1e-10
  (atol 1e-12): the largest angle difference between the versions on the output grid, the largest relative
  difference in a berry's peak pedicel tension, and, where both versions book the same impacts, the largest
  difference in their onsets, peak forces and peak times;
- every benchmark scene over the benchmark's rtol ladder: wall time per simulated second (minimum of
  --repeats, the two versions alternating) and the cost at 1e-6 rad interpolated on each version's own
  work–precision curve against the new version's rtol 1e-13 reference, as `grapefmu bench` does.
Prints one table; exits 1 if any trajectory differs by more than 1e-9 rad."""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LADDER = [10.0 ** -k for k in range(3, 13)]

WORKER = r'''
import json, sys, time, glob, math
import numpy as np
import grapefmu
from grapefmu.bench.scenes import bench_scenes, build

def scenes(root):
    out = {}
    for p in sorted(glob.glob(f"{root}/scenes/**/*.toml", recursive=True)):
        try:
            out[p.split("/scenes/", 1)[1]] = grapefmu.load_scene(p)
        except grapefmu.GrapefmuError:  # a scene this version cannot read (a newer key): reported as missing
            pass
    for k, d in bench_scenes().items():
        out[f"bench: {k}"] = build(d)
    return out

S = scenes(sys.argv[1])
print(json.dumps({"ready": sorted(S)}), flush=True)
for line in sys.stdin:
    req = json.loads(line)
    sc = S[req["scene"]]
    if req["op"] == "trajectory":
        run = grapefmu.simulate(sc, rtol=req["rtol"], atol=req["rtol"] * 1e-2, output_interval=1e-3)
        imp = run.impacts
        np.savez(req["file"], y=np.column_stack([run.t, run.angles]), onset=imp.onset, peak_force=imp.peak_force,
                 peak_time=imp.peak_time, peak_tension=run.peak_tension)
        print(json.dumps({"ok": True}), flush=True)
    else:
        t0 = time.perf_counter()
        run = grapefmu.simulate(sc, rtol=req["rtol"], atol=req["rtol"] * 1e-2, output_interval=1e-3)
        wall = time.perf_counter() - t0
        np.save(req["file"], run.angles)
        print(json.dumps({"wall": wall, "t_end": float(run.t[-1])}), flush=True)
'''


class Worker:
    def __init__(self, src: Path, label: str):
        env = {**os.environ, "PYTHONPATH": str(src)}
        self.label = label
        self.p = subprocess.Popen([sys.executable, "-c", WORKER, str(ROOT)], stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, text=True, env=env, cwd="/")
        self.scenes = json.loads(self.p.stdout.readline())["ready"]

    def ask(self, **req):
        self.p.stdin.write(json.dumps(req) + "\n")
        self.p.stdin.flush()
        return json.loads(self.p.stdout.readline())


def cost_at(points, target=1e-6):
    pts = sorted(p for p in points if p[0] > 0 and math.isfinite(p[0]))
    for (e1, c1), (e2, c2) in zip(pts, pts[1:]):
        if e1 <= target <= e2:
            w = (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1)) if e2 > e1 else 0.0
            return math.exp(math.log(c1) + w * (math.log(c2) - math.log(c1)))
    return math.nan


def main() -> int:
    import tempfile

    import numpy as np

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="checkout of the other version (its src/ is used)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="trajectories only, no timing")
    a = ap.parse_args()
    new, old = Worker(ROOT / "src", "new"), Worker(Path(a.old) / "src", "old")
    tmp = Path(tempfile.mkdtemp())
    worst = 0.0
    print(f"{'scene':<40} {'max |Δ angle| at rtol 1e-10 (rad)':>34} {'Δ peak tension (rel)':>21} {'impacts':>8} "
          f"{'|Δ onset| (s)':>14} "
          f"{'Δ peak force (rel)':>19} {'|Δ peak time| (s)':>18}")
    for name in new.scenes:
        if name not in old.scenes:
            print(f"{name:<40} {'(the old version cannot read it)':>34}")
            continue
        f_new, f_old = tmp / "n.npz", tmp / "o.npz"
        new.ask(op="trajectory", scene=name, rtol=1e-10, file=str(f_new))
        old.ask(op="trajectory", scene=name, rtol=1e-10, file=str(f_old))
        rn, ro = np.load(f_new), np.load(f_old)
        yn, yo = rn["y"], ro["y"]
        d = float(np.abs(yn - yo).max()) if yn.shape == yo.shape else math.inf
        worst = max(worst, d)
        tn, to = rn["peak_tension"], ro["peak_tension"]  # each berry's
        dt = float((np.abs(tn - to) / np.maximum(np.abs(to), 1e-300)).max()) if tn.shape == to.shape else math.inf
        n = len(rn["onset"])
        if n != len(ro["onset"]):
            impacts = f"{n} / {len(ro['onset'])}: the versions' impact counts differ"
        elif n == 0:
            impacts = f"{0:>8}"
        else:
            rel = np.abs(rn["peak_force"] - ro["peak_force"]) / np.maximum(np.abs(ro["peak_force"]), 1e-300)
            impacts = (f"{n:>8} {np.abs(rn['onset'] - ro['onset']).max():>14.2e} {rel.max():>19.2e} "
                       f"{np.abs(rn['peak_time'] - ro['peak_time']).max():>18.2e}")
        print(f"{name:<40} {d:>34.3e} {dt:>21.2e} {impacts}", flush=True)
    print(f"largest difference: {worst:.3e} rad (bound 1e-9)")
    if not a.quick:
        print(f"\n{'benchmark scene':<28} {'old ms/s @1e-6':>15} {'new ms/s @1e-6':>15} {'new/old':>8}"
              f" {'new/old wall, same rtol (median over ladder)':>45}")
        for name in [s for s in new.scenes if s.startswith("bench: ")]:
            ref = tmp / "ref.npy"
            new.ask(op="time", scene=name, rtol=1e-13, file=str(ref))
            r = np.load(ref)
            pts = {"old": [], "new": []}
            ratios = []
            for rtol in LADDER:
                best = {"old": math.inf, "new": math.inf}
                err = {}
                for _ in range(a.repeats):
                    for w in (old, new):
                        f = tmp / f"{w.label}.npy"
                        out = w.ask(op="time", scene=name, rtol=rtol, file=str(f))
                        best[w.label] = min(best[w.label], out["wall"] / out["t_end"])
                        y = np.load(f)
                        err[w.label] = float(np.abs(y - r).max()) if y.shape == r.shape else math.inf
                for k in ("old", "new"):
                    pts[k].append((err[k], best[k]))
                ratios.append(best["new"] / best["old"])
            co, cn = cost_at(pts["old"]), cost_at(pts["new"])
            print(f"{name[7:]:<28} {1e3 * co:>15.4f} {1e3 * cn:>15.4f} {cn / co:>8.3f} {float(np.median(ratios)):>45.3f}",
                  flush=True)
    return 0 if worst <= 1e-9 else 1


if __name__ == "__main__":
    sys.exit(main())
