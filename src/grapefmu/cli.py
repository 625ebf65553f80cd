"""The `grapefmu` command: a thin layer over the library."""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time
import tomllib
from pathlib import Path

from . import __version__
from .errors import GrapefmuError, SolverError
from .results.writers import check_target
from .scenefile import default_scene_path


class Progress:
    """A one-line progress bar on stderr, shown only once a run has taken more than a second."""

    #: a bar is on screen without its newline (an error or interruption message starts a new line)
    open_line = False

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
        Progress.open_line = frac < 1.0
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
        ("peak pedicel tension", f"{s['peak_pedicel_tension']:.4g} N"),
        ("largest impact energy", f"{1e3 * s['max_impact_energy']:.4g} mJ"),
        ("energy dissipated", f"{1e3 * s['dissipated_energy']:.4g} mJ"),
        ("energy ledger error", run.ledger_report()),
        ("detachment risk", ("YES: " + ", ".join(s["detached_berries"][:10])
                             + (", ..." if len(s["detached_berries"]) > 10 else ""))
         if s["detachment_risk"] else "no"),
        ("bruising impacts", str(s["bruising_impacts"])),
        ("fatigue impacts", str(s["fatigue_impacts"])),
    ]
    if s["berries"] > 2:
        st = run.stats
        rows.insert(2, ("kept", f"{st.get('degrees_of_freedom', '-')} degrees of freedom, {st.get('candidate_pairs', '-')} "
                               f"candidate pairs ({run.scene.model.pairs_pruned} never within reach left out), "
                               f"{st.get('near_pairs_mean', float('nan')):.1f} near pairs per step, "
                               f"at most {s['max_active_pairs']} in contact, {st.get('groups', 1)} independent group(s)"))
        rows.append(("berries over detachment", str(s["berries_over_detachment_force"])))
        rows.append(("dissipated per berry", f"largest {1e3 * s['max_dissipated_per_berry']:.4g} mJ, "
                                             f"mean {1e3 * s['mean_dissipated_per_berry']:.4g} mJ"))
    if s.get("zeno_guard_activations"):
        rows.append(("Zeno guard", f"{s['zeno_guard_activations']} activations (resting-contact treatment used)"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def cmd_simulate(a: argparse.Namespace) -> int:
    from .scenefile import load_scene
    from .write import check_output, write_run
    from .results.plot import check_plot
    from .solver.api import simulate
    from .solver.budget import check_samples

    if a.out is not None:  # refuse an output that cannot be written before the run, not after it
        check_output(a.out, "--out")
    if a.plot is not None:
        check_plot(a.plot, "--plot")
    scene = load_scene(a.scene or default_scene_path())
    if a.t_end is not None:
        check_samples(scene.model, a.t_end, scene.solver.output_interval, "--t-end")
    run = simulate(scene, a.t_end, method=a.method, rtol=a.rtol, atol=a.atol, progress=Progress("simulate"))
    print(f"scene {scene.name}: {scene.model.n_berries} berries, {len(scene.model.pairs)} contact pairs, "
          f"excitation {scene.excitation.kind}")
    print(_summary_table(run))
    warnings = run.summary()["warnings"]
    for w in warnings:
        print(f"warning: {w}")
    if a.out:
        write_run(run, a.out)
        print(f"wrote {a.out}")
    if a.plot:
        from .results.plot import plot_run
        plot_run(run, a.plot)
        print(f"wrote {a.plot}")
    if a.strict and warnings:
        print(f"grapefmu: --strict: {len(warnings)} warning(s), the results cannot be trusted", file=sys.stderr)
        return 3
    return 0


def cmd_cluster(a: argparse.Namespace) -> int:
    from .cluster.generate import ClusterSpec, RowSpec, Spread, cluster_scene, row_scene
    from .scenefile import scene_from_dict
    from .scenefile import dumps
    from .results.writers import atomic_path

    out = check_target(a.output, (".toml",), "--output")
    if a.row:
        doc = row_scene(RowSpec(berries=a.berries, pitch=a.pitch if a.pitch is not None else 0.027, name=out.stem))
    else:
        spreads = {k: Spread(*getattr(a, k)) for k in ("diameter", "twig_length", "hinge_stiffness", "hinge_damping")
                   if getattr(a, k) is not None}
        doc = cluster_scene(ClusterSpec(berries=a.berries, seed=a.seed, precompression=a.precompression, name=out.stem,
                                        **spreads))
    scene = scene_from_dict(doc, Path.cwd())  # the generated scene passes the same checks as a file
    what = f"a row of {a.berries} berries" if a.row else f"a cluster of {a.berries} berries, seed {a.seed}"
    head = f"# {what}, generated by grapefmu {__version__} (grapefmu cluster); SI units, z up; see docs/scenes.md\n"
    with atomic_path(out) as tmp:
        tmp.write_text(head + dumps(doc))
    m = scene.model
    print(f"wrote {out}: {m.n_berries} berries, {m.n_dof} degrees of freedom, {len(m.pairs)} candidate contact pairs "
          f"({m.pairs_pruned} pairs that can never touch left out)")
    return 0


def cmd_sweep(a: argparse.Namespace) -> int:
    from .sweep import load_spec, run_sweep

    spec = load_spec(a.spec)
    out = check_target(a.output if a.output is not None else Path(a.spec).with_suffix(".parquet"), (".parquet",),
                       "--output")
    a.output = str(out)  # named if the sweep is interrupted
    if a.workers is not None and not 1 <= a.workers <= 1024:
        raise GrapefmuError(f"--workers: expected an integer in [1, 1024], got {a.workers}")
    run_sweep(spec, out, workers=a.workers, scheduler=a.scheduler)
    print(f"wrote {out}")
    return 0


def cmd_paper(a: argparse.Namespace) -> int:
    from .paper.reproduce import reproduce
    return reproduce(check_target(a.out, None, "--out"))


def face(name: str, needs: str):
    """A function that a face (the FMU builder, the ROS node) registers in the entry-point group
    `grapefmu.faces`: the core names no face, and a missing one is one clear line."""
    from importlib.metadata import entry_points

    found = entry_points(group="grapefmu.faces", name=name)
    try:
        return next(iter(found)).load()
    except (StopIteration, ImportError) as e:
        raise GrapefmuError(f"this command needs {needs}: {e or 'not installed'}") from None


def cmd_build_fmu(a: argparse.Namespace) -> int:
    check_target(a.output, (".fmu",), "--output")
    build_fmu = face("build_fmu", "the FMU extra (pip install 'grapefmu[fmu]')")
    out = build_fmu(a.scene or default_scene_path(), a.output, a.fmi, a.outputs)
    print(f"wrote {out} (FMI {a.fmi}.0 co-simulation)")
    if a.cross_check:
        cross_check = face("cross_check", "the FMU extra (pip install 'grapefmu[fmu]')")
        print(f"wrote the FMI cross-check package {cross_check(a.scene or default_scene_path(), a.cross_check, a.fmi)}")
    return 0


def cmd_replay(a: argparse.Namespace) -> int:
    if a.publish:
        if not Path(a.recording).is_file():
            raise GrapefmuError(f"{a.recording}: no such recording (expected an MCAP file written by grapefmu)")
        return face("publish", "ROS 2 (pip install 'grapefmu[ros]')")(a.recording, a.rate)
    from .recording.replay import check
    r = check(a.recording)  # a corrupted file raises CorruptRecording: one line naming the record, exit 2
    if r.truncated:
        print(f"warning: {r.truncated}", file=sys.stderr)
    print(f"re-simulated from {'the scene' if r.source == 'scene' else 'the recorded applied inputs'}; "
          f"{r.compared} joint states compared")
    print(f"  largest deviation: angle {r.max_angle_deviation:.3g} rad, angular velocity {r.max_rate_deviation:.3g} rad/s")
    if not r.ok:
        print(f"grapefmu: check failed: {a.recording}: the recorded joint states deviate by up to "
              f"{r.max_deviation:.3g} (at t = {r.worst_time:.6f} s), more than the tolerance {r.tolerance:g} rad, rad/s",
              file=sys.stderr)
        return 1
    return 0


def cmd_outputs(a: argparse.Namespace) -> int:
    from .results.catalogue import markdown
    sys.stdout.write(markdown())
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    check_target(a.out, (".md",), "--out")
    check_target(a.plots, None, "--plots")
    if a.scale:
        from .bench.scale import main as scale
        return scale(Path(a.out), Path(a.plots))
    from .bench.harness import main as bench
    return bench(a.quick, Path(a.out), Path(a.plots))


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="grapefmu", description="Berries that swing and collide when a gripper moves a grape cluster.")
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
    s.add_argument("--strict", action="store_true",
                   help="exit with code 3 when the run has warnings (results that cannot be trusted)")
    s.set_defaults(func=cmd_simulate)
    b = sub.add_parser("build-fmu", help="package a scene as an FMI co-simulation FMU")
    b.add_argument("scene", nargs="?", help="scene TOML (default: the packaged default scene)")
    b.add_argument("-o", "--output", required=True, help="the .fmu file to write")
    b.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
    b.add_argument("--outputs", choices=("full", "summary"),
                   help="per angle, berry and pair, or cluster totals only (default: full up to 16 berries and pairs)")
    b.add_argument("--cross-check", metavar="DIR",
                   help="also write the FMI cross-check package (FMU, _in.csv, _ref.csv, _ref.opt, ReadMe) under DIR")
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
    be.add_argument("--scale", action="store_true", help="cost against the number of berries, N = 2 … 300 "
                                                          "(rewrites only its own section of the report)")
    be.add_argument("--out", default="docs/benchmarks.md", help="the Markdown report to write")
    be.add_argument("--plots", default="docs/bench", help="directory for one work–precision plot per scene")
    be.set_defaults(func=cmd_bench)
    c = sub.add_parser("cluster", help="generate a cluster scene (seeded) or a planar row of berries")
    c.add_argument("-o", "--output", required=True, help="the scene TOML to write")
    c.add_argument("--berries", type=int, default=60, help="number of berries (default 60)")
    c.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    c.add_argument("--row", action="store_true", help="a planar row on one rod (Newton's cradle) instead")
    c.add_argument("--pitch", type=float, help="--row: hinge spacing in m (default 0.027, touching at rest)")
    c.add_argument("--precompression", type=float, default=0.0, help="largest overlap of two berries at rest, m")
    for name, unit in (("diameter", "m"), ("twig_length", "m"), ("hinge_stiffness", "N·m/rad"),
                       ("hinge_damping", "N·m·s/rad")):
        c.add_argument(f"--{name.replace('_', '-')}", type=float, nargs=2, metavar=("MEAN", "SD"),
                       help=f"normal distribution of the {name.replace('_', ' ')}, {unit}")
    c.set_defaults(func=cmd_cluster)
    w = sub.add_parser("sweep", help="run a grid or Monte Carlo sweep over scene parameters to Parquet (resumable)")
    w.add_argument("spec", help="sweep spec TOML (docs/sweeps.md)")
    w.add_argument("-o", "--output", help="the Parquet file (default: the spec's name with .parquet)")
    w.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    w.add_argument("--scheduler", help="a Dask distributed scheduler address, tcp://host:port, instead")
    w.set_defaults(func=cmd_sweep)
    o = sub.add_parser("outputs", help="list every output channel (name, unit, ROS topic, FMU causality) as Markdown")
    o.set_defaults(func=cmd_outputs)
    p = sub.add_parser("paper", help="reproduce tests 1–9 of Xu et al. (2025) and check each claim")
    p.add_argument("--out", default="out/paper", help="directory for figures and the claims report")
    p.set_defaults(func=cmd_paper)
    return ap


def _check_overrides(a: argparse.Namespace) -> None:
    for name, lo, hi in (("t_end", 0.0, 1e5), ("rtol", 1e-14, 0.1), ("atol", 1e-16, 1.0)):
        v = getattr(a, name, None)
        if v is not None and not (math.isfinite(v) and lo < v <= hi):
            raise GrapefmuError(f"--{name.replace('_', '-')}: expected a number in ({lo:g}, {hi:g}], got {v!r}")
    rate = getattr(a, "rate", None)
    if rate is not None and not (math.isfinite(rate) and rate >= 0.0):
        raise GrapefmuError(f"--rate: expected a finite speed factor > 0 (or 0 for as fast as possible), got {rate!r}")


class Parser(argparse.ArgumentParser):
    """argparse, with a usage error as one line (`grapefmu simulate: argument --t-end: ...`) and exit code 2."""

    def error(self, message: str):
        self.exit(USAGE, f"{self.prog}: {' '.join(message.split())} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):
        a, extra = self.parse_known_args(args, namespace)
        if extra:  # named with the command they were given to
            prog = f"{self.prog} {a.command}" if getattr(a, "command", None) else self.prog
            self.exit(USAGE, f"{prog}: unrecognized arguments: {' '.join(extra)} (see {prog} --help)\n")
        return a


#: exit codes: a usage or input error the user can fix, a run that failed, an interruption (128 + signal)
USAGE, FAILURE = 2, 1


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM, raised where the program is, so every `with atomic_path(...)` removes its temporary file."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _on_signal(signum, frame):
    # a second signal while cleaning up ends the process at once (the next writer removes what it left)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    raise Interrupted(signum)


def _explain(e: BaseException) -> tuple[str, int]:
    """An error a user can cause as (one line naming the input and what is allowed, exit code)."""
    if isinstance(e, SolverError):
        return str(e), FAILURE
    if isinstance(e, GrapefmuError):
        return str(e), USAGE
    if isinstance(e, UnicodeDecodeError):
        return f"input is not UTF-8 text ({e.reason} at byte {e.start})", USAGE
    if isinstance(e, OSError):
        where = f"{e.filename}: " if e.filename is not None else ""
        user = isinstance(e, (FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError,
                              PermissionError))
        return f"{where}{e.strerror or e}", USAGE if user else FAILURE
    if isinstance(e, tomllib.TOMLDecodeError):
        return f"not valid TOML: {e}", USAGE
    if isinstance(e, RecursionError):
        return "input nested too deeply to read (a few hundred levels at most)", USAGE
    if isinstance(e, OverflowError):
        return f"a number is out of range: {e}", USAGE
    if isinstance(e, MemoryError):
        return "out of memory: shorten the run, raise the output interval or use fewer berries", FAILURE
    raise e


#: what each command writes (argument names), named when a run is interrupted
TARGETS = {"simulate": ("out", "plot"), "cluster": ("output",), "sweep": ("output",), "build-fmu": ("output",),
           "paper": ("out",), "bench": ("out", "plots")}


def _stamp(path: str) -> tuple | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def _interrupted(a: argparse.Namespace, before: dict[str, tuple | None]) -> str:
    """What an interruption leaves: every file target not replaced since the start is untouched."""
    paths = [str(getattr(a, k)) for k in TARGETS.get(a.command, ()) if getattr(a, k, None)]
    files = [p for p in paths if not os.path.isdir(p) and _stamp(p) == before.get(p)]
    dirs = [p for p in paths if os.path.isdir(p)]
    said = "interrupted"
    if files:
        said += f"; nothing written to {', '.join(files)}"
    if dirs:
        said += f"; {', '.join(dirs)} holds only what was finished"
    return said


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    cmd = f"grapefmu {a.command}"
    before = {str(getattr(a, k)): _stamp(str(getattr(a, k))) for k in TARGETS.get(a.command, ()) if getattr(a, k, None)}
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        handlers = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            _check_overrides(a)
            return a.func(a)
        except (GrapefmuError, OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError, OverflowError,
                MemoryError) as e:
            text, code = _explain(e)
            print(f"{_newline()}{cmd}: {' '.join(text.split())}", file=sys.stderr)
            return code
        except KeyboardInterrupt as e:
            signum = getattr(e, "signum", signal.SIGINT)
            print(f"{_newline()}{cmd}: {_interrupted(a, before)}", file=sys.stderr)
            return 128 + signum
    finally:
        for sig, h in handlers.items():
            if h is not None:
                signal.signal(sig, h)


def _newline() -> str:
    """A newline if a progress bar is on screen, so the message that follows starts its own line."""
    said, Progress.open_line = Progress.open_line, False
    return "\n" if said else ""


if __name__ == "__main__":
    sys.exit(main())
