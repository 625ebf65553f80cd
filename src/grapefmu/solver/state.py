"""The solver's state grouped by concern (MuJoCo's mjData), and what one run records.

Everything that changes while the solver steps lives here and nowhere else, so `get_state`/`set_state`
restore a run exactly. Scalars sit in one-element structured arrays (named fields the compiled core can
write in place); per-pair and per-berry quantities are named arrays.
"""
from __future__ import annotations

import functools
import operator
from typing import NamedTuple

import numpy as np

from ..errors import StateError
from ..physics.compiled import inline, jit
from ..physics.excitation import INPUT
from ..physics.forces import CONTACT
from ..results.contacts import CHANGE
from ..results.records import COUNTERS, IMPACT, TOTALS

__all__ = ["BOOK_PAIR", "CONFIG", "COUNTERS", "CONTACT", "IMPACT", "INPUT", "TOTALS", "Book", "BroadPhase",
           "Integrator", "Physical", "Recorder", "SolverState", "assign", "copy", "flatten", "recorder", "unflatten",
           "zeros"]

#: the solver's settings as the compiled core reads them
CONFIG = np.dtype([("rtol", "f8"), ("atol", "f8"), ("fixed_step", "f8"), ("zeno_window", "f8"), ("locate", "?"),
                   ("h_max", "f8"), ("skin", "f8"), ("step_control", "?"), ("bruise_force", "f8"),
                   ("bruise_energy", "f8"), ("detachment_force", "f8")])
#: integrator scalars; h_contact: the step size error control proposed after the first step of the last contact
#: to open (0 before one has), where the next onset starts (after_onset: the next accepted step sets it); err_last: the
#: last accepted step's error norm, which step-size control's PI term reads (0 before the first)
CLOCK = np.dtype([("h", "f8"), ("t_prev", "f8"), ("h_last", "f8"), ("break_index", "i8"), ("h_contact", "f8"),
                  ("err_last", "f8"), ("after_onset", "?")])
#: per pair: the impact going on (valid while the pair is in contact), running totals, the Zeno guard
BOOK_PAIR = np.dtype([("onset", "f8"), ("approach_speed", "f8"), ("impact_peak", "f8"), ("impact_peak_time", "f8"),
                      ("impulse_at_onset", "f8"), ("dissipated_at_onset", "f8"), ("bruising", "?"),
                      ("peak_force", "f8"),     # N, since the start, refined on the dense output
                      ("impulse", "f8"),        # ∫F dt since the start, N·s
                      ("dissipated", "f8"),     # ∫(F − F_el) δ̇ dt since the start, J
                      ("smooth_until", "f8"),   # s; inf: smooth for good (a smooth law under step-size control)
                      ("ring_pos", "i8")], align=True)
#: the output grid's cursor
CURSOR = np.dtype([("grid_t0", "f8"), ("grid_dt", "f8"), ("grid_k", "i8"), ("n_out", "i8"), ("n_impacts", "i8"),
                   ("n_changes", "i8"), ("grid_end", "f8")])  # grid_end: the run's end, sampled on or off the grid


class Physical(NamedTuple):
    """The state of the berries: time, y = [q | q̇ | energy integrals | base motion] and the contact modes."""

    t: np.ndarray          # (1,) s
    y: np.ndarray          # physics/layout.py
    contacts: np.ndarray   # (P,) CONTACT


class Integrator(NamedTuple):
    """The Runge–Kutta method's memory: the derivative at y, the last step's stages and dense output."""

    f: np.ndarray          # dy/dt at the current state
    y_prev: np.ndarray     # the state at the last step's start
    stages: np.ndarray     # (S, ny): every stage the dense output combines (Tableau.p)
    dense: np.ndarray      # (ny, k): the last step's interpolant coefficients
    clock: np.ndarray      # (1,) CLOCK


class Book(NamedTuple):
    """Impacts, peaks, per-pair integrals and the Zeno guard, kept while stepping so nothing is recomputed."""

    counters: np.ndarray       # (1,) COUNTERS
    totals: np.ndarray         # (1,) TOTALS
    pair: np.ndarray           # (P,) BOOK_PAIR
    peak_tension: np.ndarray   # (N,) N
    ring: np.ndarray           # (P, zeno_max_events) s: each pair's recent switch times (the Zeno guard)


class BroadPhase(NamedTuple):
    """A Verlet list: the pairs closer than the skin when it was built, and every pair in contact."""

    near: np.ndarray       # (P,) pair indices, the first `count` valid, ascending
    count: np.ndarray      # (1,) int
    reference: np.ndarray  # (N, 6) berry centres when the list was built, rachis frame then world frame


class SolverState(NamedTuple):
    physical: Physical
    input: np.ndarray      # (1,) INPUT: the held base acceleration, apart from the scene's excitation
    integrator: Integrator
    book: Book
    broad_phase: BroadPhase
    fingerprint: np.ndarray  # (1,) uint64: the model and method the state belongs to (set_state checks it)


#: the state's groups by their field name (flatten's dotted names)
_GROUPS = {"physical": Physical, "integrator": Integrator, "book": Book, "broad_phase": BroadPhase}


class Recorder(NamedTuple):
    """Where a run's samples, contact changes and finished impacts go (not part of the state). The samples' arrays
    come first (SAMPLED of them)."""

    t: np.ndarray          # (cap,)
    y: np.ndarray          # (cap, ny)
    accel: np.ndarray      # (cap, 6) ACCEL_COMPONENTS
    totals: np.ndarray     # (cap,) TOTALS
    changes: np.ndarray    # (cap_changes,) results.contacts.CHANGE, its sample on the output grid (cursor.grid_k)
    logged: np.ndarray     # (P,) CONTACT: each pair's record as the samples from its last change on hold it
    impacts: np.ndarray    # (cap_impacts,) IMPACT
    cursor: np.ndarray     # (1,) CURSOR


#: the recorder's arrays with a row per sample
SAMPLED = 4


@jit
def recorder(cap, ny, npair, cap_impacts):
    """Rows are read only up to the cursor's counts, each written whole before (record_grid, switch_pair): left
    uninitialised, as zero-filling a run's worth of structured rows cost more than a short run's steps."""
    cursor = np.zeros(1, dtype=CURSOR)
    cursor[0].grid_end = np.inf  # no run's end to sample (a face's steps) until a run sets it
    return Recorder(np.empty(cap), np.empty((cap, ny)), np.empty((cap, 6)), np.empty(cap, dtype=TOTALS),
                    np.empty(max(4 * npair, 64), dtype=CHANGE), np.zeros(npair, dtype=CONTACT),
                    np.empty(cap_impacts, dtype=IMPACT), cursor)


def _dotted(cls=SolverState, prefix: str = ""):
    """The dotted name of every array of a state, in order."""
    for name in cls._fields:
        sub = _GROUPS.get(name)
        if sub is not None:
            yield from _dotted(sub, f"{prefix}{name}.")
        else:
            yield prefix + name


#: (dotted name, getter) of every array of a state: flatten runs four times in a set_state, walking the tuples cost
#: it 0.1 ms
_ARRAYS = tuple((name, operator.attrgetter(name)) for name in _dotted())


def flatten(state: SolverState) -> dict[str, np.ndarray]:
    """Every array of the state by its dotted name ("physical.y", "book.ring", ...)."""
    return {name: get(state) for name, get in _ARRAYS}


def unflatten(arrays: dict[str, np.ndarray], cls=SolverState, prefix: str = ""):
    """The inverse of flatten (arrays are taken as they are: copy first if they are shared)."""
    parts = []
    for f in cls._fields:
        sub = _GROUPS.get(f)
        if sub is not None:
            parts.append(unflatten(arrays, sub, f"{prefix}{f}."))
            continue
        a = arrays.get(prefix + f)
        if a is None:
            raise StateError(f"state {prefix}{f}: missing (not a solver state of this version)")
        parts.append(a)
    return cls(*parts)


def _dup(a: np.ndarray) -> np.ndarray:
    """a.copy(), through bytes for a record array (numpy copies those field by field, ten times slower)."""
    return np.frombuffer(bytearray(a.tobytes()), a.dtype).reshape(a.shape) if a.dtype.names else a.copy()


def copy(state: SolverState) -> SolverState:
    """A deep copy (spelled out: it runs before every step a face takes, so it must be cheap)."""
    P, I, Bk, B = state.physical, state.integrator, state.book, state.broad_phase
    return SolverState(
        Physical(P.t.copy(), P.y.copy(), _dup(P.contacts)), _dup(state.input),
        Integrator(I.f.copy(), I.y_prev.copy(), I.stages.copy(), I.dense.copy(), _dup(I.clock)),
        Book(_dup(Bk.counters), _dup(Bk.totals), _dup(Bk.pair), Bk.peak_tension.copy(), Bk.ring.copy()),
        BroadPhase(B.near.copy(), B.count.copy(), B.reference.copy()), state.fingerprint.copy())


class _Bytes(NamedTuple):
    """The bytes of each of a state's arrays, by its name in SolverState (zeros lays them out)."""

    t: int
    y: int
    contacts: int
    input: int
    f: int
    y_prev: int
    stages: int
    dense: int
    clock: int
    counters: int
    totals: int
    pair: int
    peak_tension: int
    ring: int
    near: int
    count: int
    reference: int
    fingerprint: int


#: bytes per record of the state's record arrays (numba reads a dtype's size only as a number)
_CONTACT_B, _INPUT_B, _CLOCK_B = CONTACT.itemsize, INPUT.itemsize, CLOCK.itemsize
_COUNTERS_B, _TOTALS_B, _BOOK_PAIR_B = COUNTERS.itemsize, TOTALS.itemsize, BOOK_PAIR.itemsize


@inline
def _words(nbytes):
    """8-byte words an array of nbytes takes, rounded up to 16 bytes so that the next one starts aligned."""
    return (nbytes + 15) // 16 * 2


@inline
def _take(memory, free, nbytes):
    """The next nbytes of memory as bytes to view (free[0]: the first word not taken yet)."""
    at = free[0]
    free[0] = at + _words(nbytes)
    return memory[at:at + (nbytes + 7) // 8].view(np.uint8)[:nbytes]


@jit
def zeros(ny, npair, n, stages, k, zeno_max):
    """A state of zeros for ny state variables, npair pairs, n berries, a method of `stages` stages and k dense
    coefficients, as views on one buffer of 8-byte words (returned first): saving the state before a step and
    restoring it after a failure are then one copy of the buffer. Each array starts on a 16-byte boundary.
    Compiled, so that an island's state is made where its session is (session.island), never passing through
    Python."""
    b = _Bytes(t=8, y=8 * ny, contacts=npair * _CONTACT_B, input=_INPUT_B, f=8 * ny, y_prev=8 * ny,
               stages=8 * stages * ny, dense=8 * ny * k, clock=_CLOCK_B, counters=_COUNTERS_B, totals=_TOTALS_B,
               pair=npair * _BOOK_PAIR_B, peak_tension=8 * n, ring=8 * npair * zeno_max, near=8 * npair, count=8,
               reference=48 * n, fingerprint=8)
    end = 0
    for nbytes in b:
        end += _words(nbytes)
    memory = np.zeros(end, np.uint64)
    free = np.zeros(1, np.int64)
    m, f = memory, np.float64
    physical = Physical(_take(m, free, b.t).view(f), _take(m, free, b.y).view(f),
                        _take(m, free, b.contacts).view(CONTACT))
    inp = _take(m, free, b.input).view(INPUT)
    integrator = Integrator(_take(m, free, b.f).view(f), _take(m, free, b.y_prev).view(f),
                            _take(m, free, b.stages).view(f).reshape((stages, ny)),
                            _take(m, free, b.dense).view(f).reshape((ny, k)), _take(m, free, b.clock).view(CLOCK))
    book = Book(_take(m, free, b.counters).view(COUNTERS), _take(m, free, b.totals).view(TOTALS),
                _take(m, free, b.pair).view(BOOK_PAIR), _take(m, free, b.peak_tension).view(f),
                _take(m, free, b.ring).view(f).reshape((npair, zeno_max)))
    broad_phase = BroadPhase(_take(m, free, b.near).view(np.int64), _take(m, free, b.count).view(np.int64),
                             _take(m, free, b.reference).view(f).reshape((n, 6)))
    return memory, SolverState(physical, inp, integrator, book, broad_phase,
                               _take(m, free, b.fingerprint).view(np.uint64))


def _bytes(a: np.ndarray) -> np.ndarray:
    return a.reshape(-1).view(np.uint8)


def assign(target: SolverState, state: SolverState) -> None:
    """Copy a checked `state` into `target`'s arrays, in place and byte for byte (a record array read back from
    bytes may have lost its aligned flag: its bytes are still the same)."""
    source = flatten(state)
    for name, a in flatten(target).items():
        _bytes(a)[:] = np.frombuffer(np.ascontiguousarray(source[name]).tobytes(), np.uint8)


#: fields whose floats may be infinite: never-switched ring slots and peaks not yet seen (−inf), a smooth law
#: under step-size control (smooth_until = +inf)
MAY_BE_INFINITE = {"book.ring", "book.peak_tension", "book.totals.peak_pedicel_tension", "book.pair.smooth_until"}


@functools.lru_cache(maxsize=64)
def _floats_of(name: str, dtype: np.dtype) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """The float fields of the state's array `name` (("",) for a plain float array; () for none), the bytes each
    takes in a record (8 per field, to gather them in one indexing) and whether each must be finite."""
    if not dtype.names:
        fields = ("",) if dtype.kind == "f" else ()
        return fields, np.zeros(0, np.intp), np.array([name not in MAY_BE_INFINITE] * len(fields))
    fields = tuple(f".{n}" for n in dtype.names if dtype.fields[n][0] == np.float64)
    columns = np.array([dtype.fields[f[1:]][1] + k for f in fields for k in range(8)], np.intp)
    return fields, columns, np.array([f"{name}{f}" not in MAY_BE_INFINITE for f in fields])


def _floats(a: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """A record array's float fields as columns (size, k), gathered from its bytes (field by field costs numpy a
    view each: set_state took 0.5 ms); a plain array as it is."""
    if not a.dtype.names:
        return a
    rows = np.ascontiguousarray(a).reshape(-1).view(np.uint8).reshape(a.size, a.dtype.itemsize)
    return np.ascontiguousarray(rows[:, columns]).view(np.float64)  # numpy may lay a fancy index out by columns


def check(state, template: SolverState, n_breaks: int) -> None:
    """Refuse, naming the field, a state that does not fit the solver whose fresh state is `template` and
    whose excitation has n_breaks breakpoints (another scene, another method, another layout) or holds
    values the compiled core cannot trust (NaN, out-of-range indices and modes). Raises StateError."""

    if not isinstance(state, SolverState):
        raise StateError(f"state: expected the SolverState that get_state returns, got {type(state).__name__}")
    try:
        got = flatten(state)
    except AttributeError as e:
        raise StateError(f"state: not a SolverState of this version ({e})") from None
    want = flatten(template)
    for name, ref in want.items():
        a = got.get(name)
        if not isinstance(a, np.ndarray):
            raise StateError(f"state {name}: expected an array, got {type(a).__name__}")
        if a.dtype != ref.dtype or a.shape != ref.shape:
            raise StateError(f"state {name}: {a.dtype.str if not a.dtype.names else 'record'} {a.shape} does not "
                             f"match this solver's {ref.shape} (a state from another scene or method?)")
    if state.fingerprint[0] != template.fingerprint[0]:
        raise StateError("state fingerprint: the state was made by another scene or method (same sizes, other "
                         "parameters); the solver keeps its own")
    for name, a in got.items():
        fields, columns, finite = _floats_of(name, a.dtype)
        if not fields:
            continue
        v = _floats(a, columns)
        if np.isfinite(v).all():
            continue
        bad = np.isnan(v) | (np.isinf(v) & finite)  # a plain array's one flag broadcasts
        if bad.any():
            k = int(np.argwhere(bad)[0][-1]) if a.dtype.names else 0
            raise StateError(f"state {name}{fields[k]}: {v[bad].flat[0]!r} is not a finite number")
    npair = state.physical.contacts.shape[0]
    mode = state.physical.contacts["mode"]
    if ((mode < 0) | (mode > 2)).any():
        raise StateError(f"state physical.contacts.mode: {int(mode[(mode < 0) | (mode > 2)][0])} is not 0, 1 or 2")
    if (state.physical.contacts["v_onset"] <= 0).any():
        raise StateError("state physical.contacts.v_onset: onset speeds must be > 0 m/s")
    count = int(state.broad_phase.count[0])
    if not 0 <= count <= npair:
        raise StateError(f"state broad_phase.count: {count} is outside [0, {npair}]")
    near = state.broad_phase.near[:count]
    every = state.broad_phase.near
    if ((every < 0) | (every >= max(npair, 1))).any() or (np.diff(near) <= 0).any():
        raise StateError(f"state broad_phase.near: pair indices must rise strictly within [0, {npair})")
    listed = np.zeros(npair, bool)
    listed[near] = True
    if (mode[~listed] != 0).any():
        raise StateError("state broad_phase.near: a pair in contact is missing from the near list")
    ring_pos = state.book.pair["ring_pos"]
    if ((ring_pos < 0) | (ring_pos >= state.book.ring.shape[1])).any():
        raise StateError(f"state book.pair.ring_pos: outside [0, {state.book.ring.shape[1]})")
    clock = state.integrator.clock[0]
    if not (clock["h"] >= 0 and clock["h_contact"] >= 0) or not 0 <= clock["break_index"] <= n_breaks:
        raise StateError(f"state integrator.clock: the step sizes h and h_contact must be ≥ 0 and the breakpoint "
                         f"index within [0, {n_breaks}]")
    for f in state.book.counters.dtype.names:
        if state.book.counters[f][0] < 0:
            raise StateError(f"state book.counters.{f}: must be ≥ 0")
