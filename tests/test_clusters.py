"""Whole clusters: generated scenes, the broad phase, independent groups and the planar row."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from grapefmu.cluster import ClusterSpec, RowSpec, cluster_scene, row_scene
from grapefmu.errors import SceneError, SolverError
from grapefmu.model import ContactPair, Model
from grapefmu.model import model as model_module
from grapefmu.model.model import SolverSettings
from grapefmu.scenefile import load_scene, scene_from_dict
from grapefmu.physics.kinematics import positions
from grapefmu.results.records import WORK
from grapefmu.solver.api import simulate
from grapefmu.solver.components import groups, sub_scene
from grapefmu.solver import session as ses
from grapefmu.solver.islands import Islands
from grapefmu.solver.solver import Solver

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def cluster(n, seed=1, t_end=0.6, rtol=1e-8, **kw):
    doc = cluster_scene(ClusterSpec(berries=n, seed=seed, **kw))
    doc["solver"] = {"rtol": rtol, "atol": rtol * 1e-3, "t_end": t_end, "output_interval": 1e-3}
    return scene_from_dict(doc, Path.cwd())


def test_generated_cluster_is_at_rest_without_overlap_and_reproducible():
    doc = cluster_scene(ClusterSpec(berries=40, seed=5))
    assert doc == cluster_scene(ClusterSpec(berries=40, seed=5))
    assert doc != cluster_scene(ClusterSpec(berries=40, seed=6))
    sc = scene_from_dict({**doc, "excitation": {"kind": "none"}, "solver": {"t_end": 0.2, "rtol": 1e-9}}, Path.cwd())
    pos = np.zeros((40, 3))
    positions(sc.initial_state, sc.model.arrays, pos)
    r = sc.model.arrays.berry["radius"]
    gaps = [np.linalg.norm(pos[i] - pos[j]) - r[i] - r[j] for i in range(40) for j in range(i)]
    assert min(gaps) >= -1e-12
    run = simulate(sc)
    # the placed pose is the static equilibrium: nothing moves without excitation
    assert np.abs(run.angles - run.angles[0]).max() < 1e-9
    assert run.collision_count == 0


def test_bad_cluster_request_names_the_field():
    with pytest.raises(SceneError, match="cluster.precompression"):
        cluster_scene(ClusterSpec(berries=10, precompression=0.01))
    with pytest.raises(SceneError, match=r"cluster.berries.*\[1, 1000\]"):
        cluster_scene(ClusterSpec(berries=0))
    for key, bad in (("berries", 2.5), ("berries", True), ("seed", 1.5), ("seed", False)):  # a TypeError, or taken
        with pytest.raises(SceneError, match=f"cluster.{key}: expected an integer"):
            cluster_scene(ClusterSpec(**{"berries": 5, key: bad}))
    with pytest.raises(SceneError, match="row.berries: expected an integer"):
        row_scene(RowSpec(berries=2.5))
    # pressed into each other at rest, or hinges beyond ±10 m: the loader named berries[59].angle or berries[0].hinge_x
    for n, pitch, key, words in ((60, 0.02, "pitch", "[0.0243, 0.339] m"), (100, 1.0, "pitch", "[0.0243, 0.202] m"),
                                 (1000, 0.027, "berries", "at most 824 berries")):
        with pytest.raises(SceneError, match=f"row.{key}") as ei:
            row_scene(RowSpec(berries=n, pitch=pitch))
        assert words in ei.value.why


def test_the_largest_precompression_gives_a_scene_that_loads():
    """The generator allowed any pair the full precompression (0.2 of the mean radius) while a scene's start may hold
    0.2 of the pair's smaller radius: half of the seeds 1-20 of a 60-berry cluster at the largest precompression were
    refused by the loader (an audit: 'berries[16].angle: ... overlap by 2.63 mm ...; at most 2.61 mm')."""
    pc = 0.1 * ClusterSpec.diameter.mean
    for seed in (7, 11, 12):
        sc = scene_from_dict(cluster_scene(ClusterSpec(berries=60, seed=seed, precompression=pc)), Path.cwd())
        pos = np.zeros((60, 3))
        positions(sc.initial_state, sc.model.arrays, pos)
        r = sc.model.arrays.berry["radius"]
        depth = max(r[i] + r[j] - np.linalg.norm(pos[i] - pos[j]) - min(pc, 0.2 * min(r[i], r[j]))
                    for i in range(60) for j in range(i))
        assert depth <= 1e-12


def test_drawn_sizes_are_the_ones_asked_for_or_refused_by_their_option():
    """A diameter was floored at 4 mm and a hinge at 1e-5 N·m/rad without a word (an audit: `grapefmu cluster
    --diameter 0.001 0` wrote 4 mm berries, 64 times the mass asked for), and a diameter beyond the model's range was
    refused as 'berries[0].mass'. The range drawn from, mean ± 3 sd, is now checked against the berry's field."""
    from grapefmu.cluster.generate import Spread
    doc = cluster_scene(ClusterSpec(berries=20, diameter=Spread(0.001, 0.0)))
    assert {b["radius"] for b in doc["berries"]} == {0.0005}
    for key, spread, words in (("diameter", Spread(0.027, 0.01), "(0, 0.2] m"),  # 3 sd reach below zero
                               ("diameter", Spread(0.3, 0.0), "(0, 0.2] m"),  # a radius above 0.1 m
                               ("hinge_stiffness", Spread(1e-6, 1e-6), "(0, 1000] N·m/rad"),
                               ("twig_length", Spread(0.9, 0.1), "≤ 1 m"),
                               ("hinge_damping", Spread(1e3, 1.0), "≤ 1000")):
        big = {"twig_length": Spread(0.5, 0.0), "hinge_stiffness": Spread(100.0, 0.0)} if key == "diameter" else {}
        with pytest.raises(SceneError, match=f"cluster.{key}") as ei:
            cluster_scene(ClusterSpec(berries=5, **{**big, key: spread}))
        assert words in ei.value.why


def test_editing_a_generated_document_leaves_the_next_one_alone():
    """A document's moves were the module's DEFAULT_MOVES themselves (dict() copies one level): slowing one generated
    plan down slowed every later default cluster in the process, and the default spec with it (an audit)."""
    fresh = cluster_scene(ClusterSpec(berries=3))
    for doc in (cluster_scene(ClusterSpec(berries=3)), row_scene(RowSpec(excitation=ClusterSpec().excitation))):
        doc["excitation"]["moves"][0]["duration"] = 9.0
        doc["solver"]["t_end"] = 9.0
        doc["contact"]["stiffness"] = 9.0
    assert cluster_scene(ClusterSpec(berries=3)) == fresh
    assert fresh["excitation"]["moves"][0]["duration"] == 0.4 and fresh["solver"]["t_end"] == 2.5


def test_energy_ledger_closes_for_a_cluster_under_pick_and_place():
    run = simulate(cluster(30, t_end=1.0))
    assert run.collision_count > 10
    assert run.ledger_error() < 1e-6
    # every impact's dissipation sums to the ledger's contact term (quadrature against ODE integral)
    assert run.impacts.dissipated.sum() == pytest.approx(run.energy["dissipated_contact"][-1], rel=1e-6)


def test_cluster_matches_the_scipy_reference():
    """Every pair the broad phase rules out of a step's event search (solver/broadphase.quiet) really stayed
    apart: a 30-berry cluster carried by the pick-and-place move has the reference's impacts (scipy's DOP853
    watching every near pair's events), each at the same time."""
    sc = cluster(30, t_end=1.0, rtol=1e-10)
    ref = simulate(sc, method="reference")
    for ours in (simulate(sc), Islands(sc).run()):  # one step size, and multirate islands
        assert ours.collision_count == ref.collision_count > 50
        np.testing.assert_array_equal(ours.impacts.pair, ref.impacts.pair)
        np.testing.assert_allclose(ours.impacts.onset, ref.impacts.onset, atol=1e-9)
        done = ~ours.impacts.ongoing
        np.testing.assert_allclose(ours.impacts.end[done], ref.impacts.end[~ref.impacts.ongoing], atol=1e-9)
        assert np.abs(ours.angles - ref.angles).max() < 1e-8
    assert ours.stats["islands_formed"] > 10


def test_islands_that_could_have_met_run_again_as_one():
    """With windows too long for the first grouping, islands whose berries' travel bounds overlap are rolled back
    and rerun together (solver/islands.py): the run still has every impact of one Solver of the whole scene at the
    same time, the same samples to the tolerance, the same counts sample by sample and peaks, and a closed energy
    ledger. Each window's samples go into the run's arrays at the next window's start, after the rollbacks, so an
    island's recorder never holds more than a window (its memory does not grow with the run)."""
    sc = cluster(30, t_end=1.0, rtol=1e-9)
    whole = simulate(sc)
    isl = Islands(sc, window=0.1)
    run = isl.run()
    assert isl.rollbacks > 0 and isl.formed > 10
    np.testing.assert_array_equal(run.impacts.pair, whole.impacts.pair)
    np.testing.assert_allclose(run.impacts.onset, whole.impacts.onset, atol=1e-8)
    np.testing.assert_allclose(run.impacts.peak_force, whole.impacts.peak_force, rtol=1e-5)
    np.testing.assert_array_equal(run.totals["collision_count"], whole.totals["collision_count"])
    # a sample holds the peaks of the steps before it, so the last; both peaks are located between the samples
    # (Brent), so they do not move with the steps (the tension's, sampled alone, differed by 1e-4 here)
    assert run.totals["peak_contact_force"][-1] == pytest.approx(whole.totals["peak_contact_force"][-1], rel=1e-6)
    assert run.totals["peak_pedicel_tension"][-1] == pytest.approx(whole.totals["peak_pedicel_tension"][-1], rel=1e-7)
    np.testing.assert_allclose(run.peak_tension, whole.peak_tension, rtol=1e-7)
    assert np.abs(run.y - whole.y).max() < 1e-6
    np.testing.assert_array_equal(run.accel, whole.accel)
    np.testing.assert_array_equal(run.contact_log.mode(len(run.t)), whole.contact_log.mode(len(whole.t)))
    assert run.ledger_error() < 1e-7
    assert run.stats["steps"] > 0 and run.stats["impacts"] == whole.stats["impacts"]
    assert {ses.outputs(s.session)[0].t.shape[0] for pool in isl.free.values() for s in pool} == {isl.per + 1}


def test_pruning_never_drops_a_pair_that_touches():
    """Random clusters with precompression, against all N(N−1)/2 pairs watched on every step."""
    for seed in (1, 2, 3):
        sc = cluster(25, seed=seed, t_end=0.8, rtol=1e-7, precompression=1e-3)
        pruned = Solver(sc).run()
        berries = sc.model.berries
        laws = {(p.i, p.j): p.law for p in sc.model.pairs}  # damping from e depends on each pair's masses
        every = tuple(ContactPair(i, j, laws.get((i, j), sc.model.pairs[0].law))
                      for i in range(len(berries)) for j in range(i + 1, len(berries)))
        assert len(every) > len(sc.model.pairs)
        full = replace(sc, model=replace(sc.model, pairs=every))
        solver = Solver(full, skin=math.inf)
        ref = solver.run()
        assert ref.stats["near_pairs_mean"] == len(every)
        assert pruned.stats["near_pairs_mean"] < len(sc.model.pairs)
        touched = {(every[p].i, every[p].j) for p in set(ref.impacts.pair.tolist())}
        kept = {(p.i, p.j) for p in sc.model.pairs}
        assert touched and touched <= kept
        np.testing.assert_array_equal(pruned.angles, ref.angles)
        assert pruned.collision_count == ref.collision_count


def test_berries_that_cannot_touch_give_exactly_the_single_pendulum():
    base = cluster(12, seed=4, t_end=0.8)
    far = [replace(b, hinge_x=0.2 * i) for i, b in enumerate(base.model.berries)]
    sc = replace(base, model=Model(tuple(far), (), (), base.model.gravity))
    assert groups(sc.model) == [[i] for i in range(12)]
    run = simulate(sc)
    assert run.stats["groups"] == 12 and run.stats["candidate_pairs"] == 0
    for i in range(12):
        alone = simulate(sub_scene(sc, [i]))
        np.testing.assert_array_equal(run.angles[:, 2 * i: 2 * i + 2], alone.angles)
        np.testing.assert_array_equal(run.pedicel_tension[:, i], alone.pedicel_tension[:, 0])
    assert run.ledger_error() < 1e-7


def test_groups_run_apart_report_the_work_of_both():
    """Every work counter the loop keeps (results.records.COUNTERS) reaches Run.stats and the summary under its name,
    and a scene run as independent groups reports the sum of its groups' work (components.merge), near pairs per step
    weighted by steps: a counter added to COUNTERS needs no edit elsewhere."""
    dual = load_scene(SCENES / "paper" / "test3.toml")
    m = dual.model
    far = tuple(replace(b, name=f"{b.name}_far", hinge_x=b.hinge_x + 0.5) for b in m.berries)
    pairs = (*m.pairs, *(ContactPair(p.i + 2, p.j + 2, p.law) for p in m.pairs))
    sc = replace(dual, model=Model(m.berries + far, pairs, (), m.gravity), angles=dual.angles * 2,
                 angular_velocities=dual.angular_velocities * 2)
    assert groups(sc.model) == [[0, 1], [2, 3]]
    run = simulate(sc, t_end=1.0)
    parts = [simulate(sub_scene(sc, members), t_end=1.0) for members in groups(sc.model)]
    assert run.stats["groups"] == 2 and all(p.stats["switches"] > 0 for p in parts)
    for name in (*WORK, "impacts", "degrees_of_freedom", "candidate_pairs"):
        assert run.stats[name] == sum(p.stats[name] for p in parts), name
    assert run.stats["near_pairs_mean"] == pytest.approx(
        sum(p.stats["near_pairs_mean"] * p.stats["steps"] for p in parts) / run.stats["steps"], rel=1e-12)
    summary = run.summary()
    assert {name: summary[name] for name in WORK} == {name: run.stats[name] for name in WORK}


def test_planar_row_of_two_is_the_dual_system():
    dual = load_scene(SCENES / "paper" / "test3.toml")
    b = dual.model.berries[0]
    doc = row_scene(RowSpec(berries=2, mass=b.mass, radius=b.radius, twig_length=b.twig_length, pitch=0.03,
                            hinge_stiffness=b.hinge_stiffness, hinge_damping=b.hinge_damping, angles=dual.angles,
                            contact={"law": "kelvin-voigt", "stiffness": 2000.0,
                                     "damping": dual.model.pairs[0].law.damping},
                            solver={"rtol": 1e-9, "atol": 1e-11, "t_end": 3.0}))
    row = scene_from_dict(doc, Path.cwd())
    a, d = simulate(row), simulate(dual)
    np.testing.assert_array_equal(a.y, d.y)
    np.testing.assert_array_equal(a.impacts.peak_force, d.impacts.peak_force)


def test_spherical_cluster_held_in_the_plane_is_the_planar_model():
    """Spherical berries with zero tilt and hinges on the rod stay in the x–z plane and follow the
    planar equations; a check of the spherical terms against the planar derivation."""
    dual = load_scene(SCENES / "paper" / "test3.toml")
    m = dual.model
    sph = tuple(replace(b, spherical=True) for b in m.berries)
    q = [x for a in dual.angles for x in (a, 0.0)]
    sc = replace(dual, model=replace(m, berries=sph), angles=tuple(q), angular_velocities=(0.0,) * 4)
    a, d = simulate(sc), simulate(dual)
    assert np.abs(a.angles[:, 1::2]).max() == 0.0
    assert np.abs(a.angles[:, 0::2] - d.angles).max() < 1e-7
    assert a.collision_count == d.collision_count


def test_newtons_cradle_conserves_momentum_and_energy_in_the_elastic_limit():
    """Five berries touching at rest, the first released: with a stiff elastic contact and no hinge
    losses the swing passes down the chain; energy is conserved to the tolerance and the horizontal
    momentum just before and after the collision train matches."""
    doc = row_scene(RowSpec(berries=5, hinge_stiffness=0.0, hinge_damping=0.0, pitch=0.027,
                            angles=(-0.3, 0, 0, 0, 0), contact={"law": "hertz", "stiffness": 5e6},
                            solver={"rtol": 1e-10, "atol": 1e-12, "t_end": 0.6, "output_interval": 1e-4}))
    sc = scene_from_dict(doc, Path.cwd())
    run = simulate(sc)
    e = run.energy
    total = e["kinetic"] + e["gravity"] + e["contact_elastic"]
    assert np.abs(total - total[0]).max() < 1e-7 * total[0]
    b = sc.model.arrays.berry
    px = (b["mass"] * b["twig_length"] * np.cos(run.angles) * run.angular_velocities).sum(axis=1)
    first = run.impacts.onset.min()
    train = run.impacts.onset < first + 0.02  # the first collision train, before anything swings back
    last = run.impacts.end[train].max()
    assert train.sum() >= 4 and last < first + 0.02
    k0 = np.searchsorted(run.t, first) - 1
    k1 = np.searchsorted(run.t, last) + 1
    assert px[k0] > 1e-3
    assert px[k1] == pytest.approx(px[k0], rel=2e-3)
    # the last berry leaves with (nearly) all of it
    assert run.angular_velocities[k1, -1] > 0.9 * run.angular_velocities[k0, 0]


def test_cluster_plot_is_drawn(tmp_path):
    """More than LINES_LIMIT berries: the cluster figure (envelopes, 3-D snapshots)."""
    from grapefmu.results.plot import plot_run
    sc = scene_from_dict({**cluster_scene(ClusterSpec(berries=12, seed=4)), "solver": {"t_end": 0.05}}, Path.cwd())
    plot_run(simulate(sc), tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 20_000


def test_islands_keep_the_crate_contacts():
    """A cluster set down into a padded crate (three obstacles, which every island keeps): multirate islands have
    one Solver's impacts, on the crate too, at the same times, a closed energy ledger and the same rachis
    accelerations."""
    sc = load_scene(Path(__file__).parents[1] / "src/grapefmu/scenes/setdown_fast.toml")
    sc = replace(sc, solver=replace(sc.solver, rtol=1e-9, atol=1e-12))
    whole = simulate(sc)
    isl = Islands(sc)
    run = isl.run()
    assert isl.formed > 20
    crate = [k for k, p in enumerate(sc.model.pairs) if p.j >= sc.model.n_berries]
    assert np.isin(whole.impacts.pair, crate).sum() > 0
    np.testing.assert_array_equal(run.impacts.pair, whole.impacts.pair)
    np.testing.assert_allclose(run.impacts.onset, whole.impacts.onset, atol=1e-8)
    assert np.abs(run.angles - whole.angles).max() < 1e-6
    assert run.ledger_error() < 1e-7
    np.testing.assert_array_equal(run.accel, whole.accel)


@pytest.mark.parametrize("window", [1e10, math.inf])
def test_islands_window_beyond_the_run_is_the_run(window):
    """A window longer than the run is one window of the whole run (it sized a recorder for the window's samples:
    MemoryError at 1e10 s, OverflowError at inf), and runs the same steps as a window of exactly the run."""
    sc = cluster(8, t_end=0.1, rtol=1e-7)
    run, whole = Islands(sc, window=window).run(), Islands(sc, window=0.1).run()
    np.testing.assert_array_equal(run.y, whole.y)
    assert run.stats["steps"] == whole.stats["steps"] and np.isfinite(run.y).all()


def test_islands_merged_twice_in_one_window_keep_what_they_recorded(monkeypatch):
    """A row struck at one end: with every berry its own island from the start and islands never regrouped (only the
    rollbacks merge them), the struck berry's island merges with its neighbour's, and that island with the next in
    a second round of the same window: each island rolls back to the cursor it saved at the window's start, so the
    samples it recorded in the windows before stay (they were lost once), and the run is one Solver's."""
    calls = []

    def singletons_then_kept(self, slack, label):
        calls.append(1)
        return np.arange(self.n) if len(calls) == 1 else label.copy()

    monkeypatch.setattr(Islands, "_components", singletons_then_kept)
    sc = row_scene(RowSpec(berries=4, pitch=0.028, angles=(-0.5, -0.014, 0.017, 0.048),
                           solver={"rtol": 1e-9, "atol": 1e-12, "t_end": 0.4, "output_interval": 1e-3}))
    sc = scene_from_dict(sc, Path.cwd())
    whole = simulate(sc)
    isl = Islands(sc, window=0.05)
    run = isl.run()
    assert isl.rollbacks >= 2
    np.testing.assert_array_equal(run.impacts.pair, whole.impacts.pair)
    assert np.abs(run.y - whole.y).max() < 1e-6


def test_islands_stop_at_the_step_limit_as_one_step_size_does():
    """`solver.max_steps` bounds a run's accepted steps; in islands, the steps of each berry's islands since the start.
    Every island ends a step at each window's end, so over 1 s (50 windows) each berry's islands take at least 50: a
    run one step size cannot finish within 40 steps stops in islands too, with the same SolverError naming the limit.
    Each island's window was once allowed 40 steps of its own, and the run finished."""
    doc = cluster_scene(ClusterSpec(berries=20, seed=7))
    for islands in (False, True):
        sc = scene_from_dict({**doc, "solver": {"t_end": 1.0, "rtol": 1e-8, "max_steps": 40, "islands": islands}},
                             Path.cwd())
        with pytest.raises(SolverError, match=r"the step limit was reached \(40 steps; "):
            simulate(sc)


def test_islands_refuse_a_bad_end_or_output_interval_as_one_solver_does():
    """Islands(scene).run takes Solver.run's t_end and output_interval and refuses what it refuses, with its words (a
    NaN end was a ValueError from numpy, an interval of 0 a ZeroDivisionError)."""
    sc = scene_from_dict({**row_scene(RowSpec(berries=3)), "solver": {"t_end": 0.2, "islands": True}}, Path.cwd())
    for t_end, dt in ((math.nan, None), (-1.0, None), ("x", None), (1e9, None), (None, 0.0), (None, math.nan),
                      (None, -0.01)):
        with pytest.raises(SolverError) as one:
            Solver(sc).run(t_end, dt)
        with pytest.raises(SolverError) as isl:
            Islands(sc).run(t_end, dt)
        assert str(isl.value) == str(one.value)


def test_a_scene_asks_for_islands():
    """`solver.islands = true` runs `simulate` in multirate islands (the Run of Islands(scene).run(), one Solver's
    impacts); a method or fixed step islands cannot take is refused at load, naming the key; a caller's paper
    method runs without them."""
    doc = cluster_scene(ClusterSpec(berries=12, seed=1, solver={"t_end": 0.6, "rtol": 1e-8, "atol": 1e-11,
                                                                "islands": True}))
    sc = scene_from_dict(doc, Path.cwd())
    run = simulate(sc)
    assert run.stats["islands_formed"] > 5 and run.summary()["islands_formed"] == run.stats["islands_formed"]
    np.testing.assert_array_equal(run.y, Islands(sc).run().y)
    whole = simulate(replace(sc, solver=replace(sc.solver, islands=False)))
    assert "islands_formed" not in whole.stats and len(whole.impacts) > 5
    np.testing.assert_array_equal(run.impacts.pair, whole.impacts.pair)
    np.testing.assert_allclose(run.impacts.onset, whole.impacts.onset, atol=1e-7)
    for bad, why in (({"method": "paper"}, "'event' method"), ({"fixed_step": 1e-4}, "adaptive steps"),
                     ({"islands": 1}, 'true, false or "auto"'), ({"islands": "always"}, 'true, false or "auto"')):
        with pytest.raises(SceneError, match=r"solver\.islands: .*" + why):
            scene_from_dict({**doc, "solver": {**doc["solver"], **bad}}, Path.cwd())
    assert "islands_formed" not in simulate(sc, t_end=0.05, method="paper").stats


def test_auto_islands_from_a_number_of_berries(monkeypatch):
    """`solver.islands = "auto"` (the default) runs `simulate` in islands from ISLANDS_FROM berries on (the Run of
    Islands(scene).run()), in one Solver below, and in one Solver for a method or fixed step islands cannot take
    (which `true` refuses at load: test_a_scene_asks_for_islands)."""
    solver = {"t_end": 0.3, "rtol": 1e-8, "atol": 1e-11}
    sc = scene_from_dict(cluster_scene(ClusterSpec(berries=12, seed=1, solver=solver)), Path.cwd())
    assert sc.solver.islands == "auto" == SolverSettings().islands
    monkeypatch.setattr(model_module, "ISLANDS_FROM", 12)
    run = simulate(sc)
    assert run.stats["islands_formed"] > 5
    np.testing.assert_array_equal(run.y, Islands(sc).run().y)
    for method, step in (("paper", 0.0), ("event", 1e-4)):
        assert "islands_formed" not in simulate(sc, method=method, fixed_step=step, cross_check=False).stats
    monkeypatch.setattr(model_module, "ISLANDS_FROM", 13)
    one = simulate(sc)
    assert "islands_formed" not in one.stats
    np.testing.assert_array_equal(one.y, Solver(sc).run().y)


def test_auto_islands_take_the_callers_method_and_fixed_step(monkeypatch):
    """A scene set to the paper method or a fixed step, run by `simulate` with the event method or adaptive steps the
    caller asks for: a group that "auto" runs in islands takes the caller's settings, as one step size does, and has
    its impacts (it was refused, the islands reading the scene's method and fixed step)."""
    monkeypatch.setattr(model_module, "ISLANDS_FROM", 12)
    doc = cluster_scene(ClusterSpec(berries=12, seed=1))
    for own, given in (({"method": "paper"}, {"method": "event"}), ({"fixed_step": 1e-3}, {"fixed_step": 0.0})):
        sc = scene_from_dict({**doc, "solver": {"t_end": 0.3, "rtol": 1e-9, "atol": 1e-12, **own}}, Path.cwd())
        run = simulate(sc, **given)
        one = simulate(replace(sc, solver=replace(sc.solver, islands=False)), **given)
        assert run.stats["islands_formed"] > 5 and "islands_formed" not in one.stats
        assert run.stats["method"] == one.stats["method"] == "event" and run.stats["fixed_step"] == 0.0
        assert len(run.impacts) == len(one.impacts) > 5
        np.testing.assert_array_equal(run.impacts.pair, one.impacts.pair)
        np.testing.assert_allclose(run.impacts.onset, one.impacts.onset, atol=1e-8)
        assert np.abs(run.angles - one.angles).max() < 1e-7


def test_islands_record_a_stepped_rachis_as_one_solver_does():
    """A staircase acceleration (zero-order hold) with steps on the output grid: a sample on a step is recorded by
    the step that ends there, on the stair before it, whether the grid's time lands on the breakpoint or an ulp past
    it (0.7 = 700 × 1 ms + 1 ulp). Islands record the same accelerations as one Solver, stair by stair."""
    from grapefmu.model import excitation as exc
    rows = np.array([[0.0, 0.0, 0.0, 0.0], [0.1, 3.0, 0.0, 1.0], [0.3, -2.0, 1.0, 0.0], [0.7, 1.0, 0.0, -2.0],
                     [1.0, 1.0, 0.0, -2.0]])
    stairs = exc.zero_order_hold(np.column_stack([rows, np.zeros((len(rows), 3))]))
    sc = replace(cluster(10, t_end=1.0, rtol=1e-6), excitation=exc.table("csv", stairs))
    whole = simulate(sc)
    run = Islands(sc).run()
    on_steps = np.searchsorted(whole.t, [0.1, 0.3, 0.7])  # the samples on the breakpoints hold the stairs before
    np.testing.assert_array_equal(whole.accel[on_steps, :3], rows[:3, 1:])
    np.testing.assert_array_equal(whole.accel[on_steps + 1, :3], rows[1:4, 1:])
    np.testing.assert_array_equal(run.accel, whole.accel)
    np.testing.assert_array_equal(run.impacts.pair, whole.impacts.pair)


def test_a_windows_islands_get_exactly_their_own_parts():
    """handover.parts, which finds every island of a window in one call, against sets: island k has the berries
    labelled which[k] (ascending), their angles, the pairs with both bodies in it or one in it and the other an
    obstacle (obstacles belong to every island), and the couplings with both ends in it; a pair or coupling across
    islands, or of berries no island takes, is in none."""
    from grapefmu.solver.handover import parts

    sc = load_scene(Path(__file__).parents[1] / "src/grapefmu/scenes/setdown_fast.toml")
    m, n = sc.model, sc.model.n_berries
    pi, pj = np.array([p.i for p in m.pairs]), np.array([p.j for p in m.pairs])
    coupled = np.array([(i, i + 1) for i in range(0, n - 1, 2)], dtype=np.int64)  # couplings of our own
    rng = np.random.default_rng(3)
    label = rng.integers(0, 6, n)
    which = np.array([4, 0, 5, 2])  # not every label, in no order
    members, m_off, dofs, d_off, pairs, p_off, couplings, c_off = parts(label, which, pi, pj, coupled, m.dof)
    assert (pj >= n).any() and n > 10
    for k, c in enumerate(which):
        own = set(np.flatnonzero(label == c))
        assert list(members[m_off[k]:m_off[k + 1]]) == sorted(own)
        assert list(dofs[d_off[k]:d_off[k + 1]]) == [a for i in sorted(own) for a in range(m.dof[i], m.dof[i + 1])]
        want = [p for p in range(len(pi)) if pi[p] in own and (pj[p] >= n or pj[p] in own)]
        assert list(pairs[p_off[k]:p_off[k + 1]]) == want
        both = [q for q, (i, j) in enumerate(coupled) if i in own and j in own]
        assert list(couplings[c_off[k]:c_off[k + 1]]) == both
    assert m_off[-1] == np.isin(label, which).sum() and p_off[-1] < len(pi)


def test_islands_hold_a_run_to_its_step_limit_as_one_solver_does():
    """A run's step limit is the run's in islands too: a hinge too stiff for it is refused before a step, naming the
    berry, where islands, whose limit holds per island and window, ran it (here 0.2 s of a hinge that needs at least
    1.5e4 steps, under a limit of 10⁴: 1.5e3 a window); and a run that stops at the limit in contact names the pair
    touching, as one Solver's does (stiffness.contact_hint; the island's pairs by their names in the scene)."""
    solver = {"rtol": 1e-8, "atol": 1e-10, "t_end": 0.2, "output_interval": 1e-3}
    doc = row_scene(RowSpec(berries=6, solver=solver))
    doc["berries"][2]["hinge_damping"] = 10.0
    sc = scene_from_dict(doc, Path.cwd())
    with pytest.raises(SolverError, match=r"berries\[2\].*nothing was run") as one:
        Solver(sc, max_steps=10_000).run()
    with pytest.raises(SolverError) as isl:
        Islands(sc, max_steps=10_000).run()
    assert str(isl.value) == str(one.value)
    pressed = scene_from_dict(row_scene(RowSpec(berries=6, pitch=0.026, angles=(0.0,) * 6, solver=solver, contact={
        "law": "kelvin-voigt", "stiffness": 2000.0, "damping": 1e4})), Path.cwd())
    with pytest.raises(SolverError, match=r"step limit was reached.*in contact when it stopped: b\d+_b\d+ "
                       r"\(kelvin-voigt: stiffness 2e\+03 N/m, damping 1e\+04 N·s/m; m = 0.0055 kg, m/c = 5.5e-07 s"):
        Islands(pressed, max_steps=3000).run()


def test_an_islands_run_keeps_few_systems_out_of_use_and_its_results_do_not_depend_on_them(monkeypatch):
    """Under sustained shaking nearly every island has a shape of its own, and the pool of systems out of use kept
    every one: a 100-berry cluster shaken at 4 Hz held 4.1 GB after 30 s, against 0.6 GB in one step size (an audit).
    The pool now keeps FREE_SYSTEMS, the least recently used shape dropped first, and a retired island keeps no
    system. A pool of two and one of any size give the same run bit for bit (a reused system is loaded afresh). The
    count of systems out of use is the pool's own (it was a counter kept beside it, which a caller's emptying the pool
    left at its old value: the next run then dropped systems it had room for)."""
    from grapefmu.solver import islands
    doc = cluster_scene(ClusterSpec(berries=20, seed=1))
    doc["excitation"] = {"kind": "sine", "amplitude": [6.0, 3.6, 2.4], "frequency": 4.1, "start": 0.0, "duration": 10.0}
    doc["solver"] = {"rtol": 1e-6, "t_end": 0.5, "output_interval": 1e-3}
    sc = scene_from_dict(doc, Path.cwd())
    runs = {}
    for cap in (2, 10**6):
        monkeypatch.setattr(islands, "FREE_SYSTEMS", cap)
        isl = Islands(sc)
        runs[cap] = isl.run()
        kept = sum(len(pool) for pool in isl.free.values())
        assert kept == isl.n_free <= cap and all(seg.system is None for seg in isl.segments)
        assert isl.formed > 20
    isl.free.clear()  # a caller releasing the pool's memory
    assert isl.n_free == 0
    again = isl.run()
    assert 0 < isl.n_free == sum(len(pool) for pool in isl.free.values())
    np.testing.assert_array_equal(again.y, runs[10**6].y)
    np.testing.assert_array_equal(runs[2].y, runs[10**6].y)
    np.testing.assert_array_equal(runs[2].impacts.records(), runs[10**6].impacts.records())
