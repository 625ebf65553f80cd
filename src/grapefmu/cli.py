"""The `grapefmu` command: a thin layer over the library."""
from __future__ import annotations

import argparse
import sys
import time
from importlib import resources
from pathlib import Path

from . import __version__
from .errors import GrapefmuError


def default_scene_path() -> Path:
    return Path(str(resources.files("grapefmu") / "scenes" / "default.toml"))


class Progress:
    """A one-line progress bar on stderr, shown only once a run has taken more than a second."""

    def __init__(self, label: str):
        self.label = label
        self.start = time.perf_counter()
        self.shown = False

    def __call__(self, t: float, t_end: float) -> None:
        wall = time.perf_counter() - self.start
        if wall < 1.0 and t < t_end:
            return
        if wall < 1.0 and not self.shown:
            return
        frac = min(t / t_end, 1.0) if t_end > 0 else 1.0
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}%  t = {t:.3f} s  wall {wall:.1f} s")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()
        self.shown = True


def _summary_table(run) -> str:
    s = run.summary()
    rows = [
        ("simulated", f"{s['t_end']:.4g} s, {s['samples']} samples, method {s['method']}"),
        ("solver", f"{s.get('steps', '-')} steps, {s.get('rejected', '-')} rejected, "
                   f"{s.get('rhs_evaluations', '-')} RHS evaluations, {1e3 * s['wall_time']:.2f} ms wall"),
        ("collisions", str(s["collision_count"])),
        ("peak contact force", f"{s['peak_contact_force']:.4g} N"),
        ("peak pedicel tension", f"{s['peak_pedicel_force']:.4g} N"),
        ("largest impact energy", f"{1e3 * s['max_impact_energy']:.4g} mJ"),
        ("energy dissipated", f"{1e3 * s['energy_dissipated']:.4g} mJ"),
        ("energy ledger error", f"{run.ledger_error():.2e} (relative)"),
        ("detachment risk", ("YES: " + ", ".join(s["berries_over_detachment_force"])) if s["detachment_risk"] else "no"),
        ("bruising impacts", str(s["bruising_impacts"])),
        ("fatigue impacts", str(s["fatigue_impacts"])),
    ]
    if s.get("zeno_guard_activations"):
        rows.append(("Zeno guard", f"{s['zeno_guard_activations']} activations (resting-contact treatment used)"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def cmd_simulate(a: argparse.Namespace) -> int:
    from .model import load_scene
    from .results.writers import write_run
    from .solver.api import simulate

    scene = load_scene(a.scene or default_scene_path())
    run = simulate(scene, a.t_end, method=a.method, rtol=a.rtol, atol=a.atol, progress=Progress("simulate"))
    print(f"scene {scene.name}: {scene.model.n_berries} berries, {len(scene.model.pairs)} contact pairs, "
          f"excitation {scene.excitation.kind}")
    print(_summary_table(run))
    if a.out:
        write_run(run, a.out)
        print(f"wrote {a.out}")
    if a.plot:
        from .results.plot import plot_run
        plot_run(run, a.plot)
        print(f"wrote {a.plot}")
    return 0


def cmd_paper(a: argparse.Namespace) -> int:
    from .paper.reproduce import reproduce
    return reproduce(Path(a.out))


def cmd_build_fmu(a: argparse.Namespace) -> int:
    try:
        from grapefmu_fmu.build import build_fmu
    except ImportError as e:
        raise GrapefmuError(f"build-fmu needs the FMU extra (pip install 'grapefmu[fmu]'): {e}") from None
    out = build_fmu(a.scene or default_scene_path(), a.output, a.fmi, a.outputs)
    print(f"wrote {out} (FMI {a.fmi}.0 co-simulation)")
    return 0


def cmd_replay(a: argparse.Namespace) -> int:
    if a.publish:
        try:
            from grapefmu_ros.replay import publish
        except ImportError as e:
            raise GrapefmuError(f"replay --publish needs ROS 2 (rclpy) installed: {e}") from None
        return publish(a.recording, a.rate)
    from .recording.replay import check
    r = check(a.recording)
    if r.truncated:
        print(f"warning: {r.truncated}", file=sys.stderr)
    print(f"re-simulated from {'the scene' if r.source == 'scene' else 'the recorded applied inputs'}; "
          f"{r.compared} joint states compared")
    print(f"  largest deviation: angle {r.max_angle_deviation:.3g} rad, angular velocity {r.max_rate_deviation:.3g} rad/s")
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    from .bench.harness import main as bench
    return bench(a.quick, Path(a.out), Path(a.plots))


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="grapefmu", description="Berries that swing and collide when a gripper moves a grape cluster.")
    ap.add_argument("--version", action="version", version=f"grapefmu {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("simulate", help="run a scene and report impacts, peaks and indicators")
    s.add_argument("scene", nargs="?", help="scene TOML (default: the packaged default scene)")
    s.add_argument("--t-end", type=float, help="simulated time in s (overrides the scene)")
    s.add_argument("--rtol", type=float, help="relative tolerance (overrides the scene)")
    s.add_argument("--atol", type=float, help="absolute tolerance (overrides the scene)")
    s.add_argument("--method", choices=("event", "paper", "reference"), help="integration method")
    s.add_argument("--out", help="write samples to .csv, .parquet or .mcap")
    s.add_argument("--plot", help="write a figure (.png, .pdf or .svg)")
    s.set_defaults(func=cmd_simulate)
    b = sub.add_parser("build-fmu", help="package a scene as an FMI co-simulation FMU")
    b.add_argument("scene", nargs="?", help="scene TOML (default: the packaged default scene)")
    b.add_argument("-o", "--output", required=True, help="the .fmu file to write")
    b.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
    b.add_argument("--outputs", choices=("full", "summary"),
                   help="per angle, berry and pair, or cluster totals only (default: full up to 16 berries and pairs)")
    b.set_defaults(func=cmd_build_fmu)
    r = sub.add_parser("replay", help="check a recording by re-simulating it, or republish it")
    r.add_argument("recording", help="an MCAP file written by grapefmu simulate or the ROS node")
    g = r.add_mutually_exclusive_group(required=True)
    g.add_argument("--check", action="store_true", help="re-simulate and report the largest deviation")
    g.add_argument("--publish", action="store_true", help="republish the recorded topics with /clock")
    r.add_argument("--rate", type=float, default=1.0, help="with --publish: speed factor (0 = as fast as possible)")
    r.set_defaults(func=cmd_replay)
    be = sub.add_parser("bench", help="speed against error on hard scenes, side by side with peer methods")
    be.add_argument("--quick", action="store_true", help="two scenes, few settings (under a minute)")
    be.add_argument("--out", default="docs/benchmarks.md", help="the Markdown report to write")
    be.add_argument("--plots", default="docs/bench", help="directory for one work–precision plot per scene")
    be.set_defaults(func=cmd_bench)
    p = sub.add_parser("paper", help="reproduce tests 1–9 of Xu et al. (2025) and check each claim")
    p.add_argument("--out", default="out/paper", help="directory for figures and the claims report")
    p.set_defaults(func=cmd_paper)
    return ap


def _check_overrides(a: argparse.Namespace) -> None:
    import math
    for name, lo, hi in (("t_end", 0.0, 1e5), ("rtol", 1e-14, 0.1), ("atol", 1e-16, 1.0)):
        v = getattr(a, name, None)
        if v is not None and not (math.isfinite(v) and lo < v <= hi):
            raise GrapefmuError(f"--{name.replace('_', '-')}: expected a number in ({lo:g}, {hi:g}], got {v!r}")


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    try:
        _check_overrides(a)
        return a.func(a)
    except GrapefmuError as e:
        print(f"grapefmu: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
