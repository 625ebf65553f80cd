"""Run every method on every scene, measure error against a reference that two independent solvers
agree on, and write a Markdown report with one work–precision plot per scene (out/bench unless told; the
committed docs/benchmarks.md and docs/bench are regenerated with --out docs/benchmarks.md --plots docs/bench).

Protocol (issue 5): reference = grapefmu at rtol 1e-13 checked against scipy DOP853 with events at 1e-13
(must agree to 1e-10 rad, or the scene is refused); error = largest angle error on the 1 ms grid, final
state error, impact count, impact-time and peak-force error; cost = wall time per simulated second, the
minimum of several rounds that run each method and setting of a scene once in turn, after a warm-up round (numba
compile measured separately), and right-hand-side evaluations with their floor (evaluations × a bare compiled
evaluation's cost on the scene's states, bench/costs.py). The paper collision scene is also stepped from a face: advance(1 ms) against one run.
A failed run is a row that says why."""
from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..results.writers import atomic_path
from ..solver.api import simulate
from ..solver.reference import simulate_reference
from . import methods as M
from .costs import AdvanceCost, advance_cost, rhs_seconds
from .scenes import bench_scenes, build

AGREE = 1e-10


@dataclass
class Row:
    scene: str
    method: str
    setting: str
    cost: float          # wall s per simulated s
    error: float         # max angle error on the grid, rad
    final_error: float
    impacts: int | None
    ref_impacts: int
    onset_error: float
    peak_error: float
    rhs: int | None
    failure: str | None = None
    self_error: float = math.nan  # MuJoCo: against its own finest step
    floor: float = math.nan       # RHS evaluations × a bare evaluation's cost, s per simulated s

    @property
    def over_floor(self) -> float:
        return self.cost / self.floor if self.floor > 0 else math.nan


#: the methods that evaluate grapefmu's compiled right-hand side (the others have no RHS floor)
OWN_RHS = ("grapefmu", "paper", "scipy")


def plan(quick: bool):
    if quick:
        return [("grapefmu event", [1e-3, 1e-6, 1e-9, 1e-11], lambda s, v: M.grapefmu_event(s, v), "rtol"),
                ("paper (ode23 check at step ends)", [1e-3, 1e-4], lambda s, v: M.paper_fixed(s, v), "h"),
                ("scipy DOP853+events", [1e-6], lambda s, v: M.scipy_events(s, "DOP853", v), "rtol"),
                ("scipy DOP853 lean", [1e-5, 1e-7, 1e-9, 1e-11], lambda s, v: M.scipy_lean(s, "DOP853", v), "rtol")]
    p = [("grapefmu event", [10.0 ** -k for k in range(3, 13)], lambda s, v: M.grapefmu_event(s, v), "rtol"),
         ("paper (ode23 check at step ends)", [1e-3, 3e-4, 1e-4, 3e-5, 1e-5], lambda s, v: M.paper_fixed(s, v), "h")]
    for integ in ("DOP853", "RK45", "LSODA"):  # the lean driver (bench/lean.py): DOP853 and the best others
        p.append((f"scipy {integ} lean", [10.0 ** -k for k in range(4, 13)] if integ == "DOP853" else
                  [1e-4, 1e-6, 1e-8, 1e-10, 1e-12], lambda s, v, i=integ: M.scipy_lean(s, i, v), "rtol"))
    for integ in ("DOP853", "RK45", "LSODA", "Radau"):
        p.append((f"scipy {integ}+events", [1e-4, 1e-7, 1e-10], lambda s, v, i=integ: M.scipy_events(s, i, v), "rtol"))
    for integ in ("Euler", "implicitfast", "RK4"):
        p.append((f"MuJoCo {integ}", [1e-3, 1e-4, 1e-5], lambda s, v, i=integ: M.mujoco_run(s, i, v), "dt"))
    return p


def metrics(scene_name, method, setting, out, wall, ref, t_end) -> Row:
    if out.failure:
        return Row(scene_name, method, setting, math.nan, math.nan, math.nan, None, len(ref.impacts), math.nan,
                   math.nan, out.rhs, out.failure)
    n = min(len(out.angles), len(ref.angles))
    err = float(np.abs(out.angles[:n] - ref.angles[:n]).max()) if n == len(ref.angles) else math.inf
    fin = float(np.abs(out.final - np.r_[ref.angles[-1], ref.angular_velocities[-1]]).max())
    onset_err = math.nan
    if out.onsets is not None and len(out.onsets) and len(ref.impacts):
        onset_err = float(max(np.abs(ref.impacts.onset - o).min() for o in out.onsets))
    peak_ref = float(ref.peak_force.max()) if ref.peak_force.size else 0.0
    peak_err = abs(out.peak_force - peak_ref) if not math.isnan(out.peak_force) else math.nan
    return Row(scene_name, method, setting, wall / t_end, err, fin, None if out.onsets is None else len(out.onsets),
               len(ref.impacts), onset_err, peak_err, out.rhs)


def _setting(r: Row) -> float:
    """The number of a row's setting ("rtol 1e-06", "h 0.001", "dt 0.0001": larger is looser), NaN if it has none."""
    try:
        return float(r.setting.split()[-1])
    except (ValueError, IndexError):
        return math.nan


def cost_at(rows: list[Row], target: float = 1e-6, key=lambda r: r.cost) -> float:
    """Wall time per simulated second (or `key` of the row, read at the same place) at `target` error on the
    method's work–precision curve: its settings in the order of the ladder (loosest first), the cheapest of a setting
    whose error is at most `target` and a log-log interpolation between two neighbouring settings whose errors
    bracket it. A setting that failed, or that booked another number of impacts than the reference (a missed or extra
    contact: no point of a smooth curve), is not interpolated from; nothing is extrapolated (NaN when no setting gets
    that close).

    Neighbours on the ladder, not on the sorted errors: a run that missed a contact can have a smaller error than
    a tighter one, or the same as a looser one, and sorting the points by error then brackets the target with
    settings whose neighbours in between did not reach it. The cheapest place is chosen by cost whatever `key` is:
    a floor or a ratio is read where the cost is, not at its own least."""
    rows = list(rows)
    values = [_setting(r) for r in rows]
    if all(math.isfinite(v) for v in values):  # else the rows' own order is the ladder's
        rows = [r for _, _, r in sorted(zip((-v for v in values), range(len(rows)), rows))]

    def point(r: Row) -> bool:
        return (not r.failure and math.isfinite(r.error) and r.error >= 0 and math.isfinite(r.cost) and r.cost > 0
                and math.isfinite(key(r)) and key(r) > 0 and (r.impacts is None or r.impacts == r.ref_impacts))

    best = (math.inf, math.nan)  # (cost, key) at the cheapest place found
    for r in rows:
        if point(r) and r.error <= target:
            best = min(best, (r.cost, key(r)))
    for a, b in zip(rows, rows[1:]):
        if not (point(a) and point(b) and a.error > 0 and b.error > 0):
            continue
        (e1, c1, k1), (e2, c2, k2) = sorted(((a.error, a.cost, key(a)), (b.error, b.cost, key(b))))
        if e1 < target < e2:
            w = (math.log(target) - math.log(e1)) / (math.log(e2) - math.log(e1))
            best = min(best, tuple(math.exp(math.log(x1) + w * (math.log(x2) - math.log(x1)))
                                   for x1, x2 in ((c1, c2), (k1, k2))))
    return best[1] if best[0] < math.inf else math.nan


def best_scipy(rows: list[Row], scene: str, target: float) -> tuple[float, str]:
    """The cheapest scipy driver's cost at `target` error on a scene, and its name (NaN, "" if none reaches it)."""
    costs = [(cost_at([r for r in rows if r.scene == scene and r.method == m], target), m)
             for m in dict.fromkeys(r.method for r in rows if r.method.startswith("scipy"))]
    return min(((c, m) for c, m in costs if c == c), default=(math.nan, ""))


def compile_seconds() -> tuple[float, float]:
    """First simulate() in a fresh process with an empty numba cache (compile), then in another with the cache the
    first filled (the checkout's own cache may be stale: then its "warm" run compiled too)."""
    code = ("import time; t = time.perf_counter(); import grapefmu; from grapefmu.scenefile import default_scene_path; "
            "grapefmu.simulate(grapefmu.load_scene(default_scene_path()), 0.1); print(time.perf_counter() - t)")
    out = []
    with tempfile.TemporaryDirectory() as d:
        env = {**os.environ, "NUMBA_CACHE_DIR": d}
        for _ in range(2):
            r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
            out.append(float(r.stdout.strip().splitlines()[-1]))
    return out[0], out[1]


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{os.cpu_count()} cores, {cpu}, Python {platform.python_version()}, {platform.system()}"


def run(quick: bool = False, repeats: int = 5, budget: float = 20.0, log=print):
    scenes = bench_scenes(quick)
    rows, refused, rhs_ns = [], {}, {}
    for name, doc in scenes.items():
        sc = build(doc)
        t_end = sc.solver.t_end
        log(f"[{name}] references ...")
        ref = simulate(sc, rtol=1e-13, atol=1e-15, output_interval=M.GRID)
        ref2 = simulate_reference(sc, rtol=1e-13, atol=1e-15, output_interval=M.GRID)
        agree = float(np.abs(ref.angles - ref2.angles).max())
        if not agree <= AGREE:
            refused[name] = agree
            log(f"[{name}] REFUSED: references differ by {agree:.3g} rad > {AGREE:g}")
            continue
        per_rhs = rhs_seconds(ref)
        rhs_ns[name] = 1e9 * per_rhs
        log(f"[{name}] bare RHS evaluation on the reference's states: {1e9 * per_rhs:.0f} ns")
        jobs = [(method, label, v, fn) for method, settings, fn, label in plan(quick) for v in settings
                if not (method.startswith("MuJoCo") and t_end / v > 3e6)]
        log(f"[{name}] {len(jobs)} methods and settings, interleaved over {1 if quick else repeats} rounds ...")
        timings = M.interleaved([functools.partial(fn, sc, v) for _, _, v, fn in jobs], 1 if quick else repeats,
                                budget)
        for (method, label, v, _), (out, wall) in zip(jobs, timings):
            rows.append(metrics(name, method, f"{label} {v:g}", out, wall, ref, t_end))
            r = rows[-1]
            if method.startswith(OWN_RHS) and r.rhs:
                r.floor = r.rhs * per_rhs / t_end
            log(f"[{name}] {method} {label}={v:g}: " + (f"FAILED {r.failure}" if r.failure else
                f"error {r.error:.2e} rad, {1e3 * r.cost:.3f} ms per simulated s"
                + (f", {r.over_floor:.1f}× its RHS floor" if r.floor > 0 else "")))
        if not quick:
            out, wall = M.fmu_fmpy(sc)
            row = metrics(name, "FMU via fmpy", "1 ms steps", out, wall, ref, t_end)
            row.final_error = math.nan
            rows.append(row)
            log(f"[{name}] FMU via fmpy: " + (f"FAILED {row.failure}" if row.failure else
                f"error {row.error:.2e} rad, {1e3 * row.cost:.3f} ms per simulated s"))
            finest = M.mujoco_run(sc, "implicitfast", 1e-6) if t_end / 1e-6 <= 3e6 else None
            for r in rows:
                if r.scene == name and r.method.startswith("MuJoCo") and not r.failure and finest is not None \
                        and not finest.failure:
                    integ, dt = r.method.split()[1], float(r.setting.split()[1])
                    mine = M.mujoco_run(sc, integ, dt)
                    r.self_error = float(np.abs(mine.angles - finest.angles).max())
        rows.extend(_agreement_row(name, agree))
    log("[paper collision] advance(1 ms) × 2000 against one run ...")
    adv = advance_cost(build(scenes["paper collision"]), repeats=3 if quick else 7)
    log(f"[paper collision] advance loop {1e3 * adv.advance:.3f} ms per simulated s, one run {1e3 * adv.run:.3f}, "
        f"fixed cost {1e6 * adv.fixed:.2f} µs per call")
    return rows, refused, rhs_ns, adv


def _agreement_row(name, agree):
    return [Row(name, "reference check", "grapefmu 1e-13 vs scipy DOP853 1e-13", math.nan, agree, math.nan, None, 0,
                math.nan, math.nan, None)]


def plot(rows: list[Row], out_dir: Path) -> list[Path]:
    from ..results.plot import pyplot
    plt = pyplot()
    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    for scene in dict.fromkeys(r.scene for r in rows):
        fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
        methods = dict.fromkeys(r.method for r in rows if r.scene == scene and r.method != "reference check")
        for k, method in enumerate(methods):
            pts = [(r.cost * 1e3, r.error) for r in rows if r.scene == scene and r.method == method and not r.failure
                   and r.error > 0 and math.isfinite(r.error)]
            if pts:  # ten colours, then the next ten methods dashed with squares
                ax.loglog(*zip(*sorted(pts)), marker="os^"[k // 10 % 3], ls=("-", "--", ":")[k // 10 % 3],
                          color=plt.cm.tab10(k % 10), label=method, ms=4)
        ax.axhline(1e-6, color="0.7", ls=":")
        ax.set_xlabel("wall time per simulated second (ms)")
        ax.set_ylabel("largest angle error on a 1 ms grid (rad)")
        ax.set_title(f"work–precision: {scene}")
        ax.legend(fontsize=7)
        path = out_dir / f"{scene.replace(' ', '_')}.png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=100, format="png")
        plt.close(fig)
        files.append(path)
    return files


def _fmt(x, fmt):
    return "—" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def _e(x: float) -> str:
    """An error target as the text writes it: 1e-6, not 1e-06."""
    return format(x, ".0e").replace("e-0", "e-")


def markdown(rows, refused, compile_s, command, plots, quick, rhs_ns, adv: AdvanceCost) -> str:
    f = _fmt
    lines = ["# Benchmarks: speed against error", "",
             f"Every figure below comes from `{command}` (date {datetime.date.today()}, machine: {machine()}).",
             "Cost: wall time per simulated second, the minimum of up to 5 rounds after a warm-up round, each round "
             "running every method and setting of the scene once in turn (interleaved, as issue 14 measures); error: "
             "largest "
             "twig-angle error on a 1 ms grid against grapefmu at rtol 1e-13, which must agree with scipy DOP853 with "
             "events at 1e-13 to 1e-10 rad or the scene is refused. RHS floor: the method's right-hand-side "
             "evaluations × one bare compiled evaluation on the scene's states (below); methods with their own "
             "physics (MuJoCo) or no count (FMU) have none.",
             ("numba compile: not measured in --quick." if math.isnan(compile_s[0]) else
              f"numba compile on a cold cache: {compile_s[0]:.1f} s for the first run; with the warm cache: "
              f"{compile_s[1]:.2f} s (import included). Not in the costs below."), ""]
    if refused:
        lines += [f"REFUSED (references disagree): {', '.join(f'{k} ({v:.2g} rad)' for k, v in refused.items())}", ""]
    methods = [m for m in dict.fromkeys(r.method for r in rows) if m != "reference check"]
    for target in (1e-6, 1e-10):
        lines += [f"## Summary: cost at {_e(target)} rad (interpolated on each work–precision curve)", "",
                  "| scene | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
        for scene in dict.fromkeys(r.scene for r in rows):
            base = cost_at([r for r in rows if r.scene == scene and r.method == "grapefmu event"], target)
            cells = []
            for m in methods:
                c = cost_at([r for r in rows if r.scene == scene and r.method == m], target)
                cells.append("not reached" if math.isnan(c) else f"{1e3 * c:.3g} ms ({c / base:.1f}×)" if base == base
                             else f"{1e3 * c:.3g} ms")
            lines.append(f"| {scene} | " + " | ".join(cells) + " |")
        lines += ["", "(×: ratio to grapefmu's cost at the same error.)", ""]
    lines += floors(rows, rhs_ns) + advance_section(adv) + targets(rows, adv)
    for scene in dict.fromkeys(r.scene for r in rows):
        lines += [f"## {scene}", "", f"![work–precision]({plots.get(scene, '')})", "",
                  "| method | setting | ms / sim s | max angle err (rad) | final err | impacts (ref) | onset err (s) | "
                  "peak force err (N) | RHS evals | RHS floor (ms / sim s) | wall / floor | note |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            if r.scene != scene:
                continue
            note = f"FAILED: {r.failure}" if r.failure else ("" if math.isnan(r.self_error) else
                                                           f"vs own finest step: {r.self_error:.2e} rad")
            lines.append(f"| {r.method} | {r.setting} | {f(1e3 * r.cost if r.cost == r.cost else None, '.3f')} | "
                         f"{f(r.error, '.2e')} | {f(r.final_error, '.2e')} | {f(r.impacts, 'd')} ({r.ref_impacts}) | "
                         f"{f(r.onset_error, '.1e')} | {f(r.peak_error, '.1e')} | {f(r.rhs, 'd')} | "
                         f"{f(1e3 * r.floor, '.3f')} | {f(r.over_floor, '.1f')} | {note} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def floors(rows: list[Row], rhs_ns: dict[str, float]) -> list[str]:
    """grapefmu against its RHS floor and against the best scipy driver, at 1e-6 and 1e-10 rad."""
    out = ["## grapefmu against its RHS floor and the best scipy driver", "",
           "Bare RHS: one compiled evaluation inlined in a compiled loop over the reference run's 1 ms samples with "
           "their contact modes (bench/costs.py). At each error the cost, the floor and the best scipy driver's cost "
           "are interpolated on their work–precision curves; × is the scipy driver's cost over grapefmu's.", "",
           "| scene | bare RHS (ns) | error (rad) | grapefmu ms / sim s | RHS floor | wall / floor | "
           "best scipy driver | its ms / sim s (×) | its wall / floor |", "|---|---|---|---|---|---|---|---|---|"]
    for scene in dict.fromkeys(r.scene for r in rows if r.scene in rhs_ns):
        ours = [r for r in rows if r.scene == scene and r.method == "grapefmu event"]
        for target in (1e-6, 1e-10):
            c, fl = cost_at(ours, target), cost_at(ours, target, key=lambda r: r.floor)
            sc, name = best_scipy(rows, scene, target)
            theirs = [r for r in rows if r.scene == scene and r.method == name]
            ratio = cost_at(theirs, target, key=lambda r: r.over_floor) if name else math.nan
            out.append(f"| {scene} | {rhs_ns[scene]:.0f} | {_e(target)} | {_fmt(1e3 * c, '.3f')} | "
                       f"{_fmt(1e3 * fl, '.3f')} | {_fmt(c / fl, '.1f')} | {name or 'none reaches it'} | "
                       f"{_fmt(1e3 * sc, '.3g')} ({_fmt(sc / c, '.1f')}×) | {_fmt(ratio, '.1f')} |")
    return out + [""]


def advance_section(adv: AdvanceCost) -> list[str]:
    span = adv.calls * adv.dt
    return ["## Stepping from a face: advance(1 ms) against one run", "",
            f"The paper collision scene, rtol 1e-6, atol 1e-8, {span:g} s: {adv.calls} calls of `Solver.advance"
            f"({adv.dt:g})` (the scene's excitation, no held input), the same {adv.calls} communication points in one "
            "compiled loop (bench/costs.py: exactly the same solver steps, none of the call's costs), and one "
            f"`Solver.run` of the same {span:g} s (1 ms output grid). Interleaved, the minimum of 7 (3 in "
            "--quick).", "",
            "| | ms per simulated s | solver steps |", "|---|---|---|",
            f"| {adv.calls} × `Solver.advance({adv.dt:g})` | {1e3 * adv.advance:.3f} | {adv.steps_advance} |",
            f"| the same points in one compiled loop | {1e3 * adv.compiled:.3f} | {adv.steps_advance} |",
            f"| one `Solver.run` | {1e3 * adv.run:.3f} | {adv.steps_run} |", "",
            f"advance's fixed cost (advance − compiled loop, per call): **{1e6 * adv.fixed:.2f} µs**. Each call costs "
            f"{1e6 * adv.over_run:.1f} µs more than its share of one run: the fixed cost and "
            f"{1e6 * (adv.compiled - adv.run) * adv.dt:.1f} µs for the {adv.steps_advance - adv.steps_run} extra "
            "solver steps in all (every communication point ends a step).", ""]


def mujoco_target(rows: list[Row], target: float = 1e-6) -> str:
    """Each scene where a MuJoCo integrator reaches `target` rad, its cheapest there against grapefmu's cost, and
    whether grapefmu is cheaper on every one."""
    found = []
    for scene in dict.fromkeys(r.scene for r in rows):
        costs = [(cost_at([r for r in rows if r.scene == scene and r.method == m], target), m)
                 for m in dict.fromkeys(r.method for r in rows if r.scene == scene and r.method.startswith("MuJoCo"))]
        theirs, name = min(((c, m) for c, m in costs if c == c), default=(math.nan, ""))
        if theirs == theirs:
            found.append((scene, name, theirs,
                          cost_at([r for r in rows if r.scene == scene and r.method == "grapefmu event"], target)))
    if not found:
        return (f"MuJoCo reaches {_e(target)} rad on no scene against the reference (its contact model differs; see "
                "the 'vs own finest step' notes).")
    return ("; ".join(f"{scene}: {name} {1e3 * theirs:.3g} ms against ours {1e3 * ours:.3g} ms ({theirs / ours:.1f}×)"
                      for scene, name, theirs, ours in found)
            + (" (on no other scene does MuJoCo reach it): " if len(found) < len({r.scene for r in rows}) else ": ")
            + ("met." if all(ours < theirs for _, _, theirs, ours in found) else "missed."))


def targets(rows: list[Row], adv: AdvanceCost) -> list[str]:
    """The targets (issue 14 on the paper collision scene, and the accuracy ones), each met or missed by how
    much (the why is in docs/bench_notes.md)."""
    sc = "paper collision"
    ours_rows = [r for r in rows if r.scene == sc and r.method == "grapefmu event"]
    ours = cost_at(ours_rows)
    floor = cost_at(ours_rows, key=lambda r: r.floor)
    out = ["## Targets (issue 14: paper collision scene)", ""]
    if ours == ours:
        out.append(f"- at most 0.2 ms per simulated second at 1e-6 rad: **{1e3 * ours:.3g} ms**, "
                   + ("met." if ours <= 2e-4 else f"missed by {ours / 2e-4:.1f}×."))
        out.append(f"- at most 1.3× its RHS floor at 1e-6 rad: **{ours / floor:.1f}×** (floor {1e3 * floor:.3g} ms), "
                   + ("met." if ours <= 1.3 * floor else "missed."))
    for target, want in ((1e-6, 30), (1e-10, 15)):
        c = cost_at(ours_rows, target)
        best, name = best_scipy(rows, sc, target)
        if best == best and c == c:
            out.append(f"- at least {want}× cheaper than the best scipy driver at {_e(target)} rad: "
                       f"**{best / c:.1f}×** ({name}, {1e3 * best:.3g} ms against {1e3 * c:.3g} ms), "
                       + ("met." if best / c >= want else "missed."))
        else:
            out.append(f"- at least {want}× cheaper than the best scipy driver at {_e(target)} rad: not measured "
                       "(no setting brackets that error).")
    out.append(f"- `advance(1e-3)` fixed cost at most 2 µs per call: **{1e6 * adv.fixed:.2f} µs**, "
               + ("met." if adv.fixed <= 2e-6 else "missed."))
    out.append("- 100-berry cluster at least 10× faster than real time, cost exponent over N ≤ 1.2: in the Scale "
               "section (`grapefmu bench --scale`).")
    out.append("- cheaper than MuJoCo wherever MuJoCo reaches 1e-6 rad: " + mujoco_target(rows))
    worst = {}
    for r in rows:
        if r.method == "grapefmu event":
            worst[r.scene] = min(worst.get(r.scene, math.inf), r.error if not r.failure else math.inf)
    not_reached = [s for s, e in worst.items() if not e <= 1e-10]
    out.append("- 1e-10 rad reached on every scene: " + ("met." if not not_reached else
               f"not on {', '.join(f'{s} (best {worst[s]:.1e})' for s in not_reached)}."))
    fails = [r for r in rows if r.method == "grapefmu event" and r.failure]
    failed = "; ".join(f"{r.scene} {r.setting}" for r in fails)
    out.append("- no grapefmu failure on any scene at any tolerance tried: " +
               ("met." if not fails else f"{len(fails)} failures: {failed}"))
    return out + [""]


def main(quick: bool, out: Path, plot_dir: Path) -> int:
    t0 = time.perf_counter()
    compile_s = (math.nan, math.nan) if quick else compile_seconds()
    rows, refused, rhs_ns, adv = run(quick, log=lambda s: print(s, file=sys.stderr, flush=True))
    plot_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(plot_dir / "rows.json") as tmp:  # the raw rows, for anyone who wants other views
        tmp.write_text(json.dumps([dataclasses.asdict(r) for r in rows], default=str))
    files = plot(rows, plot_dir)
    rel = {p.stem.replace("_", " "): os.path.relpath(p, out.parent) for p in files}
    command = "grapefmu bench" + (" --quick" if quick else "") + f" --out {out} --plots {plot_dir}"
    text = markdown(rows, refused, compile_s, command, rel, quick, rhs_ns, adv)
    with atomic_path(out) as tmp:
        tmp.write_text(text)
    scale = plot_dir / "scale.md"
    if scale.exists() and not quick:  # keep the scale section (grapefmu bench --scale) in the report
        from .scale import in_report, insert_section
        insert_section(out, in_report(scale.read_text(), plot_dir, out))
    print(text)
    print(f"wrote {out} and {len(files)} plots in {plot_dir} ({time.perf_counter() - t0:.0f} s)")
    return 0
