"""When a run's results cannot be trusted: the checks behind `Run.summary()["warnings"]`.

Each check gives one line a user can act on, or nothing. `grapefmu simulate` prints them after the summary
table and exits with code 3 under `--strict`. The checks here need only the run; comparing a paper-method
run with event location needs a second simulation, so solver/api.py does it and leaves its line in
`run.stats["warnings"]`, which `warnings` appends.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..model.contact import Law
from ..model.model import MAX_OVERLAP_FRACTION, Model
from ..physics.kinematics import deepest_overlap

if TYPE_CHECKING:
    from .run import Run

#: A fixed step longer than this fraction of the shortest contact oscillation period is too long.
#: A contact lasts about half a period, so at 1/10 an explicit Runge–Kutta step still puts about five steps
#: into each impact (ωh ≈ 0.63, inside every tableau's stability region, force peak resolved to a few per cent);
#: beyond it the impact is sampled by one or two steps, and the contact force, the collision count and the
#: energy ledger stop meaning anything (issue 16: fixed_step = 1.0 gave 128 collisions and 9.6e10 N).
STEP_FRACTION = 0.1
#: Below this energy scale per berry (J) the ledger's residual is round-off, not an error of the method:
#: 1e-12 J is about 2e6 ulps of a berry's largest energy terms (m g l ≈ 3e-3 J), more than round-off gathers
#: over 1e5 steps, and a millionth of the energy of a 10 g berry on a 3 cm twig swung out by 1 mm (1.6e-6 J).
LEDGER_FLOOR_PER_BERRY = 1e-12


def contact_period(run: Run) -> tuple[float, int] | None:
    """(period in s, pair index) of the stiffest contact pair relative to its mass: T = 2π √(m*/k) with
    m* = m_i m_j / (m_i + m_j) the pair's reduced mass. Kelvin–Voigt's k is its spring constant, for every
    candidate pair (a step that is too long may step over a contact entirely). Hertz and Hunt–Crossley
    (F_el = K δ^1.5) stiffen with penetration; their tangent stiffness dF_el/dδ = 1.5 K^(2/3) F^(1/3) is taken
    at the pair's peak contact force of the run (for Hunt–Crossley that includes the damping part, so the
    stiffness is overestimated, the safe side); a smooth-law pair that never touched sets no bound.
    None when no pair sets a bound."""
    M = run.scene.model.arrays
    pair = M.pair
    if not len(pair):
        return None
    m = M.berry["mass"]
    obstacle = pair["j"] >= len(m)  # it does not move: the berry's own mass (it indexed a berry that is not there)
    mi, mj = m[pair["i"]], m[np.where(obstacle, pair["i"], pair["j"])]
    m_eff = np.where(obstacle, mi, mi * mj / (mi + mj))
    k = pair["stiffness"].astype(float).copy()
    smooth = pair["law"] != int(Law.KELVIN_VOIGT)
    peak = np.maximum(np.asarray(run.peak_force, dtype=float), 0.0)
    k[smooth] = 1.5 * np.cbrt(k[smooth] ** 2 * peak[smooth])
    ok = k > 0.0
    if not ok.any():
        return None
    period = np.full(len(pair), math.inf)
    period[ok] = 2.0 * math.pi * np.sqrt(m_eff[ok] / k[ok])
    p = int(np.argmin(period))
    return float(period[p]), p


def fixed_step_warning(run: Run) -> str | None:
    """A fixed step (solver.fixed_step) longer than STEP_FRACTION of the shortest contact period."""
    h = float(run.stats.get("fixed_step", 0.0) or 0.0)
    if h <= 0.0:
        return None
    found = contact_period(run)
    if found is None:
        return None
    period, p = found
    if h <= STEP_FRACTION * period:
        return None
    model = run.scene.model
    return (f"fixed step {h:.3g} s is too long for the contact stiffness: pair {model.pair_name(p)} oscillates with "
            f"period {period:.3g} s, and a step above 1/{round(1 / STEP_FRACTION)} of it "
            f"({STEP_FRACTION * period:.3g} s) does not resolve an impact; contact forces, collisions and energies "
            f"are not reliable")


def ledger_tolerance(rtol: float) -> float:
    """The relative ledger error above which a run is flagged: 1000 rtol, kept within [1e-6, 1e-2].
    An adaptive run's global error is typically 10–100 × its local tolerance rtol and the ledger integrates
    it over every step and impact, hence the factor 1000 (the default scene closes to 2e-8 at rtol = 1e-8,
    hard contact laws to 5e-6); the floor keeps very tight tolerances from flagging round-off, and the
    ceiling keeps a loose rtol from hiding a ledger that misses 1 % of the energy."""
    return min(max(1e3 * float(rtol), 1e-6), 1e-2)


def ledger_assessment(run: Run) -> tuple[float, float, float]:
    """(relative error, energy scale J, floor J); the relative error is NaN when the scale is below the
    floor. The scale is the largest of the swing energy (largest kinetic energy plus the range of the
    potential energy: what moved between kinetic and potential, so neither a static preload nor a constant
    reference level counts), the largest work done by the base and the energy dissipated."""
    e = run.energy
    kinetic = e["kinetic"]
    potential = e["stored"] - kinetic
    swing = float(np.max(kinetic) + np.ptp(potential)) if len(kinetic) else 0.0
    scale = max(swing, float(np.max(np.abs(e["base_work"]), initial=0.0)),
                float(np.max(run.dissipated, initial=0.0)))
    floor = LEDGER_FLOOR_PER_BERRY * run.scene.model.n_berries
    if not scale > floor:
        return math.nan, scale, floor
    return float(np.max(np.abs(e["residual"]), initial=0.0)) / scale, scale, floor


def ledger_warning(run: Run) -> str | None:
    err, scale, _ = ledger_assessment(run)
    if math.isnan(err):
        return None
    rtol = float(run.stats.get("rtol", run.scene.solver.rtol))
    tol = ledger_tolerance(rtol)
    if err <= tol:
        return None
    return (f"energy ledger error {err:.2e} of the run's energy scale {scale:.3g} J exceeds {tol:.0e} (1000 × rtol "
            f"{rtol:.0e}, within [1e-6, 1e-2]): energy is not conserved to the accuracy asked for")


def pressed_too_deep(model: Model, penetration: np.ndarray) -> tuple[int, int, float, float] | None:
    """(sample, pair, δ, bound) of the pair pressed deepest beyond MAX_OVERLAP_FRACTION of the smaller radius (a
    berry's own against an obstacle) in penetration (S, P), m, or None: the contact laws hold for shallow contact and
    a start that deep is refused; a run gets there when its rachis drags berries into an obstacle or an impact is
    far too fast for its law."""
    return deepest_overlap(penetration, MAX_OVERLAP_FRACTION * model.contact_radius)


def overlap_of_radius(model: Model, penetration: np.ndarray) -> float:
    """The deepest overlap in penetration (S, P) over its pair's smaller radius (a berry's own against an obstacle);
    0 when no pair touches."""
    return float((penetration / model.contact_radius).max(initial=0.0))


def overlap_words(model: Model, p: int, delta: float, bound: float, t: float) -> str:
    """What pressed_too_deep found, for a run's warning and the ROS node's diagnostics."""
    pr, nb = model.pairs[p], model.n_berries
    who = (f"berry {model.berries[pr.i].name!r} was {delta * 1e3:.3g} mm inside obstacle "
           f"{model.obstacles[pr.j - nb].name!r}" if pr.j >= nb else
           f"berries {model.berries[pr.i].name!r} and {model.berries[pr.j].name!r} overlapped by {delta * 1e3:.3g} mm")
    return (f"{who} at t = {t:.6g} s, beyond {bound * 1e3:.3g} mm ({MAX_OVERLAP_FRACTION:g} of the "
            f"{'berry' if pr.j >= nb else 'smaller'} radius), where no contact law holds: its contact force and "
            "what follows from it are not physical (a rachis that drags berries into an obstacle, or an impact far "
            "too fast for the law)")


def overlap_warning(run: Run) -> str | None:
    """The deepest overlap of the run's samples beyond its bound (pressed_too_deep), or None."""
    hit = pressed_too_deep(run.scene.model, run.penetration)
    return None if hit is None else overlap_words(run.scene.model, hit[1], hit[2], hit[3], float(run.t[hit[0]]))


def warnings(run: Run) -> list[str]:
    """Every warning about `run`, one line each: the checks above, then those the run was given
    (run.stats["warnings"], e.g. the paper method's comparison with event location)."""
    out = [w for w in (fixed_step_warning(run), ledger_warning(run), overlap_warning(run)) if w]
    return out + [str(w) for w in run.stats.get("warnings", ())]
