"""Islands against one step size on scenes the tests do not run in islands (docs/solver.md "Multirate islands"): the
set-down scenes (a turning rachis, the crate's obstacles), cluster60, and the 30-berry cluster with Hertz contact
under step-size control (impacts booked at step ends, so the two ways book them at different times). Each scene runs
with `simulate` (one step size) and with `Islands(scene).run()` at the same tolerances; printed: impacts both ways and
how many pair up (same pair, in order), the largest onset and peak-force differences among them, the largest angle
difference on the output grid, and whether the counts of the last sample agree.
Run: .venv/bin/python benchmarks/islands_agree.py [--rtol 1e-6]"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import grapefmu
from grapefmu.bench.scale import scene as scale_scene
from grapefmu.results.records import COUNTS
from grapefmu.solver.islands import Islands

ROOT = Path(__file__).resolve().parents[1]


def scenes(rtol: float) -> dict:
    """The scenes by name (their own solver settings but for the tolerances, which main sets)."""
    out = {}
    for name in ("setdown_fast", "setdown_gentle", "cluster60"):
        out[name] = grapefmu.load_scene(ROOT / "scenes" / f"{name}.toml")
    out["cluster30 hertz step-control"] = scale_scene("cluster", 30, rtol, contact={"law": "hertz",
                                                      "effective_modulus": 1e6}, location="step-control")
    return out


def paired(a, b) -> tuple[int, float, float]:
    """Impacts of a and b matched per pair in order of onset: how many, the largest onset difference (s) and the
    largest relative peak-force difference."""
    n, d_on, d_peak = 0, 0.0, 0.0
    for p in np.union1d(a.pair, b.pair):
        ia, ib = np.flatnonzero(a.pair == p), np.flatnonzero(b.pair == p)
        ia, ib = ia[np.argsort(a.onset[ia])], ib[np.argsort(b.onset[ib])]
        for x, y in zip(ia, ib):
            n += 1
            d_on = max(d_on, abs(a.onset[x] - b.onset[y]))
            d_peak = max(d_peak, abs(a.peak_force[x] - b.peak_force[y]) / max(abs(b.peak_force[y]), 1e-12))
    return n, d_on, d_peak


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rtol", type=float, default=1e-6)
    a = ap.parse_args()
    print(f"rtol {a.rtol:g}: one step size (simulate) against Islands(scene).run()")
    print(f"{'scene':32s} {'impacts':>9s} {'paired':>6s} {'onsets (s)':>10s} {'peaks (rel)':>11s} "
          f"{'angles (rad)':>12s} {'counts':>6s} {'islands':>7s}")
    for name, sc in scenes(a.rtol).items():
        one = grapefmu.simulate(sc, rtol=a.rtol, atol=a.rtol * 1e-3)
        isl = Islands(sc, rtol=a.rtol, atol=a.rtol * 1e-3).run()
        n, d_on, d_peak = paired(isl.impacts, one.impacts)
        d_q = float(np.abs(isl.angles - one.angles).max())
        same = all(int(isl.totals[f][-1]) == int(one.totals[f][-1]) for f in COUNTS)
        print(f"{name:32s} {len(isl.impacts):>4d}/{len(one.impacts):<4d} {n:>6d} {d_on:>10.1e} {d_peak:>11.1e} "
              f"{d_q:>12.1e} {'same' if same else 'differ':>6s} {isl.stats['islands_formed']:>7d}")


if __name__ == "__main__":
    main()
