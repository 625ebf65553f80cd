"""`Run`: what one simulation reports (samples, impacts, energy ledger, summary and indicators)."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..model.model import Scene
from ..physics.dynamics import centres, derived
from ..physics.layout import Layout, layout
from ..solver import core

ENERGY_TERMS = ("kinetic", "gravity", "hinge_elastic", "coupling_elastic", "contact_elastic")


@dataclass
class Impacts:
    """One row per impact: from the pair's first touch (δ = 0, closing) to its separation."""

    pair: np.ndarray          # index into model.pairs
    onset: np.ndarray         # s
    end: np.ndarray           # s (the run's end for an impact still going on)
    approach_speed: np.ndarray  # m/s, δ̇ at onset
    separation_speed: np.ndarray  # m/s, −δ̇ at separation (NaN while ongoing)
    peak_force: np.ndarray    # N
    peak_time: np.ndarray     # s
    impulse: np.ndarray       # N·s
    dissipated: np.ndarray    # J
    ongoing: np.ndarray       # bool

    @property
    def duration(self) -> np.ndarray:
        return self.end - self.onset

    def __len__(self) -> int:
        return len(self.onset)

    @classmethod
    def from_rows(cls, rows: np.ndarray, ongoing: np.ndarray | None = None) -> Impacts:
        rows = rows.reshape(-1, core.IMPACT_COLUMNS)
        order = np.argsort(rows[:, core.I_ONSET], kind="stable")
        rows = rows[order]
        og = np.zeros(len(rows), dtype=bool) if ongoing is None else ongoing[order]
        return cls(rows[:, core.I_PAIR].astype(int), rows[:, core.I_ONSET], rows[:, core.I_END], rows[:, core.I_SPEED],
                   rows[:, core.I_SEP_SPEED], rows[:, core.I_PEAK], rows[:, core.I_TPEAK], rows[:, core.I_IMPULSE],
                   rows[:, core.I_DISS], og)


@dataclass
class Run:
    scene: Scene
    t: np.ndarray
    y: np.ndarray
    mode: np.ndarray
    accel: np.ndarray
    v_onset: np.ndarray
    smooth: np.ndarray
    impacts: Impacts
    peak_force: np.ndarray      # per pair, N (refined on the dense output where the method allows)
    peak_tension: np.ndarray    # per berry, N
    stats: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_solver(cls, scene: Scene, samples, rows: np.ndarray, solver, stats) -> Run:
        S = solver.state
        open_rows = []
        for p in range(S.mode.shape[0]):
            if S.mode[p] != 0:
                o = S.imp_open[p]
                open_rows.append([p, o[core.O_ONSET], S.fl[core.T], o[core.O_SPEED], o[core.O_PEAK], o[core.O_TPEAK],
                                  S.pair_int[p, 0] - o[core.O_J], S.pair_int[p, 1] - o[core.O_D], np.nan])
        allrows = np.vstack([rows.reshape(-1, core.IMPACT_COLUMNS)] + [np.array(open_rows).reshape(-1, core.IMPACT_COLUMNS)])
        ongoing = np.r_[np.zeros(len(rows), bool), np.ones(len(open_rows), bool)]
        t, y, mode, acc, vo, sm = samples
        npair = len(scene.model.pairs)
        return cls(scene, t, y, mode[:, :npair], acc, vo[:, :npair], sm[:, :npair], Impacts.from_rows(allrows, ongoing),
                   S.peak_force.copy(), S.peak_tension.copy(), stats)

    # --- layout and raw state ---------------------------------------------------------------------
    @property
    def layout(self) -> Layout:
        m = self.scene.model
        return layout(m.n_berries, m.n_dof, len(m.couplings))

    @property
    def angles(self) -> np.ndarray:
        return self.y[:, self.layout.q]

    @property
    def angular_velocities(self) -> np.ndarray:
        return self.y[:, self.layout.w]

    @property
    def base_displacement(self) -> np.ndarray:
        return self.y[:, self.layout.base]

    @cached_property
    def positions(self) -> np.ndarray:
        """World positions of the berry centres (n, N, 3), z up: base displacement + hinge + twig."""
        M = self.scene.model.arrays
        out = np.zeros((len(self.t), M.berry.shape[0], 3))
        for k in range(len(self.t)):
            centres(self.y[k], M, out[k])
        out[:, :, 0] += self.base_displacement[:, None, 0]
        out[:, :, 2] += self.base_displacement[:, None, 1]
        return out

    @property
    def active_pairs(self) -> np.ndarray:
        """Pairs in contact at each sample."""
        return (self.mode != 0).sum(axis=1)

    @cached_property
    def _derived(self) -> tuple[np.ndarray, ...]:
        n = len(self.t)
        m = self.scene.model
        p = max(len(m.pairs), 1)
        force, pen = np.zeros((n, p)), np.zeros((n, p))
        tension, energy = np.zeros((n, m.n_berries)), np.zeros((n, 5))
        mode = np.zeros((n, p), dtype=np.int64)
        vo = np.ones((n, p))
        sm = np.zeros((n, p), dtype=np.bool_)
        mode[:, : len(m.pairs)] = self.mode
        vo[:, : len(m.pairs)] = self.v_onset
        sm[:, : len(m.pairs)] = self.smooth
        derived(self.t, np.ascontiguousarray(self.y), mode, np.ascontiguousarray(self.accel), vo, sm, m.arrays,
                force, pen, tension, energy)
        return force[:, : len(m.pairs)], pen[:, : len(m.pairs)], tension, energy

    @property
    def contact_force(self) -> np.ndarray:
        return self._derived[0]

    @property
    def penetration(self) -> np.ndarray:
        return self._derived[1]

    @property
    def pedicel_force(self) -> np.ndarray:
        return self._derived[2]

    # --- energy ledger ------------------------------------------------------------------------------
    @cached_property
    def energy(self) -> dict[str, np.ndarray]:
        """Energies in the rachis' frame (J). `residual` is what the ledger fails to account for:
        stored + dissipated − work done by the base − (the same at t = 0)."""
        e = self._derived[3]
        lay = self.layout
        out = {name: e[:, k] for k, name in enumerate(ENERGY_TERMS)}
        out["dissipated_hinge"] = self.y[:, lay.d_hinge].sum(axis=1)
        out["dissipated_coupling"] = self.y[:, lay.d_coupling].sum(axis=1)
        out["dissipated_contact"] = self.y[:, lay.d_contact]
        out["base_work"] = self.y[:, lay.work]
        stored = e.sum(axis=1)
        dissipated = out["dissipated_hinge"] + out["dissipated_coupling"] + out["dissipated_contact"]
        total = stored + dissipated - out["base_work"]
        out["stored"] = stored
        out["residual"] = total - total[0]
        return out

    def ledger_error(self) -> float:
        """Largest ledger residual relative to the largest energy that moved through the system."""
        e = self.energy
        scale = max(np.max(np.abs(e["stored"])), np.max(np.abs(e["base_work"])),
                    np.max(e["dissipated_hinge"] + e["dissipated_coupling"] + e["dissipated_contact"]), 1e-300)
        return float(np.max(np.abs(e["residual"])) / scale)

    # --- summary --------------------------------------------------------------------------------
    @property
    def collision_count(self) -> int:
        return len(self.impacts)

    def dissipated_per_berry(self) -> np.ndarray:
        """Energy each berry dissipated (J): its hinge, plus half of every contact and coupling it is in."""
        m = self.scene.model
        lay = self.layout
        out = self.y[-1, lay.d_hinge].copy()
        for k, c in enumerate(m.couplings):
            d = self.y[-1, lay.d_coupling.start + k]
            out[c.i] += 0.5 * d
            out[c.j] += 0.5 * d
        imp = self.impacts
        for p, d in zip(imp.pair, imp.dissipated):
            out[m.pairs[p].i] += 0.5 * d
            out[m.pairs[p].j] += 0.5 * d
        return out

    def indicators(self) -> dict[str, Any]:
        th = self.scene.thresholds
        imp = self.impacts
        names = self.scene.model.names
        overload = [names[i] for i in range(len(names)) if self.peak_tension[i] > th.detachment_force]
        bruising = (imp.peak_force >= th.bruise_force) | (imp.dissipated >= th.bruise_energy)
        fatigue = imp.peak_force >= th.fatigue_fraction * th.bruise_force
        return {
            "detachment_risk": bool(overload),
            "berries_over_detachment_force": overload,
            "n_berries_over_detachment_force": len(overload),
            "bruising_impacts": int(bruising.sum()),
            "fatigue_impacts": int(fatigue.sum()),
            "damage_risk": bool(bruising.any()),
        }

    def summary(self) -> dict[str, Any]:
        imp = self.impacts
        per_berry = self.dissipated_per_berry()
        return {
            "t_end": float(self.t[-1]),
            "samples": len(self.t),
            "berries": self.scene.model.n_berries,
            "collision_count": self.collision_count,
            "peak_contact_force": float(self.peak_force.max()) if self.peak_force.size else 0.0,
            "peak_pedicel_force": float(self.peak_tension.max()),
            "max_impact_energy": float(imp.dissipated.max()) if len(imp) else 0.0,
            "energy_dissipated": float(self.energy["dissipated_hinge"][-1] + self.energy["dissipated_coupling"][-1]
                                       + self.energy["dissipated_contact"][-1]),
            "max_dissipated_per_berry": float(per_berry.max()),
            "mean_dissipated_per_berry": float(per_berry.mean()),
            "max_active_pairs": int(self.active_pairs.max()) if len(self.t) else 0,
            **self.indicators(),
            **{k: v for k, v in self.stats.items() if k in (
                "method", "steps", "rejected", "rhs_evaluations", "zeno_guard_activations", "wall_time",
                "degrees_of_freedom", "candidate_pairs", "near_pairs_mean", "near_list_rebuilds")},
        }

    @property
    def touched_pairs(self) -> list[int]:
        """Pairs that were in contact at some point: the only ones whose columns are not all zero."""
        return sorted(set(self.impacts.pair.tolist()) | set(np.flatnonzero(self.mode.any(axis=0)).tolist()))

    # --- columns for writers ----------------------------------------------------------------------
    def columns(self) -> dict[str, np.ndarray]:
        """Per angle, per berry, per pair that touched (a cluster has thousands of idle candidate
        pairs), the cluster's active-pair count and the energy ledger."""
        m = self.scene.model
        cols = {"time": self.t}
        for k, name in enumerate(m.dof_names):
            cols[f"angle_{name}"] = self.angles[:, k]
        for k, name in enumerate(m.dof_names):
            cols[f"angular_velocity_{name}"] = self.angular_velocities[:, k]
        for i, name in enumerate(m.names):
            cols[f"pedicel_force_{name}"] = self.pedicel_force[:, i]
        touched = self.touched_pairs
        for p in touched:
            cols[f"contact_force_{m.pair_name(p)}"] = self.contact_force[:, p]
        for p in touched:
            cols[f"penetration_{m.pair_name(p)}"] = self.penetration[:, p]
        pos = self.positions
        for i, name in enumerate(m.names):
            cols[f"x_{name}"] = pos[:, i, 0]
            cols[f"y_{name}"] = pos[:, i, 1]
            cols[f"z_{name}"] = pos[:, i, 2]
        cols["base_ax"] = self.accel[:, 0]
        cols["base_az"] = self.accel[:, 1]
        cols["active_pairs"] = self.active_pairs
        for k, v in self.energy.items():
            cols[f"energy_{k}"] = v
        return cols
