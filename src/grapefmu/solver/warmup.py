"""The numba core's first compile: a one-line notice before it, and its time kept apart from the solver's.

numba compiles the core on its first call in a process, or loads it from its cache (an index `*.nbi` and
data `*.nbc` per function in `__pycache__` beside the sources, or under NUMBA_CACHE_DIR). Compiling takes
COMPILE_SECONDS on the machines measured (README.md: how), loading from the cache about a second.

- `cache_is_cold()`: no usable cached code for the core (read from numba's index files, nothing compiled).
- `notice()`: once per process, when the cache is cold, one line on stderr (or to `write`) before the compile.
- `prepare(scene)`: compile or load everything a run of the scene calls (its first output interval, its
  summary and columns) and return the seconds taken, so the run that follows measures the solver alone.

The command line calls them before a run (the summary's `numba core` row), a sweep's driver says the notice
and its workers prepare before their first run (the row's `compile_time_s`); the FMU and the ROS node can
call the same functions before their first step."""
from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from ..model.model import Scene, runs_in_islands

#: the first compile of the core on a cold cache, s, on the fastest and slowest machine measured (README.md: two
#: cores each, `NUMBA_CACHE_DIR` empty): a range, because the slowest took four times as long as the fastest
COMPILE_SECONDS = (90, 400)
NOTICE = ("grapefmu: compiling the core once ({seconds[0]} to {seconds[1]} s on two cores); later runs load it from "
          "the cache")


class Prepared(NamedTuple):
    seconds: float   # wall time of the compile or cache load (0 when this process had already prepared)
    compiled: bool   # the cache was cold: numba compiled (else it loaded what an earlier process compiled)


def _entry_points() -> tuple:
    """The compiled functions a run starts from: everything else is compiled (or loaded) with them."""
    from ..physics.observe import observe
    from .loop import integrate
    from .session import start
    return integrate, start, observe


def cache_is_cold() -> bool:
    """True when numba has no usable cached code for the core's entry points: no index file, or one written
    for other sources or another numba (numba's own freshness check); never compiles anything."""
    for f in _entry_points():
        if f.overloads:  # compiled or loaded in this process already
            continue
        try:
            if not f._cache._cache_file._load_index():
                return True
        except Exception:  # noqa: BLE001 - numba's internals moved: look for index files beside the sources
            return not any(Path(f.py_func.__code__.co_filename).parent.glob("__pycache__/*.nbi"))
    return False


_decided = False  # notice() has looked at the cache in this process (it speaks at most once)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def notice(write: Callable[[str], object] | None = None) -> bool:
    """Say NOTICE (one line, on stderr unless `write` is given) if the core is about to be compiled; at most
    once per process, and only before its first compile. True if it said it."""
    global _decided
    if _decided:
        return False
    _decided = True
    if not cache_is_cold():
        return False
    (write or _stderr)(NOTICE.format(seconds=COMPILE_SECONDS))
    return True


_prepared: set[str] = set()  # method families this process has compiled or loaded ("event" covers "paper")


def prepare(scene: Scene, method: str | None = None, *, say: bool = True,
            write: Callable[[str], object] | None = None) -> Prepared:
    """Compile (or load from the cache) what a run of `scene` with `method` calls, by simulating its first output
    interval and taking that run's summary and columns, after notice() (unless `say` is false). Once per process
    and method family; later calls return Prepared(0.0, False) at once."""
    from .api import simulate

    method = method or scene.solver.method
    family = "reference" if method == "reference" else "event"
    if runs_in_islands(scene.solver.islands, scene.model.n_berries, method, scene.solver.fixed_step):
        family = "islands"  # solver/islands.py's own compiled calls besides the event method's
    if family in _prepared:
        return Prepared(0.0, False)
    cold = cache_is_cold()
    if say:
        notice(write)
    start = time.perf_counter()
    dt = min(scene.solver.output_interval, scene.solver.t_end)
    run = simulate(scene, dt, method=method, output_interval=dt, cross_check=False)
    run.summary()
    run.columns()
    _prepared.add(family)
    return Prepared(time.perf_counter() - start, cold)
