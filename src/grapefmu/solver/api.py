"""`simulate(scene)`: a whole run with the method the scene (or the caller) asks for."""
from __future__ import annotations

from collections.abc import Callable

from ..model.model import Scene
from ..results.run import Run
from .components import run_by_group
from .solver import Solver


def simulate(scene: Scene, t_end: float | None = None, *, method: str | None = None, rtol: float | None = None,
             atol: float | None = None, fixed_step: float | None = None, output_interval: float | None = None,
             progress: Callable[[float, float], None] | None = None) -> Run:
    """A whole run. Groups of berries that can never interact are integrated one group at a time
    (solver/components.py); Solver itself steps the whole scene together, as an FMU or node must."""
    method = method or scene.solver.method
    if method == "reference":
        from .reference import simulate_reference
        return run_by_group(scene, lambda sc, *_: simulate_reference(sc, t_end, rtol=rtol, atol=atol,
                                                                     output_interval=output_interval))

    def one(sc: Scene, done: float, share: float) -> Run:
        hook = None if progress is None else lambda t, te: progress((done + share * t / te) * te, te)
        return Solver(sc, method=method, rtol=rtol, atol=atol, fixed_step=fixed_step).run(t_end, output_interval, hook)

    return run_by_group(scene, one)


__all__ = ["Solver", "simulate"]
