"""How much memory one run may plan to use, and the scene values that would need more: values that are each
in range but together would exhaust the machine are refused with the estimate before anything is allocated
(the samples a run records are checked by grapefmu.solver.budget, which knows their size)."""
from __future__ import annotations

import functools
import os

from ..errors import SceneError

#: the share of this machine's physical memory one run may plan to use
MEMORY_FRACTION = 0.5
#: copies of the solver state alive at once: the state and the copy a run keeps to restore on failure
STATE_COPIES = 2


@functools.cache
def memory_limit() -> int:
    """Bytes one run may plan to use: MEMORY_FRACTION of the physical memory (of 32 GiB if it cannot be read), read
    once: it does not change while the process runs, and every run asks."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 32 * 2**30
    return int(MEMORY_FRACTION * total)


def gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB"


def limit_text() -> str:
    return f"at most {gib(memory_limit())} ({MEMORY_FRACTION:g} of this machine's memory)"


def check_state(n_pairs: int, zeno_max_events: int, key: str = "solver.zeno_max_events") -> None:
    """Refuse a Zeno-guard ring (zeno_max_events switch times, float64, per contact pair) that would not fit."""
    from ..model.model import SolverSettings

    need = float(n_pairs) * zeno_max_events * 8 * STATE_COPIES
    if need > memory_limit():
        raise SceneError(key, f"{zeno_max_events} switch times kept for each of {n_pairs} contact pairs "
                         f"(berries, contact.pairs) is about {gib(need)} of memory; {limit_text()}: "
                         f"lower {key.rsplit('.', 1)[-1]} (the default is {SolverSettings().zeno_max_events})")
