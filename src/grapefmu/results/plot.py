"""Figures a person reads faster than a table: angles, forces against thresholds, energy ledger."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import GrapefmuError
from .run import Run
from .writers import atomic_path, check_target, one_of

#: the figure types plot_run writes (matplotlib's format is taken from the suffix)
PLOT_TYPES = (".png", ".pdf", ".svg")


def check_plot(path: str | Path, option: str = "plot") -> Path:
    """Refuse, before the run, a path plot_run could not write (unknown type, a directory, not writable)."""
    return check_target(path, PLOT_TYPES, option)


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save(fig, path: str | Path) -> None:
    """Write a figure to a .png, .pdf or .svg (the type from the suffix) atomically, and close it."""
    if Path(path).suffix.lower() not in PLOT_TYPES:
        raise GrapefmuError(f"{path}: unknown figure type {Path(path).suffix!r}; use {one_of(PLOT_TYPES)}")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=Path(path).suffix.lstrip(".").lower())
    pyplot().close(fig)


#: above this many berries the figure shows envelopes and counts, not one line per berry and pair
LINES_LIMIT = 8


def _legend(ax, **kw) -> None:
    """The legend beside the panel, never over its curves or threshold lines."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8, **kw)


def plot_run(run: Run, path: str | Path, title: str | None = None) -> None:
    """The run's figure (`figure`) written to a .png, .pdf or .svg."""
    save(figure(run, title), path)


def figure(run: Run, title: str | None = None):
    """The run as a matplotlib figure: one line per berry and pair, or for a cluster (more than LINES_LIMIT
    berries) envelopes and counts. Quantities in the units of the files, except the angle axis (degrees, so
    labelled)."""
    fig = (_cluster_figure if run.scene.model.n_berries > LINES_LIMIT else _lines_figure)(run)
    s = run.summary()
    err = run.ledger_error()
    fig.suptitle(title or f"{run.scene.name}: {s['berries']} berries, {s['collision_count']} impacts, peak contact "
                 f"{s['peak_contact_force_n']:.3g} N, peak pedicel {s['peak_pedicel_tension_n']:.3g} N, "
                 + ("ledger not meaningful (no energy moved)" if np.isnan(err) else f"ledger error {err:.1e}"),
                 fontsize=10)
    return fig


def _lines_figure(run: Run):
    plt = pyplot()
    m = run.scene.model
    th = run.scene.thresholds
    rows = 6 if m.obstacles else 5
    fig, ax = plt.subplots(rows, 1, figsize=(9, 11 + 2 * (rows - 5)), sharex=True, constrained_layout=True)
    t = run.t
    for k, name in enumerate(m.dof_names):  # a spherical berry's swing and tilt each: one line per angle
        ax[0].plot(t, np.degrees(run.angles[:, k]), label=name)
    ax[0].set_ylabel("twig angle (deg; files: rad)")
    _legend(ax[0])
    touched = [p for p in range(len(m.pairs)) if np.any(run.contact_force[:, p] > 0.0)]
    for p in touched:  # a line and a legend entry for each of a cluster's idle pairs hid the ones that touched
        ax[1].plot(t, run.contact_force[:, p], label=m.pair_name(p))
    if len(touched) < len(m.pairs):
        ax[1].plot([], [], " ", label=f"{len(m.pairs) - len(touched)} pairs never pushing (not drawn)")
    for k, onset in enumerate(run.impacts.onset):
        ax[1].axvline(onset, color="0.85", lw=0.6, zorder=0)
    ax[1].axhline(th.bruise_force, color="r", ls="--", lw=0.8, label=f"bruise {th.bruise_force:g} N")
    ax[1].set_ylabel("contact force (N)")
    _legend(ax[1])
    for i, name in enumerate(m.names):
        ax[2].plot(t, run.pedicel_tension[:, i], label=name)
    ax[2].axhline(th.detachment_force, color="r", ls="--", lw=0.8, label=f"detachment {th.detachment_force:g} N")
    ax[2].set_ylabel("pedicel tension (N)\n< 0: twig compressed")
    _legend(ax[2])
    e = run.energy
    for k in ("kinetic", "gravity", "hinge_elastic", "contact_elastic"):
        ax[3].plot(t, e[k], label=k.replace("_", " "))
    ax[3].plot(t, run.dissipated, label="dissipated", ls="--")
    ax[3].plot(t, e["base_work"], label="work by base", ls=":")
    ax[3].set_ylabel("energy (J)")
    _legend(ax[3])
    _accel(ax[4], t, run.accel)
    ax[4].set_xlabel("time (s)")
    if m.obstacles:
        _impacts_by_surface(run, ax[5])
    return fig


def _impacts_by_surface(run: Run, ax) -> None:
    """Each impact's peak force at its onset, one colour per surface (between berries, each obstacle) with that
    surface's bruise force; bruising impacts filled."""
    imp = run.impacts
    for k, (name, row) in enumerate(run.impacts_by_surface().items()):
        hit, soft = row["impacts"] & imp.bruising, row["impacts"] & ~imp.bruising
        ax.scatter(imp.onset[hit], imp.peak_force[hit], color=f"C{k}", s=18,
                   label=f"{name}: {row['count']} impacts, {row['bruising']} bruising (filled)")
        ax.scatter(imp.onset[soft], imp.peak_force[soft], facecolors="none", edgecolors=f"C{k}", s=18)
        ax.axhline(row["bruise_force_n"], color=f"C{k}", ls="--", lw=0.8)
    ax.set_ylabel("impact peak force (N)\n--: its surface's bruise force")
    ax.set_xlabel("impact onset (s)")
    _legend(ax)


def _cluster_figure(run: Run):
    """A cluster: the berries at rest and at their largest swing (coloured by pedicel tension, one scale), force
    and tension envelopes against the thresholds, pairs in contact, energy per berry and the rachis input."""
    plt = pyplot()
    th = run.scene.thresholds
    t = run.t
    obstacles = bool(run.scene.model.obstacles)
    fig = plt.figure(figsize=(12, 13.5 if obstacles else 11), constrained_layout=True)
    grid = fig.add_gridspec(5 if obstacles else 4, 2)
    pos = run.positions
    moved = np.linalg.norm(pos - pos[:1] - (pos.mean(axis=1, keepdims=True) - pos[:1].mean(axis=1, keepdims=True)),
                           axis=2).max(axis=1)
    k_max = int(np.argmax(moved))
    shown = run.pedicel_tension[[0, k_max]]
    lo, hi = float(shown.min()), float(shown.max())  # one colour scale for both panels
    for col, (k, label) in enumerate(((0, "t = 0"), (k_max, f"largest swing, t = {t[k_max]:.3f} s"))):
        ax = fig.add_subplot(grid[0, col], projection="3d")
        r = run.scene.model.arrays.berry["radius"]
        dots = ax.scatter(pos[k, :, 0], pos[k, :, 1], pos[k, :, 2], s=(r / r.max()) ** 2 * 60,
                          c=run.pedicel_tension[k], cmap="viridis", vmin=lo, vmax=hi if hi > lo else lo + 1e-9,
                          depthshade=False)
        ax.set_title(f"berries, {label}", fontsize=9)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        fig.colorbar(dots, ax=ax, shrink=0.6, pad=0.1, label="pedicel tension (N)")
    ax = fig.add_subplot(grid[1, 0])
    ax.plot(t, run.contact_force.max(axis=1, initial=0.0), lw=0.8, label="largest contact force")
    ax.axhline(th.bruise_force, color="r", ls="--", lw=0.8, label=f"bruise {th.bruise_force:g} N")
    ax.set_ylabel("force (N)")
    _legend(ax)
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, run.pedicel_tension.max(axis=1), lw=0.8, label="largest pedicel tension")
    ax.plot(t, np.median(run.pedicel_tension, axis=1), lw=0.8, label="median")
    ax.axhline(th.detachment_force, color="r", ls="--", lw=0.8, label=f"detachment {th.detachment_force:g} N")
    ax.set_ylabel("tension (N)")
    _legend(ax)
    ax = fig.add_subplot(grid[2, 0])
    ax.step(t, run.active_pairs, where="post", lw=0.8)
    ax.set_ylabel("pairs in contact")
    ax.set_title(f"{run.stats.get('candidate_pairs', len(run.scene.model.pairs))} candidate pairs; "
                 f"{run.stats.get('near_pairs_mean', float('nan')):.0f} near pairs per step on average", fontsize=9)
    ax = fig.add_subplot(grid[2, 1])
    per_berry = run.dissipated_per_berry()
    ax.bar(np.arange(len(per_berry)), np.sort(per_berry)[::-1], width=1.0)
    ax.set_ylabel("dissipated per berry (J)")
    ax.set_xlabel("berries, most first")
    ax = fig.add_subplot(grid[3, 0])
    e = run.energy
    for k in ("kinetic", "gravity", "hinge_elastic", "contact_elastic"):
        ax.plot(t, e[k], label=k.replace("_", " "))
    ax.plot(t, run.dissipated, ls="--", label="dissipated")
    ax.plot(t, e["base_work"], ls=":", label="work by base")
    ax.set_ylabel("energy (J)")
    ax.set_xlabel("time (s)")
    _legend(ax)
    ax = fig.add_subplot(grid[3, 1])
    _accel(ax, t, run.accel)
    ax.set_xlabel("time (s)")
    if obstacles:
        _impacts_by_surface(run, fig.add_subplot(grid[4, :]))
    return fig


def _accel(ax, t, accel) -> None:
    """The rachis acceleration's components that are ever non-zero (a_x and a_z always), the angular ones on an axis
    of their own (rad/s², dashed), and one legend for both."""
    from ..physics.excitation import ACCEL_COMPONENTS
    turn = None
    for k, name in enumerate(ACCEL_COMPONENTS):
        if k in (0, 2) or np.any(accel[:, k]):
            if k >= 3 and turn is None:
                turn = ax.twinx()
                turn.set_ylabel("rachis angular accel (rad/s²)")
            (turn if k >= 3 else ax).plot(t, accel[:, k], label=name, color=f"C{k}", ls="--" if k >= 3 else "-")
    ax.set_ylabel("rachis accel (m/s²)")
    lines = ax.get_lines() + (turn.get_lines() if turn is not None else [])
    ax.legend(lines, [x.get_label() for x in lines], loc="upper left", bbox_to_anchor=(1.12 if turn else 1.01, 1.0),
              borderaxespad=0.0, fontsize=8)
