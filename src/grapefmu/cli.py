"""The `grapefmu` command: a thin layer over the library."""
from __future__ import annotations

import argparse
import math
import os
import shlex
import signal
import sys
import threading
import time
import tomllib
from pathlib import Path

from . import __version__
from .errors import GrapefmuError, SceneError, SolverError
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


def _compile_row(s: dict) -> tuple[str, str] | None:
    """How long numba took before the run: a compile (cold cache) or a load from the cache."""
    if "compile_time_s" not in s:
        return None
    how = "compiled (first run; later runs load it from the cache)" if s.get("compiled") else "loaded from the cache"
    return "numba core", f"{s['compile_time_s']:.2f} s, {how}; not in the solver time"


def _summary_table(run) -> str:
    """The summary as a table; every quantity in the unit its key and the CSV columns carry (N, J, s)."""
    s = run.summary()
    rows = [
        ("simulated", f"{s['t_end_s']:.4g} s, {s['samples']} samples, method {s['method']}"
                      + (f" ({s['integrator']})" if "integrator" in s else "")),
        ("solver", "".join(f"{s[k]} {what}, " for k, what in (("steps", "steps"), ("rejected", "rejected"),
                                                                 ("rhs_evaluations", "RHS evaluations")) if k in s)
                   + f"{s['wall_time_s']:.4g} s wall"
                   + (f"; in multirate islands: {s['islands_formed']} formed, {s['island_rollbacks']} rolled back"
                      if "islands_formed" in s else "")),
        ("collisions", str(s["collision_count"])),
        ("peak contact force", f"{s['peak_contact_force_n']:.4g} N"),
        ("peak pedicel tension", f"{s['peak_pedicel_tension_n']:.4g} N"),
        ("largest impact energy", f"{s['max_impact_energy_j']:.4g} J"),
        ("energy dissipated", f"{s['dissipated_energy_j']:.4g} J"),
        ("energy ledger error", run.ledger_report()),
        ("detachment risk", ("YES: " + ", ".join(s["detached_berries"][:10])
                             + (", ..." if len(s["detached_berries"]) > 10 else ""))
         if s["detachment_risk"] else "no"),
        ("bruising impacts", str(s["bruising_impacts"])),
        ("fatigue impacts", str(s["fatigue_impacts"])),
        *((f"  on {name}", f"{row['count']} impacts, {row['bruising']} bruising, largest {row['peak_force_n']:.4g} N "
                           f"(bruises at {row['bruise_force_n']:.4g} N)")
          for name, row in s.get("impacts_by_surface", {}).items()),
    ]
    compiled = _compile_row({**s, "compiled": run.stats.get("compiled")})
    if compiled:
        rows.insert(1, compiled)
    if s["berries"] > 2:
        st = run.stats
        kept = [f"{st['degrees_of_freedom']} degrees of freedom" if "degrees_of_freedom" in st else "",
                f"{st['candidate_pairs']} candidate pairs ({run.scene.model.pairs_pruned} never within reach left out)"
                if "candidate_pairs" in st else "",
                f"{st['near_pairs_mean']:.1f} near pairs per step" if "near_pairs_mean" in st else "",
                f"at most {s['max_active_pairs']} in contact", f"{st.get('groups', 1)} independent group(s)"]
        rows.insert(3 if compiled else 2, ("kept", ", ".join(k for k in kept if k)))
        rows.append(("berries over detachment", str(s["berries_over_detachment_force"])))
        rows.append(("dissipated per berry", f"largest {s['max_dissipated_per_berry_j']:.4g} J, "
                                             f"mean {s['mean_dissipated_per_berry_j']:.4g} J"))
    if s.get("zeno_guard_activations"):
        rows.append(("Zeno guard", f"{s['zeno_guard_activations']} activations (resting-contact treatment used)"))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{w}}  {v}" for k, v in rows)


def _compiling() -> None:
    """Before a command's first run of the core, after its inputs are checked: one line if numba must compile."""
    from .solver.warmup import notice
    notice(lambda line: print(f"{_newline()}{line}", file=sys.stderr, flush=True))


def cmd_simulate(a: argparse.Namespace) -> int:
    from .scenefile import load_scene
    from .write import check_output, write_run
    from .results.plot import check_plot
    from .solver.api import simulate
    from .solver.budget import check_samples
    from .model.excitation import check_covers
    from .solver.warmup import prepare

    outs = []  # each file once (a.csv and ./a.csv are one), refused before the run if it cannot be written
    for out in a.out or ():
        if os.path.realpath(out) not in map(os.path.realpath, outs):
            outs.append(out)
    for out in outs:
        check_output(out, "--out")
    if a.plot is not None:
        check_plot(a.plot, "--plot")
    if a.plot is not None and a.plot in outs:
        raise GrapefmuError(f"--plot {a.plot}: also given as --out; choose another name")
    scene = load_scene(a.scene or default_scene_path())
    if a.t_end is not None:
        check_samples(scene.model, a.t_end, scene.solver.output_interval, "--t-end")
    check_covers(scene.excitation, scene.solver.t_end if a.t_end is None else a.t_end,
                 "solver.t_end" if a.t_end is None else "--t-end")
    warm = prepare(scene, a.method, write=lambda line: print(f"{_newline()}{line}", file=sys.stderr, flush=True))
    run = simulate(scene, a.t_end, method=a.method, rtol=a.rtol, atol=a.atol, progress=Progress("simulate"))
    run.stats.update(compile_time=warm.seconds, compiled=warm.compiled)
    print(f"scene {scene.name}: {_count(scene.model.n_berries, 'berry', 'berries')}, "
          f"{_count(len(scene.model.pairs), 'contact pair')}, "
          f"excitation {scene.excitation.kind}")
    print(_summary_table(run))
    warnings = run.summary()["warnings"]
    for w in warnings:
        print(f"warning: {w}")
    for out in outs:
        write_run(run, out)
        print(f"wrote {out}")
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
    cluster_only = ("seed", "precompression", "diameter", "twig_length", "hinge_stiffness", "hinge_damping")
    given = [k for k in (cluster_only if a.row else ("pitch",)) if getattr(a, k) is not None]
    if given:  # an option of the other kind would be ignored without a word
        raise GrapefmuError(f"--{given[0].replace('_', '-')}: " + ("for a cluster, not with --row" if a.row else
                                                                   "only with --row"))
    try:
        if a.row:
            doc = row_scene(RowSpec(berries=a.berries, pitch=a.pitch if a.pitch is not None else 0.027,
                                    name=out.stem))
        else:
            chosen = {k: Spread(*v) if isinstance(v, list) else v for k in cluster_only
                      if (v := getattr(a, k)) is not None}
            doc = cluster_scene(ClusterSpec(berries=a.berries, name=out.stem, **chosen))
    except SceneError as e:  # cluster.seed, row.pitch: the option the user typed
        if not e.key.startswith(("cluster.", "row.")):
            raise
        raise GrapefmuError(f"--{e.key.split('.', 1)[1].replace('_', '-')}: {e.why}") from None
    scene = scene_from_dict(doc, Path.cwd())  # the generated scene passes the same checks as a file
    berries = _count(a.berries, "berry", "berries")
    what = f"a row of {berries}" if a.row else \
        f"a cluster of {berries}, seed {ClusterSpec.seed if a.seed is None else a.seed}"
    head = f"# {what}, generated by grapefmu {__version__} (grapefmu cluster); SI units, z up; see docs/scenes.md\n"
    with atomic_path(out) as tmp:
        tmp.write_text(head + dumps(doc))
    m = scene.model
    print(f"wrote {out}: {_count(m.n_berries, 'berry', 'berries')}, "
          f"{_count(m.n_dof, 'degree of freedom', 'degrees of freedom')}, "
          f"{_count(len(m.pairs), 'candidate contact pair')} ({_count(m.pairs_pruned, 'pair')} that can never touch "
          "left out)")
    return 0


def cmd_sweep(a: argparse.Namespace) -> int:
    from .sweep import load_spec, run_sweep

    spec = load_spec(a.spec)
    out = check_target(a.output if a.output is not None else Path(a.spec).with_suffix(".parquet"), (".parquet",),
                       "--output")
    a.output = str(out)  # named if the sweep is interrupted
    if a.workers is not None and not 1 <= a.workers <= 1024:
        raise GrapefmuError(f"--workers: expected an integer in [1, 1024], got {a.workers}")
    try:
        run_sweep(spec, out, workers=a.workers, scheduler=a.scheduler)
    except BaseException as e:  # interrupted: say what is kept and how to go on
        if not _interrupted_by(e):
            raise
        journal = out.with_name(out.name + ".journal.jsonl")
        try:
            kept = max(len(journal.read_text().splitlines()) - 1, 0)
        except OSError:
            kept = 0
        e.note = (f"{kept} finished run(s) kept in {journal}; run the same command again to resume" if kept else
                  "no run had finished; run the same command again to start over")
        raise
    print(f"wrote {out}")
    import pyarrow.parquet as pq
    status = pq.read_table(out, columns=["status"]).column("status").to_pylist()
    if "ok" not in status:  # a table of refusals: written, so that each says why, but not a sweep that ran
        print(f"grapefmu sweep: no run finished ({len(status)} refused or failed; the first: {status[0]})",
              file=sys.stderr)
        return FAILURE
    return 0


def cmd_fit(a: argparse.Namespace) -> int:
    from .fit import fit, parameters, read_measured
    from .fit.report import check_outputs, plot_residuals, table, write_json, write_scene
    from .scenefile import load_scene
    from .scenefile.parse import loads_toml, read_text

    check_outputs(a.output, a.report, a.plot)
    if not 1 <= a.segments <= 1000:
        raise GrapefmuError(f"--segments: expected an integer in [1, 1000], got {a.segments}")
    scene = load_scene(a.scene)
    doc = loads_toml(read_text(a.scene), a.scene)
    params = parameters(a.param or [], doc)
    series = [read_measured(d, scene.model) for d in a.data]
    _compiling()
    start = time.perf_counter()

    def progress(n: int, rms: float) -> None:  # after a second, one line on stderr updated per evaluation
        wall = time.perf_counter() - start
        if wall >= 1.0:
            sys.stderr.write(f"\rfit: {n} evaluations, residual rms {rms:.3g} rad, wall {wall:.1f} s ")
            sys.stderr.flush()
            Progress.open_line = True

    res = fit(doc, Path(a.scene).parent, params, series, segments=a.segments, progress=progress,
              **({"rtol": a.rtol} if a.rtol is not None else {}), **({"atol": a.atol} if a.atol is not None else {}))
    if Progress.open_line:
        print(_newline(), end="", file=sys.stderr)
    tracked = sorted({d for m in series for d in m.dofs})
    print(f"fit: {len(series)} series, {res.residuals} measured angles ({', '.join(tracked)}), {len(params)} "
          f"parameter(s) and the start states ({res.unknowns} unknowns informed by the data); {res.iterations} "
          f"evaluations, {res.seconds:.1f} s")
    print(f"  residual standard deviation {res.sigma:.3g} rad; condition number of JᵀJ {res.condition:.3g}")
    print(table(res))
    for w in res.warnings:
        print(f"warning: {w}")
    sources = [str(d) for d in a.data]
    write_scene(res, a.output, sources)
    print(f"wrote {a.output}")
    if a.report:
        write_json(res, a.report, a.scene, sources)
        print(f"wrote {a.report}")
    if a.plot:
        plot_residuals(res, a.plot)
        print(f"wrote {a.plot}")
    return 0


def cmd_risk(a: argparse.Namespace) -> int:
    from .risk import assess, distribution
    from .risk.montecarlo import plan_doc

    out = check_target(a.out, None, "--out")
    if a.workers is not None and not 0 <= a.workers <= 1024:
        raise GrapefmuError(f"--workers: expected an integer in [0, 1024], got {a.workers}")
    scales = _pair(a.scales, "--scales")
    dist = distribution(plan_doc(a.plans[0])[0], a.fit, a.range or [])  # every plan is checked against it (assess)
    say = lambda line: print(f"{_newline()}{line}", file=sys.stderr, flush=True)  # noqa: E731
    try:
        r = assess(a.plans, dist, a.samples, a.seed, out, max_bruise=a.max_bruise, scales=scales, workers=a.workers,
                   scheduler=a.scheduler, say=say, command="grapefmu " + shlex.join(a.argv))
    except BaseException as e:
        if not _interrupted_by(e):
            raise
        e.note = (f"the finished runs are kept in {out} (a journal per interrupted sweep, a table per finished "
                  "one); run the same command again to resume")
        raise
    for o in r.outcomes:
        print(f"{o.plan}: P(bruise) = {o.bruise.text()}, P(detachment) = {o.detach.text()}"
              + (f"; {len(o.failed)} run(s) did not finish" if o.failed else ""))
    if r.search is not None:
        print(f"search: {r.search.note}")
    for f in r.files:
        print(f"wrote {f}")
    return 0


def _pair(text: str, option: str) -> tuple[float, float]:
    lo, _, hi = text.partition(":")
    try:
        a, b = float(lo), float(hi)
    except ValueError:
        a = b = math.nan
    if not (math.isfinite(a) and math.isfinite(b) and 0 < a < b):
        raise GrapefmuError(f"{option} {text}: expected LOW:HIGH with 0 < LOW < HIGH")
    return a, b


def cmd_paper(a: argparse.Namespace) -> int:
    from .paper.reproduce import reproduce
    out = check_target(a.out, None, "--out")
    _compiling()
    return reproduce(out)


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
        _compiling()
        print(f"wrote the FMI cross-check package {cross_check(a.scene or default_scene_path(), a.cross_check, a.fmi)}")
    return 0


def cmd_replay(a: argparse.Namespace) -> int:
    from .recording.replay import check, read_recording
    if a.publish:
        # the publisher streams without CRCs: a damaged chunk went out as far as it decoded, exit 0, not a word
        rec = read_recording(a.recording, set())  # a corrupted file raises CorruptRecording, exit 2
        if rec.truncated:
            print(f"warning: {rec.truncated}", file=sys.stderr)
        return face("publish", "ROS 2 (pip install 'grapefmu[ros]')")(a.recording, a.rate)
    if Path(a.recording).is_file():
        _compiling()
    r = check(a.recording)  # a corrupted file raises CorruptRecording: one line naming the record, exit 2
    if r.truncated:
        print(f"warning: {r.truncated}", file=sys.stderr)
    print(f"re-simulated from {'the scene' if r.source == 'scene' else 'the recorded applied inputs'}; "
          f"{r.compared} joint states compared")
    print(f"  largest deviation: angle {r.max_angle_deviation:.3g} rad, angular velocity {r.max_rate_deviation:.3g} rad/s")
    if r.unmatched:
        why = ("a second state at one stamp, or recorded settings (t_end, output_interval) that do not describe the "
               "run that wrote them" if r.source == "scene" else "a state at another stamp than the interval it "
               "follows (the rachis/accel_applied of its own lost from the recording?)")
        print(f"grapefmu: check failed: {a.recording}: {r.unmatched} recorded joint states (the first at t = "
              f"{r.first_unmatched:.6f} s) have no sample in the re-simulation: {why}", file=sys.stderr)
        return 1
    if r.missing:
        why = ", or recorded settings (t_end, output_interval) that do not describe the run that wrote it"
        print(f"grapefmu: check failed: {a.recording}: {r.missing} re-simulated samples (the first at t = "
              f"{r.first_missing:.6f} s) have no recorded joint state: states left out of the recording"
              f"{why if r.source == 'scene' else ''}", file=sys.stderr)
        return 1
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
    _compiling()
    if a.scale:
        from .bench.scale import main as scale
        return scale(Path(a.out), Path(a.plots))
    from .bench.harness import main as bench
    return bench(a.quick, Path(a.out), Path(a.plots))


class Help(argparse.HelpFormatter):
    """Every option's help ends with its default, unless the text already says it (a flag's default is off)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or action.default is None or action.default is False \
                or action.default is argparse.SUPPRESS or not action.option_strings:
            return text
        return f"{text} (default: %(default)s)"


def _count(n: int, one: str, many: str | None = None) -> str:
    """'1 berry', '2 berries'."""
    return f"{n} {one if n == 1 else many or one + 's'}"


METHODS = ("event: adaptive Dormand–Prince 5(4), 8(5,3) below rtol 1e-7 (1e-5 for fewer than 10 berries), every "
           "contact onset and release located "
           "exactly (the default); "
           "paper: the paper's ode23 with contacts checked only at step ends, cross-checked against event; "
           "reference: scipy solve_ivp (DOP853) with scipy's event location, slow, an independent check "
           "(docs/solver.md)")

COMMANDS = {  # name: one-line description (also the --help page's first line)
    "simulate": "Run a scene and report impacts, peak forces, damage and detachment indicators; write the samples "
                "(CSV, Parquet, MCAP) and a figure.",
    "paper": "Reproduce tests 1–9 of Xu et al. (2025): figures and a check of each of the paper's claims.",
    "cluster": "Generate a cluster scene (seeded, spherical twigs) or a planar row of berries as a scene TOML.",
    "sweep": "Run a grid or Monte Carlo sweep over scene parameters, one Parquet row per run (resumable).",
    "fit": "Estimate scene parameters (hinge, contact, coupling) from measured swings by least squares on the "
           "solver: estimates, standard errors, correlations, residual plots and a fitted scene TOML.",
    "risk": "Probability of bruising and detachment for handling plans under uncertain parameters (Monte Carlo on "
            "the sweep engine, resumable), plans side by side, and the fastest plan under a bruise bound.",
    "build-fmu": "Package a scene as an FMI 2 or 3 co-simulation FMU.",
    "replay": "Check a recording by re-simulating it, or republish its topics on ROS 2.",
    "outputs": "List every output channel (name, unit, file column, ROS topic, FMU causality) as Markdown.",
    "bench": "Measure speed against error on hard scenes, side by side with peer methods; write a Markdown report "
             "and plots (under out/bench unless told).",
}


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="grapefmu", description="Berries that swing and collide when a gripper moves a grape cluster.",
                formatter_class=Help)
    ap.add_argument("--version", action="version", version=f"grapefmu {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, epilog: str | None = None) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=COMMANDS[name], description=COMMANDS[name], epilog=epilog,
                              formatter_class=Help)

    s = command("simulate", "The first run in a fresh checkout compiles the numba core (README.md: how long); "
                            "later runs load it from the cache.")
    s.add_argument("scene", nargs="?",
                   help="scene TOML (default: the packaged default scene, the same as scenes/default.toml)")
    s.add_argument("--t-end", type=float, metavar="S", help="simulated time in s (default: the scene's solver.t_end)")
    s.add_argument("--rtol", type=float, help="relative tolerance (default: the scene's solver.rtol)")
    s.add_argument("--atol", type=float, help="absolute tolerance (default: the scene's solver.atol)")
    s.add_argument("--method", choices=("event", "paper", "reference"),
                   help=f"integration method (default: the scene's solver.method). {METHODS}")
    s.add_argument("--out", action="append", metavar="FILE",
                   help="write the samples to FILE: .csv, .parquet or .mcap; give it again for more files "
                        "(--out a.csv --out b.mcap), every one checked before the run (default: none)")
    s.add_argument("--plot", metavar="FILE", help="write a figure, .png, .pdf or .svg (default: none)")
    s.add_argument("--strict", action="store_true",
                   help="exit with code 3 when the run has warnings (results that cannot be trusted)")
    s.set_defaults(func=cmd_simulate)
    p = command("paper")
    p.add_argument("--out", default="out/paper", metavar="DIR", help="directory for the figures and claims.md")
    p.set_defaults(func=cmd_paper)
    c = command("cluster")
    c.add_argument("-o", "--output", required=True, metavar="FILE", help="the scene TOML to write (required)")
    c.add_argument("--berries", type=int, default=60, help="number of berries")
    c.add_argument("--seed", type=int, help="random seed (default: 1)")
    c.add_argument("--row", action="store_true", help="a planar row on one rod (Newton's cradle) instead")
    c.add_argument("--pitch", type=float, metavar="M",
                   help="--row: hinge spacing in m (default: 0.027, touching at rest)")
    c.add_argument("--precompression", type=float, metavar="M",
                   help="largest overlap of two berries at rest, m (default: 0)")
    from .cluster.generate import ClusterSpec
    for name, unit in (("diameter", "m"), ("twig_length", "m"), ("hinge_stiffness", "N·m/rad"),
                       ("hinge_damping", "N·m·s/rad")):
        d = getattr(ClusterSpec, name)
        c.add_argument(f"--{name.replace('_', '-')}", type=float, nargs=2, metavar=("MEAN", "SD"),
                       help=f"normal distribution of the {name.replace('_', ' ')}, {unit} "
                            f"(default: {d.mean:g} {d.sd:g})")
    c.set_defaults(func=cmd_cluster)
    w = command("sweep")
    w.add_argument("spec", help="sweep spec TOML (docs/sweeps.md)")
    w.add_argument("-o", "--output", metavar="FILE", help="the Parquet file (default: the spec's name with .parquet)")
    w.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    w.add_argument("--scheduler", metavar="ADDRESS",
                   help="a Dask distributed scheduler, tcp://host:port, instead of local processes (default: none)")
    w.set_defaults(func=cmd_sweep)
    f = command("fit", "The measured CSV has the simulator's columns: time_s, angle_<angle>_rad per tracked angle, and "
                       "optionally base_ax_m_s2 and base_az_m_s2 (the gripper). docs/fit_and_risk.md")
    f.add_argument("scene", help="scene TOML: the rig, its initial state (a starting guess) and starting values")
    f.add_argument("data", nargs="+", help="measured CSV, one per recorded series")
    f.add_argument("--param", action="append", metavar="KEY", required=True,
                   help="a parameter to estimate, given again for more: berries[*].hinge_stiffness (shared), "
                        "berries[0].hinge_damping (one twig), contact.stiffness, contact.restitution, "
                        "contact.damping, coupling.stiffness, ... (required)")
    f.add_argument("-o", "--output", required=True, metavar="FILE", help="the fitted scene TOML to write (required)")
    f.add_argument("--report", metavar="FILE", help="a JSON report: estimates, covariance, what risk --fit reads "
                                                     "(default: none)")
    f.add_argument("--plot", metavar="FILE", help="residual plots, .png, .pdf or .svg (default: none)")
    f.add_argument("--segments", type=int, default=1,
                   help="cut each series into this many pieces, each started from its own estimated state")
    f.add_argument("--rtol", type=float, help="the solver's relative tolerance while fitting (default: 1e-10)")
    f.add_argument("--atol", type=float, help="the solver's absolute tolerance while fitting (default: 1e-12)")
    f.set_defaults(func=cmd_fit)
    k = command("risk", "Every plan runs over the same draws. Probabilities carry 95 % Clopper–Pearson intervals. "
                        "docs/fit_and_risk.md")
    k.add_argument("plans", nargs="+", help="scene TOMLs, one per handling plan (their excitation is the plan)")
    k.add_argument("--fit", metavar="FILE", help="the parameters' distribution from a fit (grapefmu fit --report): "
                                                 "normal in log p with the fit's covariance (default: none)")
    k.add_argument("--range", action="append", metavar="KEY=LOW:HIGH",
                   help="a parameter drawn log-uniformly (the restitution logit-uniformly) in [LOW, HIGH]; replaces "
                        "the fit's distribution for that key; give it again for more (default: none)")
    k.add_argument("--samples", type=int, default=200, help="draws (runs per plan)")
    k.add_argument("--seed", type=int, default=1, help="seed of the draws")
    k.add_argument("--out", default="out/risk", metavar="DIR",
                   help="directory for the tables (one per plan and searched scale), risk.md, risk.json, risk.png")
    k.add_argument("--max-bruise", type=float, metavar="P",
                   help="search the first plan's fastest duration whose bruise probability is shown at most P "
                        "(default: no search)")
    k.add_argument("--scales", default="0.25:4", metavar="LOW:HIGH",
                   help="the time scales the search considers (moves' durations times the scale)")
    k.add_argument("--workers", type=int, help="local worker processes, 0: this process (default: one per core)")
    k.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler, tcp://host:port (default: none)")
    k.set_defaults(func=cmd_risk)
    b = command("build-fmu")
    b.add_argument("scene", nargs="?", help="scene TOML (default: the packaged default scene)")
    b.add_argument("-o", "--output", required=True, metavar="FILE", help="the .fmu file to write (required)")
    b.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version")
    b.add_argument("--outputs", choices=("full", "summary"),
                   help="per angle, berry and pair, or cluster totals only (default: full up to 16 berries and pairs)")
    b.add_argument("--cross-check", metavar="DIR",
                   help="also write the FMI cross-check package (FMU, _in.csv, _ref.csv, _ref.opt, ReadMe) under DIR "
                        "(default: none)")
    b.set_defaults(func=cmd_build_fmu)
    r = command("replay")
    r.add_argument("recording", help="an MCAP file written by grapefmu simulate or the ROS node")
    g = r.add_mutually_exclusive_group(required=True)
    g.add_argument("--check", action="store_true", help="re-simulate and report the largest deviation")
    g.add_argument("--publish", action="store_true", help="republish the recorded topics with /clock (Ctrl-C stops)")
    r.add_argument("--rate", type=float, default=1.0, help="with --publish: speed factor, 0 = as fast as possible")
    r.set_defaults(func=cmd_replay)
    o = command("outputs")
    o.set_defaults(func=cmd_outputs)
    be = command("bench", "Maintainers regenerate the committed report with --out docs/benchmarks.md --plots "
                          "docs/bench (README.md, Maintainers).")
    be.add_argument("--quick", action="store_true", help="two scenes, few settings (minutes on 2 cores)")
    be.add_argument("--scale", action="store_true", help="cost against the number of berries, N = 2 … 300 "
                                                          "(rewrites only its own section of the report)")
    be.add_argument("--out", default="out/bench/benchmarks.md", metavar="FILE", help="the Markdown report to write")
    be.add_argument("--plots", default="out/bench", metavar="DIR",
                    help="directory for one work–precision plot per scene and rows.json")
    be.set_defaults(func=cmd_bench)
    return ap


def _check_overrides(a: argparse.Namespace) -> None:
    from .model.bounds import bound
    from .model.model import SolverSettings
    for name in ("t_end", "rtol", "atol"):  # the scene file's ranges (solver.t_end, ...)
        v, b = getattr(a, name, None), bound(SolverSettings, name)
        if v is not None and not b.holds(v):
            raise GrapefmuError(f"--{name.replace('_', '-')}: expected {b.allowed}, got {v!r}")
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


#: the signals _on_signal turned into Interrupted: raised inside a library's Python code (numba boxing a compiled
#: object, say), the exception may come out as another one
_received: list[int] = []


def _on_signal(signum, frame):
    # a second signal while cleaning up ends the process at once (the next writer removes what it left)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _received.append(signum)
    raise Interrupted(signum)


def _redeliver(unraisable) -> None:
    """sys.unraisablehook while a command runs. An Interrupted raised inside a callback from C (llvmlite's object
    cache, which numba calls while it compiles) is printed as a traceback and dropped there, and the command would
    run on: raise it again a moment later, back in Python code. Anything else goes to the default hook."""
    e = unraisable.exc_value
    if not isinstance(e, Interrupted):
        sys.__unraisablehook__(unraisable)
        return
    signal.signal(signal.SIGALRM, lambda _signum, frame: _on_signal(e.signum, frame))
    signal.setitimer(signal.ITIMER_REAL, 0.01)


def _interrupted_by(e: BaseException) -> bool:
    """Whether e ends the command because of SIGINT or SIGTERM: the Interrupted raised, or what a library made of it."""
    return isinstance(e, KeyboardInterrupt) or bool(_received)


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
           "fit": ("output", "report", "plot"), "risk": ("out",),
           "paper": ("out",), "bench": ("out", "plots")}


def _stamp(path: str) -> tuple | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def _targets(a: argparse.Namespace) -> list[str]:
    """The paths the command writes (an option given several times, as simulate --out, gives several)."""
    out = []
    for k in TARGETS.get(a.command, ()):
        v = getattr(a, k, None)
        out += [str(p) for p in (v if isinstance(v, list) else [v]) if p]
    return out


def _interrupted(a: argparse.Namespace, before: dict[str, tuple | None]) -> str:
    """What an interruption leaves: every file target not replaced since the start is untouched."""
    paths = _targets(a)
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
    a.argv = list(sys.argv[1:] if argv is None else argv)  # as typed: a report names the command that made it
    cmd = f"grapefmu {a.command}"
    before = {p: _stamp(p) for p in _targets(a)}
    handlers, hook = {}, sys.unraisablehook
    if threading.current_thread() is threading.main_thread():
        handlers = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
        handlers[signal.SIGALRM] = signal.getsignal(signal.SIGALRM)
        sys.unraisablehook = _redeliver
    _received.clear()
    try:
        try:
            _check_overrides(a)
            return a.func(a)
        except BaseException as e:
            if _interrupted_by(e):
                signum = getattr(e, "signum", _received[0] if _received else signal.SIGINT)
                note = getattr(e, "note", None)
                print(f"{_newline()}{cmd}: {_interrupted(a, before)}{'; ' + note if note else ''}", file=sys.stderr)
                return 128 + signum
            if not isinstance(e, (GrapefmuError, OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError,
                                  OverflowError, MemoryError)):
                raise
            text, code = _explain(e)
            print(f"{_newline()}{cmd}: {' '.join(text.split())}", file=sys.stderr)
            return code
    finally:
        if handlers:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            sys.unraisablehook = hook
        for sig, h in handlers.items():
            if h is not None:
                signal.signal(sig, h)


def _newline() -> str:
    """A newline if a progress bar is on screen, so the message that follows starts its own line."""
    said, Progress.open_line = Progress.open_line, False
    return "\n" if said else ""


if __name__ == "__main__":
    sys.exit(main())
