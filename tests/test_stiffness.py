"""A hinge too stiff for the explicit pairs within the step limit is refused before the first step, naming it
(solver/stiffness.py, docs/reliability.md "Known limits"); the bound it refuses on holds on runs that are stepped."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import grapefmu
from grapefmu.bench.scenes import _dual, build
from grapefmu.errors import SolverError
from grapefmu.solver.stiffness import least_steps, stability_polynomial, stability_radius
from grapefmu.solver.tableau import BOGACKI_SHAMPINE, DOP853, DOPRI5


@pytest.mark.parametrize("tb", [DOPRI5, DOP853, BOGACKI_SHAMPINE], ids=["DOPRI5", "DOP853", "ode23"])
def test_the_stability_radius_is_where_a_scan_of_each_ray_leaves_the_region(tb):
    """Against a plain scan of |R| outward along rays (not the roots the module solves for): the farthest first exit
    over the left half-plane, and R itself against e^z's series, which an order-p pair matches to z^p."""
    coef = stability_polynomial(tb)
    assert np.allclose(coef[: tb.order + 1], [1 / math.factorial(k) for k in range(tb.order + 1)], rtol=1e-12)
    radii = np.arange(1, 1201) * 0.01
    far = 0.0
    for phi in np.linspace(math.pi / 2, math.pi, 181):
        inside = np.abs(np.polynomial.polynomial.polyval(radii * np.exp(1j * phi), coef)) <= 1.0
        far = max(far, radii[np.argmin(inside)] if not inside.all() else radii[-1])
    assert far - 0.01 <= stability_radius(tb) <= far * 1.01


def stiff(damping: float, stiffness: float = 1e-3, t_end: float = 2.0):
    """The paper collision's pair with the right berry's hinge made stiff (m l² = 9.9e-6 kg·m²)."""
    return build(_dual((0.0, math.pi / 4), right={"hinge_damping": damping, "hinge_stiffness": stiffness},
                       t_end=t_end))


def test_a_hinge_too_stiff_for_the_step_limit_is_refused_before_any_step():
    sc = stiff(1000.0)  # |λ| ≥ c / (2 m l²) = 5.1e7 /s: at least 1.5e7 steps of DOP853 over 2 s
    s = grapefmu.Solver(sc, rtol=1e-6)
    before = s.stats
    with pytest.raises(SolverError, match=r"berries\[1\] \('right'\).*max_steps = 10000000: hinge_damping = 1000 "):
        s.run()
    assert s.t == 0.0 and s.stats == before and s.stats["steps"] == 0
    with pytest.raises(SolverError, match="too stiff"):
        grapefmu.simulate(sc)
    # allowed more steps, or asked a shorter span, it runs (here 20 µs)
    run = grapefmu.Solver(sc, rtol=1e-6).run(2e-5, 1e-5)
    assert run.t[-1] == pytest.approx(2e-5)


@pytest.mark.parametrize("damping, stiffness, t_end, loose", [(10.0, 1e-3, 0.02, 4.0), (0.0, 1000.0, 0.2, None)],
                         ids=["damper", "spring"])
def test_no_run_takes_fewer_steps_than_the_bound(damping, stiffness, t_end, loose):
    """The bound is a floor on the steps actually taken; on a damper, whose fast eigenvalue is c/(m l²) where the
    bound takes half of it, and DOP853's real interval 6.1 where r_max is 6.8, within a small factor of them."""
    sc = stiff(damping, stiffness, t_end)
    s = grapefmu.Solver(sc, rtol=1e-6)
    bound, berry = least_steps(sc.model, s.tableau, t_end, s.layout.turning)
    assert berry == 1 and bound > 200
    s.run()
    steps = s.stats["steps"]
    assert steps >= bound
    if loose:
        assert steps <= loose * bound


def test_a_face_step_too_long_for_the_stiffest_hinge_is_refused_at_once():
    """advance(dt), as the FMU's doStep and the ROS node call it with their own step limit: a dt whose bound passes
    max_steps is refused before a step, the state as it was; a dt within it is stepped, in no fewer steps."""
    sc = stiff(1000.0)
    s = grapefmu.Solver(sc, rtol=1e-6, max_steps=1000, driven=True)  # DOPRI5: at least 1.5e7 steps a second
    before = s.stats
    with pytest.raises(SolverError, match=r"berries\[1\] \('right'\).*max_steps = 1000: .*nothing was run"):
        s.advance(1e-3, base_accel=(0.0,) * 6)
    assert s.t == 0.0 and s.stats == before
    bound = least_steps(sc.model, s.tableau, 2e-5, s.layout.turning)[0]
    assert bound < 1000
    s.advance(2e-5, base_accel=(0.0,) * 6)
    assert s.t == pytest.approx(2e-5) and s.stats["steps"] >= bound


def test_a_scene_file_sets_the_step_limit():
    """solver.max_steps in the scene file is the limit a Solver and simulate keep (the way out the refusal names),
    checked like every setting."""
    doc = _dual((0.0, math.pi / 4), right={"hinge_damping": 1000.0}, t_end=1e-3)  # at least 7.4e3 steps
    doc["solver"]["max_steps"] = 1000
    with pytest.raises(SolverError, match=r"max_steps = 1000: .*\(solver.max_steps\)"):
        grapefmu.simulate(build(doc))
    doc["solver"]["max_steps"] = 100_000
    sc = build(doc)
    assert grapefmu.Solver(sc).max_steps == 100_000
    run = grapefmu.simulate(sc)
    assert run.t[-1] == pytest.approx(1e-3) and run.stats["steps"] >= least_steps(sc.model, DOP853, 1e-3, False)[0]
    assert grapefmu.Solver(sc, max_steps=7).max_steps == 7  # a caller's own limit still wins
    for bad, words in ((0, r"integer in \[1, 1000000000000\], got 0"), (2.5, "integer"), (True, "integer")):
        doc["solver"]["max_steps"] = bad
        with pytest.raises(grapefmu.SceneError, match=words) as e:
            build(doc)
        assert e.value.key == "solver.max_steps"


def test_a_face_step_keeps_the_scenes_step_limit(tmp_path):
    """The FMU's doStep (and the ROS node's tick: both advance a driven Solver) takes the scene's solver.max_steps, the
    way out its errors name; a scene that does not set it gets 10⁵ a step, where a run gets 10⁷. On a hinge whose 1 ms
    step needs at least 743 steps of DOP853 (bound) and takes 1586: a limit under the bound is refused before a step,
    one between the bound and the steps taken stops at the limit, the FMU keeping its state either way."""
    from grapefmu_fmu.core import DISCARD, FmuCore

    doc = _dual((0.0, math.pi / 4), right={"hinge_damping": 100.0})
    assert grapefmu.Solver(build(doc)).max_steps == 10_000_000

    def step(max_steps):
        if max_steps is not None:
            doc["solver"]["max_steps"] = max_steps
        path = tmp_path / f"limit{max_steps}.toml"
        path.write_text(build(doc).source)
        core = FmuCore(path)
        assert core.initialize(0.0) is None
        return core, core.step(0.0, 1e-3)

    core, out = step(None)
    bound = least_steps(core.scene.model, core.solver.tableau, 1e-3, core.solver.layout.turning)[0]
    assert out is None and core.solver.max_steps == 100_000 and core.solver.stats["steps"] >= bound
    taken = core.solver.stats["steps"]
    for limit, words in ((int(0.7 * bound), rf"max_steps = {int(0.7 * bound)}: .*nothing was run"),
                         ((int(bound) + taken) // 2, rf"step limit was reached \({(int(bound) + taken) // 2} steps")):
        core, out = step(limit)
        assert out is not None and out[0] == DISCARD and re.search(words, out[1]), out
        assert "solver.max_steps" in out[1] and core.solver.t == 0.0 and core.solver.stats["steps"] == 0


def test_a_run_stopped_at_its_step_limit_in_contact_names_the_pair_and_its_law():
    """A contact law is stiff only while its pair touches, so it is not refused before a step: a run that stops at its
    step limit in contact names the pairs touching, their laws and, for Kelvin–Voigt, the time scales m/c and √(m/k)
    on the pair's mass m. Pressed together (hanging 1 mm into each other) on a damping of 1e4 N·s/m, m/c = 5.5e-7 s:
    the steps the error reports are the pair's stability limit on that time scale (h ≤ r_max m/c), not accuracy's."""
    sc = build(_dual(d0=0.026, contact={"law": "kelvin-voigt", "stiffness": 2000.0, "damping": 1e4}, t_end=0.1))
    s = grapefmu.Solver(sc, rtol=1e-6, max_steps=3000)
    with pytest.raises(SolverError, match=r"step limit was reached.*in contact when it stopped: left_right "
                       r"\(kelvin-voigt: stiffness 2e\+03 N/m, damping 1e\+04 N·s/m; m = 0.0055 kg, "
                       r"m/c = 5.5e-07 s, √\(m/k\) = 0.00166 s\)") as e:
        s.run()
    assert s.t == 0.0
    h = float(re.search(r"the step size was ([0-9.e+-]+) s", str(e.value)).group(1))
    assert 0.5 * stability_radius(s.tableau) * 5.5e-7 < h <= stability_radius(s.tableau) * 5.5e-7


@pytest.mark.parametrize("law, coefficients", [
    ("hertz", "stiffness 1e+12 N/m^1.5"), ("hunt-crossley", "stiffness 1e+12 N/m^1.5, damping 0.5 (χ, dimensionless)")])
def test_a_hertzian_pair_stopped_at_its_step_limit_is_named_with_its_time_scales_at_the_overlap(law, coefficients):
    """A Hertzian law has no fixed time scale: the pair's words give its coefficients, its mass and, at the overlap δ
    when it stopped, its stiffness k = dF/dδ = 1.5 K √δ and √(m/k); Hunt–Crossley's also its damping there,
    c = ∂F/∂δ̇ = χ K δ^1.5 / δ̇⁻, and m/c. The run stops after exactly max_steps accepted steps (it took 5000
    before, the loop's chunk): one Solver stepped that many times by step() stands where the run stopped, and its
    own observation and contact record give the overlap and the onset speed δ̇⁻ the figures come from."""
    contact = {"law": law, "stiffness": 1e12, **({"damping": 0.5} if law == "hunt-crossley" else {})}
    sc = build(_dual(d0=0.026, contact=contact, t_end=0.1))
    with pytest.raises(SolverError, match=re.escape(f"in contact when it stopped: left_right ({law}: {coefficients}; "
                                                    "m = 0.0055 kg; at δ = ")) as e:
        grapefmu.Solver(sc, rtol=1e-6, max_steps=3).run()  # pressed 1 mm: the first 5 steps are in contact
    words = str(e.value)
    number = "([0-9.e+-]+|inf)"
    t = float(re.search(rf"stopped at t = {number} s", words)[1])
    d, k = (float(x) for x in re.search(rf"at δ = {number} m, k = {number} N/m", words).groups())
    tau_k = float(re.search(rf"√\(m/k\) = {number} s\)", words)[1])
    stepped = grapefmu.Solver(sc, rtol=1e-6)
    for _ in range(3):
        stepped.step()
    assert stepped.t == pytest.approx(t, rel=1e-8)
    assert d == pytest.approx(float(stepped.observe().penetration[0, 0]), rel=5e-3)
    assert k == pytest.approx(1.5e12 * math.sqrt(d), rel=5e-3)
    assert tau_k == pytest.approx(math.sqrt(0.0055 / k), rel=5e-3)
    if law == "hunt-crossley":
        c, tau_c = (float(x) for x in re.search(rf"c = {number} N·s/m, m/c = {number} s", words).groups())
        v_onset = float(stepped.state.physical.contacts["v_onset"][0])
        assert c == pytest.approx(0.5 * 1e12 * d ** 1.5 / v_onset, rel=1e-2)
        assert tau_c == pytest.approx(0.0055 / c, rel=5e-3)
    else:
        assert "m/c" not in words and "damping" not in words.split("left_right")[1]


def test_a_fixed_step_that_blows_a_hinge_up_says_which_and_how_short_a_step_holds():
    """A fixed step past a hinge's stability (the paper method, ode23: h|λ| = 3.03 where its real interval ends at
    2.51) ends with NaN as before, now naming the hinge and the longest stable step; 0.97 of that step, taken at
    its word, runs to the end with finite angles."""
    import re

    sc = stiff(0.03, t_end=0.5)
    with pytest.raises(SolverError, match=r"NaN or infinite \(berries\[1\] \('right'\).*ode23") as e:
        grapefmu.simulate(sc, method="paper", fixed_step=1e-3, output_interval=1e-3, cross_check=False)
    longest = float(re.search(r"a fixed step under ([0-9.e+-]+) s keeps it stable", str(e.value))[1])
    assert 8e-4 < longest < 1e-3
    run = grapefmu.simulate(sc, method="paper", fixed_step=0.97 * longest, output_interval=1e-3, cross_check=False)
    assert run.t[-1] == pytest.approx(0.5) and np.isfinite(run.angles).all()
