"""The memory a run's samples will take, estimated before anything is allocated, so that a t_end and an
output interval that are each in range but together would exhaust the machine are refused with the estimate
instead of failing an hour in (the limit, and the Zeno-guard check, are in grapefmu.scenefile.budget)."""
from __future__ import annotations

import functools
import math

from ..errors import SceneError
from ..scenefile.budget import gib, limit_text, memory_limit

#: copies of each sample alive at the peak: the recorder, the run's derived series, the writer's columns
#: and their stacked table (measured: 4 to 5 times the recorder on the default scene and on a 60-berry cluster)
SAMPLE_COPIES = 5


def sample_bytes(model) -> int:
    """Bytes one output sample takes in the recorder (its arrays, so this follows the recorder's layout), and in
    each pair's contact record at it (the run's dense `contacts`, built when asked for)."""
    return _sample_bytes(model.n_berries, model.n_dof, len(model.couplings), len(model.pairs))


@functools.lru_cache(maxsize=256)
def _sample_bytes(n_berries: int, n_dof: int, n_couplings: int, n_pairs: int) -> int:
    """sample_bytes by the model's sizes (a recorder is built to measure one: cached, as every run asks)."""
    from ..physics.forces import CONTACT
    from ..physics.layout import layout
    from .state import SAMPLED, recorder

    ny = layout(n_berries, n_dof, n_couplings, moving=True, turning=True).size  # the larger one
    return sum(a.nbytes for a in recorder(1, ny, n_pairs, 0)[:SAMPLED]) + n_pairs * CONTACT.itemsize


def check_samples(model, t_end: float, output_interval: float, t_key: str = "solver.t_end",
                  dt_key: str = "solver.output_interval") -> None:
    """Refuse a run whose samples would not fit in memory, naming both keys and the estimate."""
    samples = math.floor(t_end / output_interval) + 2
    need = float(samples) * sample_bytes(model) * SAMPLE_COPIES
    if need > memory_limit():
        raise SceneError(f"{t_key}, {dt_key}", f"{t_end:g} s every {output_interval:g} s is {samples:.3g} samples, "
                         f"about {gib(need)} of memory; {limit_text()}: shorten the run or raise the output interval")
