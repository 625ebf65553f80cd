"""The numba decorators every compiled module uses (one place for the compile options and the cache's stamp), and
how numba counts references in this process."""
from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

import llvmlite.binding as ll
import numba as nb
from llvmlite import ir
from numba.core import codegen
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

_COUNTING = re.compile(r"^define [^\n]*@(NRT_incref|NRT_decref)\(([^\n]*)\)[^\n{]*\{\n(.*?)\n\}\n", re.M | re.S)
_optimize_final_module = codegen.CPUCodeLibrary._optimize_final_module


def _counts_inlined(library) -> None:
    """numba's _optimize_final_module, then NRT_incref and NRT_decref inlined into the library's machine code.

    Why: numba keeps the two counting functions out of line so that its reference-count pruning can see them; after
    the pruning they are still calls, each a few instructions of work behind a call that makes the caller spill its
    registers, and hundreds remain per step (numba's arrays taken out of the model, state and workspace tuples at
    every inlined call; how many, and what inlining them saves: docs/solver.md, "Reference counts").
    How: each call is renamed to an internal always-inline copy of its function and LLVM's always-inliner run. The
    module other libraries link in (numba's _shared_module) is the one from before, with the calls, so a caller that
    inlines this library's functions still prunes across them. The counts' bodies (plain or atomic) are then part of
    every cached function's code: the cache is stamped with which (COUNTS)."""
    _optimize_final_module(library)
    text = str(library._final_module)
    found = list(_COUNTING.finditer(text))
    if not found:
        return
    shared = library._final_module.clone()  # numba's _get_module_for_linking, from the module with the calls
    for fn in shared.functions:
        if not fn.is_declaration and fn.linkage == ll.Linkage.external:
            fn.linkage = "linkonce_odr"
    library._shared_module = shared
    for m in found:
        text = text.replace(f"call void @{m.group(1)}(", f"call void @{m.group(1)}.inline(")
        text += f"\ndefine internal void @{m.group(1)}.inline({m.group(2)}) alwaysinline {{\n{m.group(3)}\n}}\n"
    module = ll.parse_assembly(text)
    module.name = library._final_module.name
    passes = ll.create_new_module_pass_manager()
    passes.add_always_inliner_pass()
    passes.add_instruction_combine_pass()
    passes.add_simplify_cfg_pass()
    passes.run(module, library._codegen._pass_builder())
    module.verify()
    library._final_module = module


codegen.CPUCodeLibrary._optimize_final_module = _counts_inlined
#: how this process counts references, compiled into every function since the counts are inlined (_counts_inlined)
COUNTS = b"plain" if PLAIN_REFCOUNTS else b"atomic"

#: the subpackages whose sources compiled code is built from (its functions, and the dtypes and constants they read)
CORE = ("bench", "model", "physics", "results", "solver")


def sources_digest(root: Path = Path(__file__).resolve().parents[1]) -> bytes:
    """A digest of every source in CORE under the package root (names and contents)."""
    h = hashlib.sha256()
    for p in sorted(q for sub in CORE for q in (root / sub).rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.digest()


def cache_stamp(root: Path = Path(__file__).resolve().parents[1]) -> bytes:
    """What every cached function's index is stamped with besides its own file: the digest of the core's sources
    under root and how this process counts references (COUNTS), both compiled into its machine code."""
    return sources_digest(root) + COUNTS


STAMP = cache_stamp()


def _stamped(dispatcher):
    """The dispatcher, its cache stamped with STAMP as well. Why: numba checks a cached function against its own
    file only, yet its machine code holds the functions it calls or inlines from other files. After an edit or an
    upgrade that changed only a callee, a caller loaded stale code from the cache: a wrong result, or a write past
    an array that aborted the process (free(): invalid pointer, 2026-11-26). With the stamp, a change to any core
    source makes every cached function compile again, once. (numba internals, checked by tests/test_compiled.py.)"""
    cache_file = dispatcher._cache._cache_file
    cache_file._source_stamp = (cache_file._source_stamp, STAMP)
    return dispatcher


_jit = nb.njit(cache=True, error_model="numpy")
_inline = nb.njit(cache=True, error_model="numpy", inline="always")


def jit(f):
    """A compiled function, cached on disk (stamped with STAMP)."""
    return _stamped(_jit(f))


def entry(dispatcher, *args):
    """dispatcher's compiled function for exactly these arguments' types (compiled, or loaded from the cache, once),
    to call without numba's dispatch, which types every argument on every call: 0.7 µs of a face's step
    (benchmarks/call_overhead.py). Only for a caller whose arguments always have these types (Solver.advance
    checks them first): the compiled function converts what it is given to them instead of choosing another."""
    return dispatcher.compile(tuple(nb.typeof(a) for a in args))


def inline(f):
    """A small helper compiled into its callers (a call boundary costs more than its arithmetic), cached as jit."""
    return _stamped(_inline(f))
