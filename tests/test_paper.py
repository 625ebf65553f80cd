"""`grapefmu paper` reproduces tests 1–9, draws its figures and reports a measured verdict per claim."""
from __future__ import annotations

import re

from grapefmu.paper.reproduce import reproduce


def test_paper_reproduction_writes_figures_and_verdicts(tmp_path, capsys):
    assert reproduce(tmp_path) == 0
    figs = sorted(p.name for p in tmp_path.glob("fig*.png"))
    assert [f[:5] for f in figs] == ["fig09", "fig11", "fig13", "fig14", "fig15", "fig16", "fig17"]
    assert all((tmp_path / f).stat().st_size > 10_000 for f in figs)
    report = (tmp_path / "claims.md").read_text()
    verdicts = re.findall(r"\*\*(AGREES|PARTLY|DISAGREES)\*\*", report)
    assert len(verdicts) == 6
    # exact mirror symmetry is a property of the model and the solver, not of tuning
    assert "**AGREES**: The symmetric case" in report
    # §3.3.1: "in test 5 [hinges viscoelastic], a noticeable delay occurs before the collision happens, and the
    # vibration range of the twig narrows"; the claim checked said the reverse (test_the_claims_measure_...)
    assert "Hinge viscoelasticity delays the collision and narrows the twig's swing (test 5 vs test 6" in report
    assert report in capsys.readouterr().out


def test_the_claims_measure_what_the_paper_describes():
    """An audit against the paper's text: its test 5 (hinges viscoelastic) collides later than test 6, and the claim
    said the reverse; the test 3/4 period was the median over the whole run, most of it after the collisions ended (the
    free tail: "the same swing period"); test 9's "maximum deflection" took |angle|, the inward swing too. Here the
    helpers on signals whose answers are known."""
    from types import SimpleNamespace

    import numpy as np

    from grapefmu.paper.reproduce import max_between, swing_period

    t = np.arange(0.0, 4.0, 1e-4)  # the free tail longer than the colliding start, as in test 3
    q = np.where(t < 1.0, np.sin(2 * np.pi * t / 0.2), np.sin(2 * np.pi * (t - 1.0) / 0.3))
    assert abs(swing_period(t, q, until=1.0) - 0.2) < 1e-3 and abs(swing_period(t, q) - 0.3) < 1e-3
    run = SimpleNamespace(t=t, angles=np.column_stack([-q, 0.5 + 0.0 * t]))  # berry 1 starts on the + side
    run.angles[:, 1] = np.where(t < 0.5, 0.5, np.where(t < 1.0, -np.radians(10.3), np.radians(8.8)))
    assert np.isclose(max_between(run, 1, 0.6, 1.9), np.radians(10.3))
    assert np.isclose(max_between(run, 1, 0.6, 1.9, outward=True), np.radians(8.8))

