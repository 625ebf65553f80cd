"""Issue 16, item 5: a run whose results cannot be trusted says so in `summary()["warnings"]`, the CLI prints
the warnings after the summary table, and `grapefmu simulate --strict` exits 3 on any of them."""
from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

import pytest

from grapefmu.cli import main
from grapefmu.results import trust
from grapefmu.scenefile import default_scene_path, dumps, scene_from_dict
from grapefmu.solver.api import simulate

DEFAULT = tomllib.loads(Path(default_scene_path()).read_text())


def variant(**tables) -> dict:
    """The default scene with some tables' entries replaced (excitation replaced whole)."""
    doc = copy.deepcopy(DEFAULT)
    for name, entries in tables.items():
        if name == "excitation":
            doc[name] = entries
        else:
            doc.setdefault(name, {}).update(entries)
    return doc


def run_of(doc: dict, **kw):
    return simulate(scene_from_dict(copy.deepcopy(doc), Path.cwd()), **kw)


def cli(tmp_path: Path, doc: dict | None, *args: str, capsys) -> tuple[int, str]:
    argv = ["simulate"]
    if doc is not None:
        path = tmp_path / "scene.toml"
        path.write_text(dumps(doc))
        argv.append(str(path))
    rc = main([*argv, *args])
    out = capsys.readouterr()
    return rc, out.out + out.err


def test_default_scene_has_no_warnings_and_strict_exits_0(tmp_path, capsys):
    run = run_of(DEFAULT)
    assert run.summary()["warnings"] == []
    assert math.isfinite(run.ledger_error()) and run.ledger_error() < trust.ledger_tolerance(1e-8)
    rc, out = cli(tmp_path, None, "--strict", capsys=capsys)
    assert rc == 0 and "warning" not in out
    assert "relative to the energy scale" in out


def test_fixed_step_too_long_for_the_contact_warns_and_strict_exits_3(tmp_path, capsys):
    doc = variant(solver={"fixed_step": 1.0})
    warnings = run_of(doc).summary()["warnings"]
    step = [w for w in warnings if w.startswith("fixed step")]
    assert len(step) == 1 and "left_right" in step[0] and "period" in step[0]
    assert any(w.startswith("energy ledger error") for w in warnings)  # the ledger does not close either
    rc, out = cli(tmp_path, doc, "--strict", capsys=capsys)
    assert rc == 3 and "warning: fixed step" in out
    rc, out = cli(tmp_path, doc, capsys=capsys)
    assert rc == 0 and "warning: fixed step" in out  # without --strict: reported, not fatal


def test_fixed_step_threshold_is_a_tenth_of_the_contact_period():
    # Kelvin–Voigt 2000 N/m between 11 g and 12 g berries: T = 2π √(m*/k)
    m_eff = 0.011 * 0.012 / 0.023
    period = 2 * math.pi * math.sqrt(m_eff / 2000.0)
    fine, coarse = 0.9 * trust.STEP_FRACTION * period, 1.2 * trust.STEP_FRACTION * period
    run = run_of(variant(solver={"fixed_step": fine, "t_end": 0.6}))
    assert trust.contact_period(run)[0] == pytest.approx(period)
    assert trust.fixed_step_warning(run) is None
    assert trust.fixed_step_warning(run_of(variant(solver={"fixed_step": coarse, "t_end": 0.6}))) is not None
    assert run_of(variant(solver={"fixed_step": 1e-4})).summary()["warnings"] == []  # small enough: no warning


def test_an_obstacle_pair_s_contact_period_is_the_berry_s_own():
    """A scene with an obstacle and a fixed step: the summary's fixed-step check looked the obstacle up as a berry
    (IndexError after the run, a traceback; found by fuzzing scene files). Its reduced mass is the berry's own: the
    obstacle does not move."""
    doc = variant(solver={"fixed_step": 1e-3, "t_end": 0.05})
    doc["obstacles"] = [{"name": "floor", "point": [0.0, 0.0, -0.2], "normal": [0.0, 0.0, 1.0], "stiffness": 1e4}]
    run = run_of(doc)
    period, p = trust.contact_period(run)
    assert run.scene.model.pair_name(p) == "left_floor"  # the stiffest relative to its mass: the lighter berry's
    assert period == pytest.approx(2 * math.pi * math.sqrt(0.011 / 1e4))
    assert isinstance(run.summary()["warnings"], list)


def test_hertz_stiffness_is_taken_at_the_peak_force():
    doc = variant(solver={"t_end": 0.8})
    doc["contact"] = {"law": "hertz", "stiffness": 2e5}
    run = run_of(doc)
    f = float(run.peak_force[0])
    assert f > 0
    k = 1.5 * (2e5 ** 2 * f) ** (1 / 3)
    m_eff = 0.011 * 0.012 / 0.023
    assert trust.contact_period(run)[0] == pytest.approx(2 * math.pi * math.sqrt(m_eff / k))


@pytest.mark.parametrize("angle", [0.0, 1e-9])
def test_a_scene_at_rest_reports_the_ledger_as_not_meaningful(tmp_path, capsys, angle):
    """No excitation, berries at rest (or 1e-9 rad off): the energy scale is round-off, so no relative
    error is claimed and nothing is flagged (issue 16: a ledger error of 1.25 against 1e-18 J)."""
    doc = variant(excitation={"kind": "none"}, solver={"t_end": 0.5})
    doc["berries"][0]["angle"] = angle
    run = run_of(doc)
    err, scale, floor = trust.ledger_assessment(run)
    assert math.isnan(err) and scale < floor
    assert run.ledger_report().startswith("not meaningful (energy scale")
    assert run.summary()["warnings"] == []
    rc, out = cli(tmp_path, doc, "--strict", capsys=capsys)
    assert rc == 0 and "not meaningful" in out and "warning" not in out


def test_ledger_tolerance_follows_rtol_within_bounds():
    assert trust.ledger_tolerance(1e-8) == pytest.approx(1e-5)
    assert trust.ledger_tolerance(1e-12) == 1e-6
    assert trust.ledger_tolerance(1e-3) == 1e-2


def test_paper_method_at_high_stiffness_disagrees_with_event_location(tmp_path, capsys):
    doc = variant(contact={"stiffness": 1e8}, solver={"t_end": 0.8})
    run = run_of(doc, method="paper")
    lines = [w for w in run.summary()["warnings"] if w.startswith("paper method disagrees with event location")]
    assert len(lines) == 1 and "collisions" in lines[0]
    rc, out = cli(tmp_path, doc, "--method", "paper", "--strict", capsys=capsys)
    assert rc == 3 and "warning: paper method disagrees" in out
    # the same scene with event location has nothing to compare and nothing to flag
    assert not any("paper method" in w for w in run_of(doc).summary()["warnings"])


def test_paper_method_on_a_large_scene_says_the_cross_check_was_skipped():
    from grapefmu.cluster.generate import ClusterSpec, cluster_scene
    doc = cluster_scene(ClusterSpec(berries=12, seed=3, solver={"rtol": 1e-6, "atol": 1e-9, "t_end": 0.02,
                                                                "output_interval": 1e-3}))
    warnings = simulate(scene_from_dict(doc, Path.cwd()), method="paper").summary()["warnings"]
    assert any(w.startswith("paper method not cross-checked") and "12 berries" in w for w in warnings)
