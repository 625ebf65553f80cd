"""`Run`: what one simulation reports (samples, impacts, energy ledger, summary and indicators).

Every reported quantity comes from the output catalogue (catalogue.py) evaluated on the run's
`snapshot()`, so a run's columns, its recordings and what the FMU and the ROS node report agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..model.model import Scene
from ..physics import observe as obs
from ..physics.damage import detaching, fatigue, pair_bruise_thresholds
from ..physics.layout import LEDGER_TERMS, Layout, angular_velocity, displacement, ledger, layout_of, orientation
from . import catalogue, trust
from .contacts import ContactLog
from .impacts import Impacts
from .records import WORK


@dataclass
class Run:
    scene: Scene
    t: np.ndarray            # (S,) s
    y: np.ndarray            # (S, ny): physics/layout.py
    contact_log: ContactLog  # each pair's contact record (mode, onset speed, smooth flag) at the samples
    accel: np.ndarray        # (S, 6) physics.excitation.ACCEL_COMPONENTS of the rachis (m/s², rad/s², world frame)
    totals: np.ndarray       # (S,) records.TOTALS at each sample (as of the solver step before it)
    impacts: Impacts
    peak_force: np.ndarray   # (P,) N, per pair, refined on the dense output where the method allows
    peak_tension: np.ndarray  # (N,) N, per berry
    stats: dict[str, Any] = field(default_factory=dict)

    # --- state ----------------------------------------------------------------------------------
    @cached_property
    def bruise_thresholds(self) -> np.ndarray:
        """(P, 2): the peak force (N) and dissipated energy (J) at which an impact of each pair bruises (the
        scene's between berries, an obstacle's own against it)."""
        th = self.scene.thresholds
        return pair_bruise_thresholds(self.scene.model.arrays, th.bruise_force, th.bruise_energy)

    @property
    def layout(self) -> Layout:
        return layout_of(self.scene)

    @property
    def angles(self) -> np.ndarray:
        return self.y[:, self.layout.q]

    @property
    def angular_velocities(self) -> np.ndarray:
        return self.y[:, self.layout.w]

    @property
    def base_displacement(self) -> np.ndarray:
        return displacement(self.layout, self.y)

    @property
    def base_angular_velocity(self) -> np.ndarray:
        return angular_velocity(self.layout, self.y)

    @property
    def base_orientation(self) -> np.ndarray:
        return orientation(self.layout, self.y)

    @cached_property
    def contacts(self) -> np.ndarray:
        """(S, P) physics.forces.CONTACT: each pair's mode, onset speed and smooth flag at each sample."""
        return self.contact_log.dense(len(self.t))

    @cached_property
    def mode(self) -> np.ndarray:
        """(S, P) int8 contact modes: 0 apart, 1 loaded, 2 overlapping but unloaded."""
        return self.contact_log.mode(len(self.t))

    @property
    def active_pairs(self) -> np.ndarray:
        """Pairs in contact at each sample."""
        return catalogue.channel("active_pairs").value(self.snapshot())

    # --- observation ------------------------------------------------------------------------------
    @cached_property
    def observation(self) -> obs.Observation:
        m = self.scene.model
        out = obs.empty(len(self.t), m.n_berries, m.n_dof, len(m.pairs))
        obs.observe(np.ascontiguousarray(self.y), np.ascontiguousarray(self.contacts), np.ascontiguousarray(self.accel),
                    self.scene.arrays, out)
        return out

    @cached_property
    def ledger(self) -> np.ndarray:
        """(S, 4) J: physics.layout.LEDGER_TERMS, the energy integrals that ride along in y."""
        return ledger(self.layout, self.y)

    def snapshot(self) -> catalogue.Snapshot:
        return catalogue.Snapshot(self.t, self.angles, self.angular_velocities, self.mode != 0, self.accel,
                                  self.base_displacement, self.base_angular_velocity, self.base_orientation, self.ledger, self.totals, self.observation,
                                  self.scene.model.obstacle_pairs)

    @property
    def contact_force(self) -> np.ndarray:
        return self.observation.contact_force

    @property
    def penetration(self) -> np.ndarray:
        return self.observation.penetration

    @property
    def pedicel_tension(self) -> np.ndarray:
        return self.observation.pedicel_tension

    @property
    def hinge_torque(self) -> np.ndarray:
        return self.observation.hinge_torque

    @cached_property
    def positions(self) -> np.ndarray:
        """World positions of the berry centres (S, N, 3), z up: base displacement + hinge + twig."""
        s = self.snapshot()
        return np.stack([catalogue.channel(f"position_{a}").value(s) for a in "xyz"], axis=-1)

    # --- energy ledger ------------------------------------------------------------------------------
    @cached_property
    def energy(self) -> dict[str, np.ndarray]:
        """The energy ledger (J): stored terms, dissipated so far, work done by the base, `stored` and
        `residual` (stored + dissipated − work − the same at the first sample), from the catalogue."""
        terms = [*(f"energy_{k}" for k in obs.ENERGY_TERMS), *LEDGER_TERMS, "energy_stored", "energy_residual"]
        cols = catalogue.table(self.snapshot(), self.scene.model, only=[catalogue.channel(k) for k in terms])
        # the ledger's own short names: kinetic, ..., dissipated_hinge, ..., base_work, stored, residual
        return {k.removeprefix("energy_").replace("dissipated_energy_", "dissipated_"): v for k, v in cols.items()}

    @property
    def dissipated(self) -> np.ndarray:
        """Energy dissipated so far by hinges, couplings and contacts, J."""
        return catalogue.dissipated(self.snapshot())

    def ledger_error(self) -> float:
        """Largest ledger residual relative to the run's energy scale (trust.ledger_assessment: the largest of
        the swing energy, the base's work and the energy dissipated); NaN when that scale is below round-off
        (trust.LEDGER_FLOOR_PER_BERRY per berry), where a relative error would only measure noise."""
        return trust.ledger_assessment(self)[0]

    def ledger_report(self) -> str:
        """The ledger error as the summary shows it: relative, or why it is not meaningful."""
        err, scale, _ = trust.ledger_assessment(self)
        if np.isnan(err):
            return f"not meaningful (energy scale {scale:.3g} J)"
        return f"{err:.2e} (relative to the energy scale {scale:.3g} J)"

    # --- summary --------------------------------------------------------------------------------
    def dissipated_per_berry(self) -> np.ndarray:
        """Energy each berry dissipated (J): its hinge, half of every coupling and contact with another berry it is in,
        and the whole of every contact with an obstacle (which takes no share): the shares add up to the total."""
        m = self.scene.model
        lay = self.layout
        out = self.y[-1, lay.d_hinge].copy()
        for k, c in enumerate(m.couplings):
            d = self.y[-1, lay.d_coupling.start + k]
            out[c.i] += 0.5 * d
            out[c.j] += 0.5 * d
        imp = self.impacts
        for p, d in zip(imp.pair, imp.dissipated):
            if m.touches_obstacle(p):  # an obstacle takes no share
                out[m.pairs[p].i] += d
                continue
            out[m.pairs[p].i] += 0.5 * d
            out[m.pairs[p].j] += 0.5 * d
        return out

    def impacts_by_surface(self) -> dict[str, dict[str, Any]]:
        """Per surface an impact can be on, between berries ("berry–berry") then each obstacle by name: its
        impacts (mask over `impacts`), how many, how many bruised, the largest peak force (N) and its bruise
        force (N)."""
        m = self.scene.model
        imp = self.impacts
        which = np.array([max(m.pairs[int(p)].j - m.n_berries + 1, 0) for p in imp.pair], dtype=int)
        surfaces = [("berry–berry", self.scene.thresholds.bruise_force)] + [(o.name, o.bruise_force)
                                                                             for o in m.obstacles]
        out = {}
        for k, (name, limit) in enumerate(surfaces):
            sel = which == k
            out[name] = {"impacts": sel, "count": int(sel.sum()), "bruising": int((sel & imp.bruising).sum()),
                         "peak_force_n": float(imp.peak_force[sel].max(initial=0.0)), "bruise_force_n": limit}
        return out

    def bruised_berries(self) -> list[str]:
        """The berries (names, in the scene's order) in at least one bruising impact: both berries of its pair (an
        obstacle is not a berry)."""
        m = self.scene.model
        hit = {b for p in self.impacts.pair[self.impacts.bruising] for b in (m.pairs[p].i, m.pairs[p].j)
               if b < m.n_berries}
        return [m.names[i] for i in sorted(hit)]

    def summary(self) -> dict[str, Any]:
        """The catalogue's cluster channels at the end of the run, the berries over the detachment force,
        impact and per-berry figures, what the solver did, and `warnings` (results/trust.py). A quantity's key
        carries its unit as a CSV column does (catalogue.file_column: `peak_contact_force_n`, `wall_time_s`);
        counts and flags have none. `compile_time_s`: numba's compile (or cache load) before the run, when the
        caller measured it apart (solver/warmup.py); `wall_time_s` is then the solver's time alone.
        A Run continued from an earlier `Solver.run` or `advance` of the same Solver: its peaks and detachment figures
        are the solver's since its start (its running book, which the faces report), its impact figures are this
        call's impacts (Run.impacts), where its columns' counts are the solver's since its start."""
        th = self.scene.thresholds
        imp = self.impacts
        per_berry = self.dissipated_per_berry()
        names = self.scene.model.names
        over = detaching(self.peak_tension, th.detachment_force)
        unit = catalogue.file_column
        # the run's end state (its impact book and peaks), not its last sample, which may lie before the end
        return {
            unit("t_end", "s"): float(self.t[-1]), "samples": len(self.t), "berries": self.scene.model.n_berries,
            "collision_count": len(imp), "bruising_impacts": int(imp.bruising.sum()),
            unit("peak_contact_force", "N"): float(self.peak_force.max(initial=0.0)),
            unit("peak_pedicel_tension", "N"): float(self.peak_tension.max()),
            unit("dissipated_energy", "J"): float(self.dissipated[-1]),
            "berries_over_detachment_force": int(over.sum()), "detachment_risk": bool(over.any()),
            "detached_berries": [names[i] for i in np.flatnonzero(over)],
            "fatigue_impacts": int(fatigue(imp.peak_force, self.bruise_thresholds[imp.pair.astype(int), 0],
                                           th.fatigue_fraction).sum()),
            "damage_risk": bool(imp.bruising.any()), "bruised_berries": self.bruised_berries(),
            **({"impacts_by_surface": {name: {k: v for k, v in row.items() if k != "impacts"}
                                       for name, row in self.impacts_by_surface().items()}}
               if self.scene.model.obstacles else {}),
            unit("max_impact_energy", "J"): float(imp.dissipated.max()) if len(imp) else 0.0,
            unit("max_dissipated_per_berry", "J"): float(per_berry.max()),
            unit("mean_dissipated_per_berry", "J"): float(per_berry.mean()),
            "max_active_pairs": int(self.active_pairs.max()) if len(self.t) else 0,
            **{k: v for k, v in self.stats.items() if k in (
                "method", "integrator", *WORK, "degrees_of_freedom", "candidate_pairs", "near_pairs_mean", "islands_formed",
                "island_rollbacks")},
            **{unit(k, "s"): self.stats[k] for k in ("wall_time", "compile_time") if k in self.stats},
            "warnings": trust.warnings(self),  # one line each where the results cannot be trusted
        }

    @property
    def collision_count(self) -> int:
        """Impacts in this run (Run.impacts): for a run from the Solver's start, the catalogue's collision_count at its
        end; a continued run's column counts since the Solver's start as well."""
        return len(self.impacts)

    @property
    def touched_pairs(self) -> list[int]:
        """Pairs that were in contact at some point: the only ones whose columns are not all zero."""
        return sorted(set(self.impacts.pair.tolist()) | set(np.flatnonzero(self.mode.any(axis=0)).tolist()))

    def columns(self) -> dict[str, np.ndarray]:
        """time, then every catalogue channel, each named with its unit as CSV and Parquet files name it
        (catalogue.file_column: `time_s`, `angle_left_rad`); per pair only for the pairs that touched (a cluster
        has thousands of idle candidate pairs)."""
        return {catalogue.file_column("time", "s"): self.t,
                **catalogue.table(self.snapshot(), self.scene.model, self.touched_pairs, units=True)}
