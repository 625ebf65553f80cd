"""`grapefmu risk` (issue 15): probabilities that a direct count of the same runs reproduces, intervals that cover
the estimate of ten times the samples, plans on common draws, the duration search, interruption and resume."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import grapefmu
from grapefmu.risk import assess, clopper_pearson, distribution, run_plan, time_scaled
from grapefmu.scenefile import scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples" / "fit_and_risk"
#: wide enough that the fast plan sometimes bruises and sometimes detaches a berry
RANGES = ["berries[*].hinge_damping=1e-5:5e-5", "contact.stiffness=1000:8000", "thresholds.bruise_force=1.5:4",
          "thresholds.detachment_force=0.5:3"]


@pytest.fixture(scope="module")
def plans(tmp_path_factory) -> list[Path]:
    """The worked example's two plans with shorter runs (0.4 s after the last move)."""
    d = tmp_path_factory.mktemp("plans")
    out = []
    for name in ("plan_fast", "plan_gentle"):
        text = (EXAMPLES / f"{name}.toml").read_text()
        doc = tomllib.loads(text)
        end = doc["excitation"]["start"] + sum(m["duration"] for m in doc["excitation"]["moves"]) + 0.4
        (d / f"{name}.toml").write_text(text.replace("t_end = 2.5", f"t_end = {end:.6g}"))
        out.append(d / f"{name}.toml")
    return out


def dist(plan: Path):
    return distribution(tomllib.loads(plan.read_text()), None, RANGES)


def row_doc(plan: Path, row: dict) -> dict:
    """The plan's own document with a row's values (RANGES) written in by hand."""
    doc = tomllib.loads(plan.read_text())
    for b in doc["berries"]:
        b["hinge_damping"] = row["berries[*].hinge_damping"]
    doc["contact"]["stiffness"] = row["contact.stiffness"]
    doc["thresholds"]["bruise_force"] = row["thresholds.bruise_force"]
    doc["thresholds"]["detachment_force"] = row["thresholds.detachment_force"]
    return doc


def direct_count(plan: Path, row: dict) -> tuple[bool, bool, set[str], set[str]]:
    """One sample simulated here, from the plan's own document with the row's values written in by hand, and
    its outcomes counted from the impact book and the pedicel tensions (not from the summary)."""
    doc = row_doc(plan, row)
    run = grapefmu.simulate(scene_from_dict(doc, plan.parent))
    th, imp, m = doc["thresholds"], run.impacts, run.scene.model
    hit = (imp.peak_force >= th["bruise_force"]) | (imp.dissipated >= th.get("bruise_energy", 1e-3))
    bruised = {m.names[i] for p in imp.pair[hit] for i in (m.pairs[p].i, m.pairs[p].j)}
    detached = {m.names[i] for i in np.flatnonzero(run.peak_tension > th["detachment_force"])}
    return bool(hit.any()), bool(detached), bruised, detached


def test_probabilities_agree_with_a_direct_count_of_the_same_runs_for_two_plans(plans, tmp_path):
    d = dist(plans[0])
    r = assess(plans, d, 40, 1, tmp_path, workers=0, progress=False)
    fast, gentle = r.outcomes
    # common random numbers: both plans ran the same draws
    inputs = [[{k: row[k] for k in d.keys} for row in o.rows] for o in r.outcomes]
    assert inputs[0] == inputs[1] and len(inputs[0]) == 40
    for plan, o in zip(plans, r.outcomes):
        counts = [direct_count(plan, row) for row in o.rows]
        assert o.bruise.n == 40 and not o.failed
        assert o.bruise.k == sum(c[0] for c in counts)
        assert o.detach.k == sum(c[1] for c in counts)
        for b in ("left", "right"):
            assert o.berry_bruise[b].k == sum(b in c[2] for c in counts)
            assert o.berry_detach[b].k == sum(b in c[3] for c in counts)
    assert 0 < fast.bruise.k < 40 and 0 < fast.detach.k < 40  # the test means something: neither 0 nor all
    assert gentle.bruise.k < fast.bruise.k
    md = (tmp_path / "risk.md").read_text()
    assert "| P(bruise), cluster | " + fast.bruise.text() in md and "Clopper–Pearson" in md
    assert (tmp_path / "risk.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "risk.json").read_text())["plans"][0]["bruise"]["count"] == fast.bruise.k


def test_runs_that_warn_are_counted_and_reported(plans, tmp_path):
    """A plan whose runs cannot be trusted (contacts checked only at the ends of fixed 2 ms steps, five times the
    contact's resolution) still gives its probabilities, and says how many of its runs warned; a plan whose runs
    give no warning says nothing. The count is that of the same runs' own summaries, simulated here."""
    coarse = tmp_path / "plan_coarse.toml"
    coarse.write_text(plans[1].read_text().replace('method = "event"', 'method = "paper"\nfixed_step = 2e-3'))
    d = dist(plans[1])
    r = assess([coarse, plans[1]], d, 3, 5, tmp_path, workers=0, progress=False)
    bad, good = r.outcomes
    alone = [grapefmu.simulate(scene_from_dict(row_doc(coarse, row), coarse.parent)).summary()["warnings"]
             for row in bad.rows]
    assert [row["warnings"] for row in bad.rows] == alone
    assert bad.warned == 3 and all(any(w.startswith("fixed step 0.002 s") for w in ws) for ws in alone)
    assert good.warned == sum(bool(row["warnings"]) for row in good.rows) == 0
    md = (tmp_path / "risk.md").read_text()
    assert "Runs that warned their results cannot be trusted" in md and "plan_coarse: 3 of 3" in md
    assert json.loads((tmp_path / "risk.json").read_text())["plans"][0]["warned_runs"] == 3


def test_the_interval_covers_the_estimate_of_ten_times_the_samples(plans, tmp_path):
    """40 draws against 400 independent ones (another seed): every 95 % interval of the small run holds the
    large run's estimate, whose own spread is a third of the interval's."""
    d = dist(plans[0])
    small = run_plan(plans[0], d, 40, 11, tmp_path / "small", workers=0, progress=False)
    large = run_plan(plans[0], d, 400, 12, tmp_path / "large", workers=0, progress=False)
    pairs = [(small.bruise, large.bruise), (small.detach, large.detach),
             *((small.berry_bruise[b], large.berry_bruise[b]) for b in ("left", "right")),
             *((small.berry_detach[b], large.berry_detach[b]) for b in ("left", "right"))]
    for s, big in pairs:
        lo, hi = s.interval
        assert lo <= big.p <= hi, (s.text(), big.text())
    assert 0.05 < large.bruise.p < 0.95 and 0.05 < large.detach.p < 0.95


@pytest.mark.parametrize("k, n", [(0, 10), (3, 40), (20, 40), (40, 40), (1, 400)])
def test_clopper_pearson_is_the_exact_binomial_interval(k, n):
    """At the lower end P(X ≥ k) = 2.5 %, at the upper P(X ≤ k) = 2.5 % (scipy's binomial, not the beta)."""
    from scipy.stats import binom
    lo, hi = clopper_pearson(k, n)
    assert lo == 0.0 if k == 0 else binom.sf(k - 1, n, lo) == pytest.approx(0.025, abs=1e-9)
    assert hi == 1.0 if k == n else binom.cdf(k, n, hi) == pytest.approx(0.025, abs=1e-9)


def test_a_plan_slowed_down_keeps_its_path_and_its_settling_time(plans):
    from grapefmu.physics.excitation import accel
    doc = tomllib.loads(plans[0].read_text())
    slow = time_scaled(doc, 1.5)
    assert [m["duration"] for m in slow["excitation"]["moves"]] == pytest.approx(
        [1.5 * m["duration"] for m in doc["excitation"]["moves"]])
    moves = sum(m["duration"] for m in doc["excitation"]["moves"])
    assert slow["solver"]["t_end"] == pytest.approx(doc["solver"]["t_end"] + 0.5 * moves)
    a, b = (scene_from_dict(x, plans[0].parent) for x in (doc, slow))
    t = np.linspace(0, 3, 3001)
    # the same path: displacement (the double integral of a) equal at the ends, peaks 1.5² lower
    assert np.abs(accel(b.excitation, t)).max() == pytest.approx(np.abs(accel(a.excitation, t)).max() / 2.25)
    run_a = grapefmu.simulate(a, method="event", output_interval=0.01)
    run_b = grapefmu.simulate(b, method="event", output_interval=0.01)
    assert run_b.base_displacement[-1] == pytest.approx(run_a.base_displacement[-1], abs=1e-9)


def test_the_search_finds_the_fastest_scale_shown_under_the_bound(plans, tmp_path):
    d = dist(plans[0])
    r = assess(plans[:1], d, 30, 3, tmp_path, max_bruise=0.15, scales=(0.5, 2.0), tolerance=0.05, workers=0,
               progress=False)
    s = r.search
    assert s.fastest is not None and s.too_fast is not None, s.note
    assert s.fastest.bruise.interval[1] <= 0.15 < s.too_fast.bruise.interval[1]
    assert s.too_fast.scale < s.fastest.scale <= s.too_fast.scale * 1.05
    assert s.fastest.duration == pytest.approx(s.fastest.scale * sum(
        m["duration"] for m in tomllib.loads(plans[0].read_text())["excitation"]["moves"]))
    assert "Fastest duration" in (tmp_path / "risk.md").read_text()


# --- a long run: progress, interruption, resume ------------------------------------------------------------

def test_an_interrupted_risk_run_keeps_its_finished_samples_and_resumes(plans, tmp_path):
    args = [sys.executable, "-m", "grapefmu", "risk", str(plans[0]), *(f"--range={r}" for r in RANGES),
            "--samples", "400", "--workers", "0", "--out", "run"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    p = subprocess.Popen(args, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    journal = tmp_path / "run" / "plan_fast.parquet.journal.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and p.poll() is None:
        if journal.exists() and len(journal.read_text().splitlines()) > 30:
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=20)
    assert p.returncode == 130, err[-2000:]
    assert "sweep [" in err  # progress was shown
    last = err.strip().splitlines()[-1]
    assert last.startswith("grapefmu risk: interrupted") and "run the same command again to resume" in last, last
    kept = [json.loads(line) for line in journal.read_text().splitlines()[1:]]
    assert 30 <= len(kept) < 400 and not (tmp_path / "run" / "plan_fast.parquet").exists()
    r = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert f"resuming, {len(kept)} of 400 runs already done" in r.stderr
    table = {row["run_id"]: row for row in pq.read_table(tmp_path / "run" / "plan_fast.parquet").to_pylist()}
    assert len(table) == 400 and not journal.exists()
    for row in kept:  # the kept samples were not run again: their rows, timings included, are the journal's
        assert table[row["run_id"]] == row
    # and the resumed table is the one an uninterrupted run gives (timings aside)
    whole = run_plan(plans[0], dist(plans[0]), 400, 1, tmp_path / "whole", workers=0, progress=False)
    strip = lambda rows: [{k: v for k, v in x.items() if k not in ("wall_time_s", "compile_time_s")}  # noqa: E731
                          for x in sorted(rows, key=lambda x: x["run_id"])]
    assert strip(table.values()) == strip(whole.rows)
    assert f"plan_fast: P(bruise) = {whole.bruise.text()}" in r.stdout


# --- bad plans and bad reports (found by an audit) --------------------------------------------------------------

def test_a_scale_whose_every_run_is_refused_writes_no_nan(plans, tmp_path):
    """At a time scale of 0.02 every run exceeds the solver's acceleration bound and is refused: P(bruise) is unknown,
    and risk.json held NaN (not JSON) and risk.md 'nan'. Now null and words, and the refusals are listed."""
    r = assess(plans[1:], dist(plans[1]), 6, 3, tmp_path, max_bruise=0.5, scales=(0.02, 4.0), tolerance=0.5,
               workers=0, progress=False)
    step = next(o for o in r.search.steps if o.scale == 0.02)
    assert step.bruise.n == 0 and len(step.failed) == 6
    text = (tmp_path / "risk.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    doc = json.loads(text)
    assert [s["bruise"]["p"] for s in doc["search"]["steps"] if s["scale"] == 0.02] == [None]
    md = (tmp_path / "risk.md").read_text()
    assert "nan" not in md and "unknown: no run finished (0/0)" in md and "0.02: 6 (the first:" in md


def test_a_plan_the_scene_validator_refuses_is_one_line_before_any_run(plans, tmp_path):
    """A plan with a negative mass ran: every run refused, P = nan written (exit 0)."""
    bad = tmp_path / "bad.toml"
    bad.write_text(plans[0].read_text().replace("mass = ", "mass = -", 1))
    r = subprocess.run([sys.executable, "-m", "grapefmu", "risk", str(plans[0]), str(bad), "--range",
                        "thresholds.bruise_force=1.7:4", "--samples", "3", "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "bad.toml: berries[0].mass" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


def test_a_range_beyond_what_the_plan_takes_is_refused_before_any_run(plans, tmp_path):
    """--range thresholds.bruise_force=1:1e5 ran: the draws above the scene's 1e4 N were refused and left out, the least
    likely to bruise, so P(bruise) came out biased high (found by an audit). Both ends are now checked against
    every plan."""
    with pytest.raises(grapefmu.GrapefmuError, match=r"--range thresholds.bruise_force=1:100000: plan .*plan_fast.toml "
                                                     r"refuses 100000 \(thresholds.bruise_force: expected a number in "
                                                     r"\(0, 10000\] N"):
        assess(plans, distribution(tomllib.loads(plans[0].read_text()), None, ["thresholds.bruise_force=1:1e5"]), 3,
               1, tmp_path / "out", workers=0, progress=False)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("change", [lambda d: d["covariance_u"][0].__setitem__(0, "x"),
                                    lambda d: d["covariance_u"][0].__setitem__(0, [1]),
                                    lambda d: d["parameters"][0].__setitem__("u", 1e300)])
def test_a_malformed_fit_report_is_refused_as_not_a_fit_report(tmp_path, change):
    """An entry of the covariance that is not a number raised a traceback; a u of 1e300 drew infinite values."""
    doc = json.loads((ROOT / "docs" / "fit_and_risk" / "fit.json").read_text())
    change(doc)
    (tmp_path / "fit.json").write_text(json.dumps(doc))
    with pytest.raises(grapefmu.GrapefmuError, match="not a fit report"):
        distribution(tomllib.loads((EXAMPLES / "plan_fast.toml").read_text()), tmp_path / "fit.json", [])
