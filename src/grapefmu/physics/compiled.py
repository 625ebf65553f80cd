"""The numba decorators every compiled module uses (one place for the compile options and the cache's stamp), and
how numba counts references in this process."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba as nb
from llvmlite import ir
from numba.core.runtime import nrt, nrtdynmod

#: set to 1 to keep numba's atomic reference counts (see plain_reference_counts)
ATOMIC_REFCOUNTS_VARIABLE = "GRAPEFMU_ATOMIC_REFCOUNTS"


def plain_reference_counts() -> bool:
    """Make numba's reference counts plain increments instead of atomic ones, if numba has not started its runtime
    yet in this process; returns whether they are plain.

    Why: the compiled core extracts arrays from its model and state records all the time, and each extraction costs
    an increment and a decrement of the array's count. Atomic (lock-prefixed) ones took about 60 % of a run's time
    on the benchmark machine (perf); plain ones cut the paper-collision run by about a third at rtol 1e-6 and 1e-10
    (benchmarks/refcounts.py). Safe because every compiled function here holds the GIL (no nogil, no parallel:
    tests/test_compiled.py checks), so no two threads touch a count at once. numba's runtime is process-wide: other
    numba code in the process that releases the GIL needs atomic counts; set GRAPEFMU_ATOMIC_REFCOUNTS=1 for it (or
    start numba's runtime before importing grapefmu, which leaves the counts atomic).

    How: numba builds its runtime's nrt_atomic_add/sub from nrtdynmod._define_atomic_inc_dec when the runtime starts;
    this replaces that builder with _plain_inc_dec. (numba's own `_disable_atomicity` switch is not usable: its plain
    variant returns the count before the decrement, so NRT_decref never sees zero and nothing numba manages is ever
    freed: every run leaked its recorder, 0.46 MB per 2 s simulated, tests/test_compiled.py.)"""
    if os.environ.get(ATOMIC_REFCOUNTS_VARIABLE, "") not in ("", "0"):
        return False
    if nrt.rtsys._init:  # started already: its counting functions are compiled
        return nrtdynmod._define_atomic_inc_dec is _plain_inc_dec
    nrtdynmod._define_atomic_inc_dec = _plain_inc_dec
    return True


def _plain_inc_dec(module, op, ordering):
    """nrt_atomic_add / nrt_atomic_sub as numba's runtime calls them (a word pointer in, the count after the
    operation out), without the lock prefix: load, add or subtract one, store, return the new count. `ordering` is
    the memory ordering the atomic version takes; a plain one has none."""
    word = nrtdynmod._word_type
    fn = ir.Function(module, ir.FunctionType(word, [word.as_pointer()]), name=f"nrt_atomic_{op}")
    [ptr] = fn.args
    builder = ir.IRBuilder(fn.append_basic_block())
    new = getattr(builder, op)(builder.load(ptr), ir.Constant(word, 1))
    builder.store(new, ptr)
    builder.ret(new)
    return fn


PLAIN_REFCOUNTS = plain_reference_counts()

#: the subpackages whose sources compiled code is built from (its functions, and the dtypes and constants they read)
CORE = ("bench", "model", "physics", "results", "solver")


def sources_digest(root: Path = Path(__file__).resolve().parents[1]) -> bytes:
    """A digest of every source in CORE under the package root (names and contents)."""
    h = hashlib.sha256()
    for p in sorted(q for sub in CORE for q in (root / sub).rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.digest()


#: what every cached function's index is stamped with besides its own file
SOURCES = sources_digest()


def _stamped(dispatcher):
    """The dispatcher, its cache stamped with SOURCES as well. Why: numba checks a cached function against its own
    file only, yet its machine code holds the functions it calls or inlines from other files. After an edit or an
    upgrade that changed only a callee, a caller loaded stale code from the cache: a wrong result, or a write past
    an array that aborted the process (free(): invalid pointer, 2026-11-26). With the stamp, a change to any core
    source makes every cached function compile again, once. (numba internals, checked by tests/test_compiled.py.)"""
    cache_file = dispatcher._cache._cache_file
    cache_file._source_stamp = (cache_file._source_stamp, SOURCES)
    return dispatcher


_jit = nb.njit(cache=True, error_model="numpy")
_inline = nb.njit(cache=True, error_model="numpy", inline="always")


def jit(f):
    """A compiled function, cached on disk (stamped with SOURCES)."""
    return _stamped(_jit(f))


def inline(f):
    """A small helper compiled into its callers (a call boundary costs more than its arithmetic), cached as jit."""
    return _stamped(_inline(f))
