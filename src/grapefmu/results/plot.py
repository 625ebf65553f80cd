"""Figures a person reads faster than a table: angles, forces against thresholds, energy ledger."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .run import Run
from .writers import atomic_path


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_run(run: Run, path: str | Path, title: str | None = None) -> None:
    plt = _pyplot()
    m = run.scene.model
    th = run.scene.thresholds
    fig, ax = plt.subplots(5, 1, figsize=(9, 11), sharex=True, constrained_layout=True)
    t = run.t
    for i, name in enumerate(m.names):
        ax[0].plot(t, np.degrees(run.angles[:, i]), label=name)
    ax[0].set_ylabel("twig angle (deg)")
    ax[0].legend(loc="upper right", fontsize=8)
    for p in range(len(m.pairs)):
        ax[1].plot(t, run.contact_force[:, p], label=m.pair_name(p))
    for k, onset in enumerate(run.impacts.onset):
        ax[1].axvline(onset, color="0.85", lw=0.6, zorder=0)
    ax[1].axhline(th.bruise_force, color="r", ls="--", lw=0.8, label=f"bruise {th.bruise_force:g} N")
    ax[1].set_ylabel("contact force (N)")
    ax[1].legend(loc="upper right", fontsize=8)
    for i, name in enumerate(m.names):
        ax[2].plot(t, run.pedicel_force[:, i], label=name)
    ax[2].axhline(th.detachment_force, color="r", ls="--", lw=0.8, label=f"detachment {th.detachment_force:g} N")
    ax[2].set_ylabel("pedicel tension (N)")
    ax[2].legend(loc="upper right", fontsize=8)
    e = run.energy
    for k in ("kinetic", "gravity", "hinge_elastic", "contact_elastic"):
        ax[3].plot(t, e[k] * 1e3, label=k.replace("_", " "))
    ax[3].plot(t, (e["dissipated_hinge"] + e["dissipated_coupling"] + e["dissipated_contact"]) * 1e3,
               label="dissipated", ls="--")
    ax[3].plot(t, e["base_work"] * 1e3, label="work by base", ls=":")
    ax[3].set_ylabel("energy (mJ)")
    ax[3].legend(loc="upper right", fontsize=8, ncol=2)
    ax[4].plot(t, run.accel[:, 0], label="ax")
    ax[4].plot(t, run.accel[:, 1], label="ay")
    ax[4].set_ylabel("rachis accel (m/s²)")
    ax[4].set_xlabel("time (s)")
    ax[4].legend(loc="upper right", fontsize=8)
    s = run.summary()
    fig.suptitle(title or f"{run.scene.name}: {s['collision_count']} impacts, peak contact {s['peak_contact_force']:.3g} N, "
                 f"peak pedicel {s['peak_pedicel_force']:.3g} N, ledger error {run.ledger_error():.1e}", fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
