"""`simulate(scene)`: a whole run with the method the scene (or the caller) asks for."""
from __future__ import annotations

import math
from collections.abc import Callable

from ..errors import GrapefmuError
from ..model.excitation import check_covers
from ..model.model import Scene, runs_in_islands
from ..results.run import Run
from .budget import check_samples
from .components import run_by_group
from .islands import Islands
from .solver import Solver, refuse_out_of_range

#: a paper-method run is compared with an event-located run of the same scene up to this many berries
#: (the second run costs about as much as the first; beyond this the warning says it was skipped)
CROSS_CHECK_MAX_BERRIES = 10
#: peak contact forces that differ by more than this fraction of the event-located one disagree
CROSS_CHECK_FORCE_TOLERANCE = 0.2


def simulate(scene: Scene, t_end: float | None = None, *, method: str | None = None, rtol: float | None = None,
             atol: float | None = None, fixed_step: float | None = None, output_interval: float | None = None,
             progress: Callable[[float, float], None] | None = None, cross_check: bool | None = None) -> Run:
    """A whole run. Groups of berries that can never interact are integrated one group at a time
    (solver/components.py); Solver itself steps the whole scene together, as an FMU or node must. With
    `solver.islands` true, or "auto" (the default) and a group of at least ISLANDS_FROM berries, an event-located
    run with adaptive steps goes in multirate islands (solver/islands.py); a caller's method or fixed step that
    islands cannot take runs without them.

    A 'paper' run (contacts checked at step ends, no event location) is compared with an 'event' run of
    the same scene (`cross_check`, on by default for the paper method); a disagreement, or a comparison
    skipped because the scene is too large, becomes a line of `run.summary()["warnings"]`."""
    method = method or scene.solver.method
    refuse_out_of_range(t_end=t_end, output_interval=output_interval, rtol=rtol, atol=atol, fixed_step=fixed_step)
    check_samples(scene.model, scene.solver.t_end if t_end is None else t_end,
                  scene.solver.output_interval if output_interval is None else output_interval,
                  "solver.t_end" if t_end is None else "t_end",
                  "solver.output_interval" if output_interval is None else "output_interval")
    check_covers(scene.excitation, scene.solver.t_end if t_end is None else t_end,
                 "solver.t_end" if t_end is None else "t_end")
    def hook(done: float, share: float) -> Callable[[float, float], None] | None:
        """progress, of a group's run placed within the whole run's."""
        return None if progress is None else lambda t, te: progress((done + share * t / te) * te, te)

    if method == "reference":
        from .reference import simulate_reference
        return run_by_group(scene, lambda sc, done, share: simulate_reference(
            sc, t_end, rtol=rtol, atol=atol, output_interval=output_interval, progress=hook(done, share)))

    step = scene.solver.fixed_step if fixed_step is None else fixed_step

    def one(sc: Scene, done: float, share: float) -> Run:
        if runs_in_islands(scene.solver.islands, sc.model.n_berries, method, step):
            return Islands(sc, rtol=rtol, atol=atol, method=method, fixed_step=fixed_step).run(
                t_end, output_interval, hook(done, share))
        return Solver(sc, method=method, rtol=rtol, atol=atol, fixed_step=fixed_step).run(t_end, output_interval,
                                                                                          hook(done, share))

    run = run_by_group(scene, one)
    if method == "paper" and (cross_check is None or cross_check):
        note = compare_with_event(run, t_end, rtol, atol, output_interval)
        if note:
            run.stats["warnings"] = [*run.stats.get("warnings", ()), note]
    return run


def compare_with_event(paper: Run, t_end: float | None, rtol: float | None, atol: float | None,
                       output_interval: float | None) -> str | None:
    """Re-run a paper-method run's scene with event location (adaptive steps, same tolerances) and say
    where the two disagree: a different collision count, or a peak contact force more than
    CROSS_CHECK_FORCE_TOLERANCE away from the event-located one. None when they agree."""
    scene = paper.scene
    n = scene.model.n_berries
    if n > CROSS_CHECK_MAX_BERRIES:
        return (f"paper method not cross-checked against event location: {n} berries (the check runs up to "
                f"{CROSS_CHECK_MAX_BERRIES}); compare with --method event before trusting collisions and forces")
    try:
        event = simulate(scene, t_end, method="event", rtol=rtol, atol=atol, fixed_step=0.0,
                         output_interval=output_interval)
    except GrapefmuError as e:
        return f"paper method not cross-checked against event location: the event run failed ({e})"
    a, b = paper.collision_count, event.collision_count
    fa = float(paper.peak_force.max(initial=0.0))
    fb = float(event.peak_force.max(initial=0.0))
    diff = abs(fa - fb) / fb if fb > 0.0 else (math.inf if fa > 0.0 else 0.0)  # relative to event location's
    if a == b and diff <= CROSS_CHECK_FORCE_TOLERANCE:
        return None
    return (f"paper method disagrees with event location: {a} collisions against {b}, peak contact force "
            f"{fa:.4g} N against {fb:.4g} N ({100 * diff:.0f} % off); contacts checked only at step ends miss or "
            f"distort impacts, use --method event")


__all__ = ["Solver", "simulate"]
