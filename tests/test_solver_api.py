"""The stepping interface the FMU and the ROS node rely on."""
from __future__ import annotations

import re

import numpy as np
import pytest

from grapefmu import Solver, SolverError, simulate
from grapefmu.errors import StateError
from grapefmu.solver.state import flatten, zeros

from .conftest import dual, scene


def test_steps_and_intervals_reproduce_a_whole_run(collision_scene):
    whole = Solver(collision_scene)
    whole.advance(1.0)
    stepped = Solver(collision_scene)
    while stepped.t < 0.5:
        stepped.step()
    stepped.advance(1.0 - stepped.t)
    assert stepped.t == 1.0
    np.testing.assert_allclose(stepped.y, whole.y, rtol=0, atol=1e-7)


def test_dense_output_matches_the_step_ends(collision_scene):
    s = Solver(collision_scene)
    for _ in range(30):
        y_start = s.y
        t_start = s.t
        s.step()
        f = s.dense_output()
        np.testing.assert_allclose(f(t_start), y_start, atol=1e-15)
        np.testing.assert_allclose(f(s.t), s.y, atol=1e-12)


def test_held_acceleration_is_independent_of_the_interval_and_matches_the_reference(tmp_path):
    """1 ms and 10 ms zero-order-hold intervals against scipy on a constant-acceleration CSV scene."""
    (tmp_path / "accel.csv").write_text("time,ax,ay\n0,4.0,-2.0\n1,4.0,-2.0\n")
    doc = dual(angles=(0.0, 0.3))
    results = []
    for dt in (1e-3, 1e-2):
        s = Solver(scene(doc), driven=True)
        for _ in range(round(0.2 / dt)):
            s.advance(dt, base_accel=(4.0, -2.0))
        results.append(s.angles)
    doc["excitation"] = {"kind": "csv", "file": str(tmp_path / "accel.csv")}
    ref = simulate(scene(doc), 0.2, method="reference", rtol=1e-12, atol=1e-14)
    assert ref.collision_count > 0
    for angles in results:
        np.testing.assert_allclose(angles, ref.angles[-1], atol=1e-7)


def test_state_roundtrip_replays_bit_for_bit(collision_scene):
    s = Solver(collision_scene, driven=True)
    s.advance(0.05)
    saved = s.get_state()
    s.advance(0.3, base_accel=(1.0, 0.5))
    first = s.y
    s.set_state(saved)
    s.advance(0.3, base_accel=(1.0, 0.5))
    assert np.array_equal(s.y, first)


@pytest.mark.parametrize("dt, accel, words", [
    (0.0, None, "dt"), (-1e-3, None, "dt"), (float("nan"), None, "dt"),
    # longer than any run: a wall-clock stamp's step was refused as a hinge too stiff for 2.5e8 steps, naming the hinge
    (1.7e9, None, r"dt: expected a step in \(0, 100000\] s \(the longest run, solver.t_end\), got 1700000000.0"),
    (1e-3, (float("nan"), 0.0), "base_accel"), (1e-3, (0.0, float("inf")), "base_accel"),
])
def test_bad_advance_is_refused_and_leaves_the_state(collision_scene, dt, accel, words):
    s = Solver(collision_scene, driven=True)
    s.advance(0.01)
    before = s.get_state()
    with pytest.raises(SolverError, match=words):
        s.advance(dt, base_accel=accel)
    assert same_state(before, s.state)


def test_a_step_the_solver_cannot_finish_leaves_the_state(collision_scene):
    s = Solver(collision_scene, max_steps=3)
    before = s.get_state()
    with pytest.raises(SolverError, match="step limit"):
        s.advance(0.5)
    assert same_state(before, s.state)


def test_a_step_holds_its_step_limit_across_a_full_impact_list():
    """advance's max_steps counts the step's accepted steps across the loop's returns: the shaken stiff pair's 10 s in
    one step take 1612 steps and 230 impacts, so the session's impact list (64) fills three times on the way. With a
    limit of 1611 the step is refused; before, each return restarted the count and it ran to the end."""
    from grapefmu.bench.scenes import bench_scenes, build
    sc = build(bench_scenes()["shaken stiff pair"])
    whole = Solver(sc, rtol=1e-6, atol=1e-8)
    whole.advance(sc.solver.t_end)
    steps, impacts = whole.stats["steps"], whole.stats["impacts"]
    assert impacts > 3 * 64
    short = Solver(sc, rtol=1e-6, atol=1e-8, max_steps=steps - 1)
    with pytest.raises(SolverError, match=rf"step limit was reached \({steps - 1} steps"):
        short.advance(sc.solver.t_end)
    assert short.t == 0.0 and short.stats["steps"] == 0
    exact = Solver(sc, rtol=1e-6, atol=1e-8, max_steps=steps)
    exact.advance(sc.solver.t_end)
    assert exact.t == whole.t and exact.stats["impacts"] == impacts


@pytest.mark.parametrize("ny, npair, n, stages, k, zeno_max", [(13, 1, 2, 7, 5, 8), (61, 0, 7, 13, 7, 3),
                                                               (20, 45, 10, 7, 5, 8)])
def test_every_array_of_a_state_lies_apart_in_its_one_buffer(ny, npair, n, stages, k, zeno_max):
    """A step's backup and rollback copy the one buffer a state's arrays view (state.zeros): each array must lie
    inside it, on a 16-byte boundary, apart from every other, and be all zeros."""
    memory, state = zeros(ny, npair, n, stages, k, zeno_max)
    base, spans = memory.ctypes.data, []
    for name, a in flatten(state).items():
        at = a.ctypes.data - base
        assert at % 16 == 0 and 0 <= at and at + a.nbytes <= memory.nbytes, name
        assert a.base is not None and not a.tobytes().strip(b"\0"), name
        spans.append((at, at + a.nbytes, name))
    spans.sort()
    for (_, end, name), (start, _, after) in zip(spans, spans[1:]):
        assert end <= start, f"{name} overlaps {after}"
    assert (state.integrator.stages.shape, state.integrator.dense.shape, state.book.ring.shape,
            state.broad_phase.reference.shape) == ((stages, ny), (ny, k), (npair, zeno_max), (n, 6))
    memory.view(np.uint8)[:] = 7  # every byte of every array is the buffer's
    assert all(not a.tobytes().strip(b"\7") for a in flatten(state).values())


def test_held_csv_excitation_equals_held_advances(tmp_path):
    """A zero-order-hold CSV in a scene gives the same run as feeding the rows to advance()."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 0.3, 0.01)
    acc = rng.uniform(-6, 6, (len(t), 2))
    rows = np.column_stack([t, acc])
    np.savetxt(tmp_path / "zoh.csv", rows, delimiter=",", header="time,ax,ay", comments="")
    doc = dual(angles=(0.0, 0.3), excitation={"kind": "csv", "file": str(tmp_path / "zoh.csv"), "hold": True})
    run = simulate(scene(doc), 0.29, rtol=1e-11, atol=1e-13)
    s = Solver(scene(dual(angles=(0.0, 0.3))), rtol=1e-11, atol=1e-13, driven=True)
    for k in range(len(t) - 1):
        s.advance(0.01, base_accel=tuple(acc[k]))
    assert run.collision_count > 0
    np.testing.assert_allclose(s.angles, run.angles[-1], atol=1e-9)


def test_impacts_closed_while_stepping_match_a_whole_run(collision_scene):
    whole = simulate(collision_scene, 1.0)
    s = Solver(collision_scene)
    got = []
    for _ in range(1000):
        s.advance(1e-3)
        imp = s.take_impacts()
        got += list(zip(imp.onset, imp.peak_force))
    closed = ~whole.impacts.ongoing
    np.testing.assert_allclose([g[0] for g in got], whole.impacts.onset[closed], atol=1e-9)
    np.testing.assert_allclose([g[1] for g in got], whole.impacts.peak_force[closed], rtol=1e-6)


def same_state(a, b) -> bool:
    fa, fb = flatten(a), flatten(b)
    return fa.keys() == fb.keys() and all(np.array_equal(fa[k], fb[k]) for k in fa)


def twelve_berries():
    from pathlib import Path

    from grapefmu.cluster import ClusterSpec, cluster_scene
    from grapefmu.scenefile import scene_from_dict
    return scene_from_dict(cluster_scene(ClusterSpec(berries=12, seed=3)), Path.cwd())


def cluster_state():
    return Solver(twelve_berries()).get_state()


def corrupted(state, name, how):
    arrays = {k: v.copy() for k, v in flatten(state).items()}
    a = arrays[name]
    if how == "truncate":
        arrays[name] = a[:-1] if a.ndim == 1 else a[:, :-1]
    elif how == "nan":
        if a.dtype.names:
            a[a.dtype.names[1]].flat[0] = np.nan
        else:
            a.flat[0] = np.nan
    elif how == "huge":
        a.view(np.int64 if a.dtype.itemsize % 8 == 0 else np.uint8).flat[0] = 10**9
    from grapefmu.solver.state import unflatten
    return unflatten(arrays)


def test_a_state_with_a_negative_contact_step_is_refused(collision_scene):
    """clock.h_contact (the step a contact onset starts from) is part of the state and checked with it."""
    from grapefmu.solver.state import copy

    s = Solver(collision_scene)
    s.advance(0.5)
    mine = s.get_state()
    assert mine.integrator.clock["h_contact"][0] > 0  # the scene's first impact has set it
    bad = copy(mine)
    bad.integrator.clock["h_contact"] = -1e-3
    with pytest.raises(StateError, match=r"integrator\.clock.*h_contact"):
        s.set_state(bad)
    assert same_state(mine, s.state)


@pytest.mark.parametrize("name, how, field", [
    ("physical.y", "truncate", "physical.y"), ("integrator.stages", "truncate", "integrator.stages"),
    ("integrator.dense", "truncate", "integrator.dense"), ("physical.y", "nan", "physical.y"),
    ("broad_phase.near", "huge", "broad_phase.near"), ("broad_phase.count", "huge", "broad_phase.count"),
    ("physical.contacts", "huge", "physical.contacts.mode"), ("integrator.clock", "nan", "integrator.clock"),
])
def test_a_corrupted_state_is_refused_naming_the_field_and_the_solver_goes_on(collision_scene, name, how, field):
    s = Solver(collision_scene)
    s.advance(0.05)
    mine = s.get_state()
    with pytest.raises(StateError, match=field.replace(".", r"\.")):
        s.set_state(corrupted(mine, name, how))
    assert same_state(mine, s.state)
    twin = Solver(collision_scene)
    twin.advance(0.05)
    s.advance(0.1)
    twin.advance(0.1)
    np.testing.assert_array_equal(s.y, twin.y)


@pytest.mark.parametrize("name, field, value, refused", [
    ("book.pair", "impulse", np.nan, True), ("book.pair", "onset", np.inf, True),
    ("book.pair", "smooth_until", np.inf, False), ("book.pair", "smooth_until", np.nan, True),
    ("input", "alpha_y", -np.inf, True),  # a packed record: its floats are off the 8-byte lines
    ("book.totals", "peak_pedicel_tension", -np.inf, False), ("book.totals", "peak_contact_force", np.inf, True),
    ("integrator.clock", "h_last", np.nan, True), ("book.ring", None, -np.inf, False), ("physical.y", None, np.inf, True),
])
def test_each_float_field_is_checked_by_its_own_rule(collision_scene, name, field, value, refused):
    """set_state gathers a record's float fields from its bytes in one go: each field must still be refused by its
    own name, and only the fields that may be infinite (state.MAY_BE_INFINITE) let an infinity through."""
    from grapefmu.solver.state import MAY_BE_INFINITE, unflatten
    s = Solver(collision_scene)
    s.advance(0.3)
    good = s.get_state()
    arrays = {k: v.copy() for k, v in flatten(good).items()}
    a = arrays[name]
    target = a[field] if field else a
    target.flat[-1] = value
    dotted = f"{name}.{field}" if field else name
    assert refused == (np.isnan(value) or dotted not in MAY_BE_INFINITE)  # the table agrees with the rule
    if refused:
        with pytest.raises(StateError, match=re.escape(f"state {dotted}: ")):
            s.set_state(unflatten(arrays))
        assert same_state(good, s.state)
    else:
        s.set_state(unflatten(arrays))
        assert same_state(unflatten(arrays), s.state)


def test_a_state_with_many_pairs_round_trips_and_names_a_bad_pair_field():
    """Records of several rows (a 12-berry cluster's pairs): their floats are gathered row by row (a fancy index of
    the bytes that numpy laid out by columns once made set_state raise ValueError for any scene of two pairs or
    more, and the FMU's build refused its own state)."""
    from grapefmu.solver.state import unflatten
    state = cluster_state()
    s = Solver(twelve_berries())
    assert state.physical.contacts.shape[0] > 2
    s.set_state(state)
    assert same_state(state, s.state)
    arrays = {k: v.copy() for k, v in flatten(state).items()}
    arrays["book.pair"]["dissipated"][-1] = np.nan
    with pytest.raises(StateError, match=re.escape("state book.pair.dissipated: ")):
        s.set_state(unflatten(arrays))
    assert same_state(state, s.state)


def test_a_state_from_another_scene_is_refused(collision_scene):
    s = Solver(collision_scene)
    with pytest.raises(StateError, match="another scene"):
        s.set_state(cluster_state())  # other sizes
    heavier = scene(dual(left={"mass": 0.02}, solver={"t_end": 2.0}))
    with pytest.raises(StateError, match="fingerprint"):
        s.set_state(Solver(heavier).get_state())  # same sizes, other parameters
    with pytest.raises(StateError):
        s.set_state("not a state")


@pytest.mark.parametrize("dt, accel", [(10**400, None), (True, None), ("ab", None), (1e-3, (1.0,)),
                                       (1e-3, "ab"), (1e-3, (1.0, 2.0, 3.0)), (1e-3, (1e4, 0.0))])
def test_advance_refuses_what_it_cannot_integrate(collision_scene, dt, accel):
    s = Solver(collision_scene)
    before = s.get_state()
    with pytest.raises(SolverError):
        s.advance(dt, accel)
    assert same_state(before, s.state)


def test_fuzzed_states_are_refused_or_integrate_cleanly(collision_scene):
    """Seeded: one element of one field replaced by garbage; set_state refuses it or the solver then
    integrates 10 ms to a finite state or refuses the step. Never a crash, a hang or a NaN."""
    rng = np.random.default_rng(2026)
    s = Solver(collision_scene, max_steps=20_000)
    s.advance(0.3)
    good = s.get_state()
    names = list(flatten(good))
    outcomes = {"refused": 0, "integrated": 0, "step refused": 0}
    for _ in range(150):
        arrays = {k: v.copy() for k, v in flatten(good).items()}
        name = names[rng.integers(len(names))]
        raw = arrays[name].view(np.uint8).reshape(-1)
        if raw.size:
            raw[rng.integers(raw.size)] = rng.integers(256)
        from grapefmu.solver.state import unflatten
        try:
            s.set_state(unflatten(arrays))
        except StateError:
            outcomes["refused"] += 1
            assert same_state(good, s.state)
            continue
        try:
            s.advance(0.01)
            assert np.isfinite(s.y).all()
            outcomes["integrated"] += 1
        except SolverError:
            outcomes["step refused"] += 1
        s.set_state(good)
    print(outcomes)
    assert outcomes["refused"] > 10 and outcomes["integrated"] > 10


def test_a_state_belongs_to_its_scene_in_every_process():
    """The fingerprint is a function of the scene alone (once it hashed a record's uninitialised padding,
    so a state saved by one process was refused by another)."""
    import subprocess
    import sys
    code = ("import grapefmu; s = grapefmu.load_scene(grapefmu.scenefile.default_scene_path()); "
            "print(grapefmu.Solver(s).state.fingerprint[0])")
    prints = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
              for _ in range(3)}
    assert len(prints) == 1


def test_a_rachis_held_still_is_left_out_of_the_state_and_an_input_that_moves_it_is_refused(collision_scene):
    """The paper's scenes hold the rachis still: their state is the angles, rates and energy integrals alone
    (2D + N + C + 2 components), and a Solver of one refuses a linear acceleration by name, state intact."""
    s = Solver(collision_scene)
    m = collision_scene.model
    assert s.layout.size == 2 * m.n_dof + m.n_berries + len(m.couplings) + 2
    s.advance(0.01)
    before = s.get_state()
    with pytest.raises(SolverError, match=r"base_accel: .*does not move.*driven=True"):
        s.advance(1e-3, base_accel=(1.0, 0.0))
    assert same_state(before, s.state)
    s.advance(1e-3, base_accel=(0.0, 0.0))  # no motion is no motion
    snap = s.snapshot()
    assert not snap.base_displacement.any() and snap.ledger[0, 3] == 0.0


def test_a_still_state_gives_the_trajectory_of_one_that_carries_the_rachis(collision_scene):
    """The same scene with and without the rachis' motion in y (a driven Solver carries it, at rest): the runs
    agree to the tolerance asked (the error norm averages over a different number of components, so not bit for
    bit), and the still one's rachis stays at the origin doing no work."""
    still = Solver(collision_scene, rtol=1e-10, atol=1e-12).run(output_interval=1e-3)
    carried = Solver(collision_scene, rtol=1e-10, atol=1e-12, driven=True).run(output_interval=1e-3)
    assert still.layout.size + 13 == carried.layout.size
    assert still.collision_count == carried.collision_count > 0
    np.testing.assert_allclose(still.angles, carried.angles, rtol=0, atol=1e-8)
    np.testing.assert_allclose(still.ledger, carried.ledger, rtol=1e-8, atol=1e-14)
    assert not still.base_displacement.any() and not carried.base_displacement.any()


@pytest.mark.parametrize("kwargs, words", [
    (dict(rtol=float("nan")), r"rtol: expected a number in \[1e-14, 0.1\], got nan"),
    (dict(atol=0.0), r"atol: expected a number in \(1e-16, 1\], got 0.0"),
    (dict(rtol=-1.0), "rtol"), (dict(fixed_step=float("inf")), r"fixed_step: expected a number in \[0, 1\] s"),
    (dict(fixed_step=-1.0), "fixed_step"),
])
def test_settings_a_scene_file_could_not_hold_are_refused_by_solver_and_simulate(collision_scene, kwargs, words):
    """An audit: rtol NaN or atol 0 from Python made the first step size NaN, and the loop rejected NaN steps forever
    (rejections do not count towards max_steps; Ctrl-C could not reach it); fixed_step inf or −1 and rtol −1 were
    taken silently. Each is now refused in the range its scene key has."""
    with pytest.raises(SolverError, match=words):
        Solver(collision_scene, **kwargs)
    with pytest.raises(SolverError, match=words):
        simulate(collision_scene, 0.1, **kwargs)


@pytest.mark.parametrize("kwargs, words", [(dict(max_steps=0), r"max_steps: expected an integer in \[1, 1e\+12\]"),
                                           (dict(t_start=float("nan")), "t_start: expected a finite time"),
                                           (dict(t_start=10**400), "t_start"), (dict(rtol=10**400), "rtol"),
                                           (dict(max_steps=10**400), "max_steps")])
def test_a_step_limit_or_start_time_out_of_range_is_refused(collision_scene, kwargs, words):
    with pytest.raises(SolverError, match=words):
        Solver(collision_scene, **kwargs)


def test_a_nan_step_size_ends_the_loop_instead_of_rejecting_forever(tmp_path):
    """The loop's underflow check let a NaN step size through (NaN < bound is False): with the settings checked at the
    door this is defence in depth, tested behind the door (a corrupted config), in a process of its own so that a
    hang fails the test instead of the suite."""
    import subprocess
    import sys
    code = ("import math; from grapefmu import Solver, SolverError; from tests.conftest import scene, dual\n"
            "s = Solver(scene(dual(solver={'t_end': 0.1}))); s.config[0]['rtol'] = math.nan\n"
            "try:\n    s.run(0.1)\nexcept SolverError as e:\n    print('refused:', e)\n")
    from pathlib import Path
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=Path(__file__).resolve().parents[1])
    assert "refused: integration stopped at t = 0 s" in out.stdout, out.stdout + out.stderr


@pytest.mark.parametrize("args, words", [
    ((-1.0,), "t_end: expected a time from the solver's t = 0.5 s"), ((float("nan"),), "t_end"),
    ((float("inf"),), "t_end"), (("0.9",), "t_end"), ((0.2,), "t_end"), ((10**400,), "t_end"),
    ((0.9, 0.0), r"output_interval: expected a number in \[1e-06, 100000\] s, got 0.0"),
    ((0.9, float("inf")), "output_interval"), ((0.9, float("nan")), "output_interval"),
    ((5e4, 1e-6), "t_end, output_interval: .* GiB of memory"),
])
def test_run_refuses_an_end_or_interval_it_cannot_take_and_keeps_the_state(collision_scene, args, words):
    """Each was a raw ValueError, ZeroDivisionError or MemoryError from numpy (an audit), and output_interval inf gave a
    run of one sample at its start whose summary said t_end 0 s."""
    from grapefmu.errors import GrapefmuError
    s = Solver(collision_scene)
    s.run(0.5)
    before = s.get_state()
    with pytest.raises(GrapefmuError, match=words):
        s.run(*args)
    assert same_state(before, s.state)
    assert len(s.run(0.5).t) == 1  # a run of no length is one sample, the state now


def test_dense_output_is_refused_before_a_step_and_outside_it(collision_scene):
    """Before any step it gave NaN and numpy's warnings; outside the last step it extrapolated silently."""
    s = Solver(collision_scene)
    with pytest.raises(SolverError, match="no step taken yet"):
        s.dense_output()
    s.advance(0.01)
    y_of = s.dense_output()
    np.testing.assert_allclose(y_of(s.t), s.y, atol=1e-12)
    with pytest.raises(SolverError, match=r"t: expected times in the last step"):
        y_of(s.t + 10.0)


def test_advance_refuses_a_step_that_cannot_move_time_and_takes_any_real_number(collision_scene):
    """advance(1e-20) at t = 0.5 s returned with t unchanged ("integrate exactly dt seconds"); numpy's float32 was
    refused where float64 and int were taken."""
    s = Solver(collision_scene)
    s.advance(np.float32(0.5))
    before = s.get_state()
    with pytest.raises(SolverError, match=r"dt: 1e-20 s does not move t = 0\.5 s"):
        s.advance(1e-20)
    assert same_state(before, s.state)


def test_a_fixed_step_too_small_for_the_step_limit_is_refused_before_a_step(collision_scene):
    """fixed_step 1e-300 took 10⁷ steps before it was refused."""
    s = Solver(collision_scene, fixed_step=1e-300)
    with pytest.raises(SolverError, match=r"fixed_step: 0.1 s in steps of 1e-300 s is 1e\+299 steps, more than "
                                          r"max_steps = 10000000"):
        s.run(0.1)
    assert s.stats["steps"] == 0


def test_a_state_overlapping_deeply_while_its_mode_says_apart_is_refused(collision_scene):
    """set_state took a state whose berries overlapped 0.53 of a radius with their pair's mode apart: stepped, the
    berries were flung apart at 46 rad/s (an audit). A solver that presses that deep holds the pair in contact, and
    such a state is taken."""
    s = Solver(collision_scene)
    state = s.get_state()
    state.physical.y[:2] = 0.4, 0.0  # the left berry swung into the right one, hanging still: 8.5 mm deep
    before = s.get_state()
    with pytest.raises(StateError, match=r"state physical.y: berries 'left' and 'right' overlap by .* while its "
                                         "contact mode says apart"):
        s.set_state(state)
    assert same_state(before, s.state)
    state.physical.contacts["mode"] = 1
    state.broad_phase.near[0], state.broad_phase.count[0] = 0, 1  # a pair in contact is on the near list
    s.set_state(state)
    assert s.touching
