"""Sweeps: identical rows on any executor, resumable after an interruption, clear errors."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from grapefmu.cli import main
from grapefmu.errors import SceneError
from grapefmu.scenefile import scene_from_dict
from grapefmu.solver.api import simulate
from grapefmu.sweep import load_spec, run_sweep

SPEC = """scene = "row.toml"
mode = "{mode}"
samples = 5
seed = 3

[[parameters]]
key = "contact.stiffness"
{stiffness}

[[parameters]]
key = "berries[*].hinge_damping"
{damping}
"""
GRID = SPEC.format(mode="grid", stiffness="values = [1500.0, 3000.0]", damping="values = [1e-5, 4e-5, 1e-4]")
MC = SPEC.format(mode="monte-carlo", stiffness='distribution = "uniform"\nlow = 1000.0\nhigh = 4000.0',
                 damping='distribution = "choice"\nvalues = [1e-5, 1e-4]')


@pytest.fixture
def folder(tmp_path):
    assert main(["cluster", "--row", "--berries", "4", "-o", str(tmp_path / "row.toml")]) == 0
    text = (tmp_path / "row.toml").read_text().replace("t_end = 2.0", "t_end = 0.5")
    (tmp_path / "row.toml").write_text(text)
    (tmp_path / "grid.toml").write_text(GRID)
    (tmp_path / "mc.toml").write_text(MC)
    return tmp_path


def rows(path: Path) -> list[dict]:
    """The rows without their timings (which depend on the machine and on the worker that ran them)."""
    return [{k: v for k, v in r.items() if k not in ("wall_time_s", "compile_time_s")}
            for r in pq.read_table(path).to_pylist()]


def test_rows_do_not_depend_on_executor_or_worker_count(folder):
    from distributed import LocalCluster

    spec = load_spec(folder / "mc.toml")
    one = rows(run_sweep(spec, folder / "one.parquet", workers=1, progress=False))
    two = rows(run_sweep(spec, folder / "two.parquet", workers=2, progress=False))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        dask = rows(run_sweep(spec, folder / "dask.parquet", scheduler=cluster.scheduler_address, progress=False))
    assert len(one) == 5 and all(r["status"] == "ok" for r in one)
    assert one == two == dask
    assert len({r["contact.stiffness"] for r in one}) == 5  # the draws really differ
    assert any(r["collision_count"] > 0 for r in one)


def test_grid_covers_every_combination_and_resumes_without_redoing_runs(folder):
    spec = load_spec(folder / "grid.toml")
    out = folder / "grid.parquet"
    full = rows(run_sweep(spec, out, workers=2, progress=False))
    assert [(r["contact.stiffness"], r["berries[*].hinge_damping"]) for r in full] == \
        [(k, c) for k in (1500.0, 3000.0) for c in (1e-5, 4e-5, 1e-4)]
    # an interrupted sweep: three rows journalled (marked, to see they are not redone), a torn fourth line
    out.unlink()
    journal = out.with_name(out.name + ".journal.jsonl")
    kept = [dict(full[k], steps=-1, wall_time_s=0.0, compile_time_s=0.0) for k in (0, 2, 5)]
    journal.write_text(json.dumps({"fingerprint": spec.fingerprint}) + "\n"
                       + "".join(json.dumps(r) + "\n" for r in kept) + '{"run_id": 1, "sta')
    resumed = rows(run_sweep(spec, out, workers=2, progress=False))
    assert [r["steps"] for r in resumed if r["run_id"] in (0, 2, 5)] == [-1, -1, -1]
    assert [r for r in resumed if r["run_id"] not in (0, 2, 5)] == [r for r in full if r["run_id"] not in (0, 2, 5)]
    assert not journal.exists()
    # a finished output of the same spec is not run again; a journal of another spec is refused
    assert rows(run_sweep(spec, out, progress=False)) == resumed
    journal.write_text(json.dumps({"fingerprint": "other"}) + "\n")
    out.unlink()
    with pytest.raises(Exception, match="different sweep spec"):
        run_sweep(spec, out, progress=False)


def test_a_run_the_validator_refuses_becomes_an_error_row(folder):
    (folder / "bad.toml").write_text(GRID.replace("[1500.0, 3000.0]", "[1500.0, -1.0]"))
    table = rows(run_sweep(load_spec(folder / "bad.toml"), folder / "bad.parquet", workers=1, progress=False))
    bad = [r for r in table if r["contact.stiffness"] == -1.0]
    assert len(bad) == 3 and all(r["status"].startswith("error: contact.stiffness") for r in bad)
    assert all(r["status"] == "ok" for r in table if r["contact.stiffness"] == 1500.0)


def test_a_key_whose_values_mix_kinds_is_written_as_their_json_text(folder):
    """[false, "auto"] for solver.islands is a legal sweep: both runs finished and then the Parquet writer refused the
    column (a traceback, and the same crash again on every resume)."""
    row = folder / "row.toml"
    row.write_text(row.read_text().replace("[solver]\n", '[solver]\nislands = "auto"\n'))
    (folder / "mixed.toml").write_text('scene = "row.toml"\nmode = "grid"\n\n[[parameters]]\nkey = "solver.islands"\n'
                                       'values = [false, "auto"]\n\n[[parameters]]\nkey = "contact.stiffness"\n'
                                       'values = [1500, 3000.5]\n')
    table = rows(run_sweep(load_spec(folder / "mixed.toml"), folder / "mixed.parquet", workers=1, progress=False))
    assert [(r["solver.islands"], r["contact.stiffness"]) for r in table] == \
        [("false", 1500.0), ("false", 3000.5), ('"auto"', 1500.0), ('"auto"', 3000.5)]
    assert all(r["status"] == "ok" for r in table)


def test_each_row_carries_the_warnings_of_its_run(folder):
    """A row whose results cannot be trusted says so: the same lines its run's summary gives (results/trust.py), and
    none for a row that can be. Before, the sweep dropped them, and a row with a step too long for the contact looked
    like any other."""
    row = folder / "row.toml"
    row.write_text(row.read_text().replace("[solver]\n", '[solver]\nmethod = "event"\nfixed_step = 0.0\n'))
    (folder / "steps.toml").write_text('scene = "row.toml"\nmode = "grid"\n\n[[parameters]]\nkey = "solver.method"\n'
                                       'values = ["paper"]\n\n[[parameters]]\nkey = "solver.fixed_step"\n'
                                       'values = [1e-5, 2e-3]\n')
    spec = load_spec(folder / "steps.toml")
    table = rows(run_sweep(spec, folder / "steps.parquet", workers=0, progress=False))
    fine, coarse = table
    assert fine["status"] == coarse["status"] == "ok" and fine["warnings"] == []
    doc = tomllib.loads((folder / "row.toml").read_text())
    doc["solver"].update(method="paper", fixed_step=2e-3)
    alone = simulate(scene_from_dict(doc, folder))  # the same run, outside the sweep
    assert coarse["warnings"] == alone.summary()["warnings"]
    assert any(w.startswith("fixed step 0.002 s is too long") for w in coarse["warnings"])


@pytest.mark.parametrize("change, field", [
    (("contact.stiffness", "contact.stifness"), "parameters[0].key"),
    (('mode = "grid"', 'mode = "latin"'), "mode"),
    (("values = [1500.0, 3000.0]", "values = []"), "parameters[0].values"),
    (("samples = 5", "samples = -5"), "samples"),  # a grid ignores it, and took -5
    (("values = [1500.0, 3000.0]", 'distribution = "grid"\nvalues = [1500.0, 3000.0]'),
     "parameters[0].distribution"),  # a grid has no distribution, and took "grid"
    (('key = "contact.stiffness"', 'key = "berries[0].hinge_damping"'), "parameters"),  # and berries[*]: one value
    # keys a mode or distribution does not read were silently ignored (found by an audit)
    (("values = [1500.0, 3000.0]", "values = [1500.0, 3000.0]\nlow = 1.0"), "parameters[0].low"),
])
def test_bad_spec_names_the_field(folder, change, field):
    (folder / "bad.toml").write_text(GRID.replace(*change))
    with pytest.raises(SceneError) as e:
        load_spec(folder / "bad.toml")
    assert e.value.key == field


@pytest.mark.parametrize("change, field, words", [
    (("low = 1000.0", "low = 1000.0\nmean = 2000.0"), "parameters[0].mean", "distribution 'uniform' does not read it"),
    (('distribution = "uniform"', 'shared = true\ndistribution = "uniform"'), "parameters[0].shared",
     "has none"),
])
def test_a_monte_carlo_key_its_distribution_does_not_read_is_refused(folder, change, field, words):
    (folder / "bad.toml").write_text(MC.replace(*change))
    with pytest.raises(SceneError, match=words) as e:
        load_spec(folder / "bad.toml")
    assert e.value.key == field


def test_a_base_scene_every_run_would_refuse_is_refused_before_any_run(folder, capsys):
    """A typo in the base scene made every run a row saying so, and the command exited 0. Refused up front when the
    first, middle and last run are refused alike on a key no parameter sets; an error on a swept key is left to the
    runs (another value may be fine)."""
    row = (folder / "row.toml").read_text()
    (folder / "row.toml").write_text(row.replace("gravity =", "gravty = 9.81\ngravity ="))
    with pytest.raises(SceneError, match="unknown key.*in the base scene row.toml, which no parameter changes") as e:
        load_spec(folder / "grid.toml")
    assert e.value.key == "gravty"
    # every run refused alike, but on the key a parameter sweeps: left to the runs (the sweep's own rows say so)
    (folder / "row.toml").write_text(row)
    (folder / "bad.toml").write_text(SPEC.format(mode="grid", stiffness="values = [-1.0]",
                                                 damping="values = [1e-5, 4e-5, 1e-4]"))
    spec = load_spec(folder / "bad.toml")
    from grapefmu.sweep.spec import scene_doc
    for run in (spec.runs()[0], spec.runs()[-1]):
        with pytest.raises(SceneError) as e:
            scene_from_dict(scene_doc(spec, run), spec.base_dir)
        assert e.value.key == "contact.stiffness"


def test_a_run_that_fails_in_an_unexpected_way_is_a_row_and_no_run_finished_is_a_failure(folder, capsys):
    """A run raising something other than grapefmu's errors (a NUL in a file name: ValueError) ended the sweep with
    a traceback, and every resume crashed again. It is now its run's row, the file name is refused by the scene's
    own check, and a sweep with no run finished exits 1 (it exited 0)."""
    (folder / "nul.toml").write_text('scene = "row.toml"\nmode = "grid"\n\n[[parameters]]\nkey = "contact.stiffness"'
                                     '\nvalues = [-1.0, -2.0]\n')
    assert main(["sweep", str(folder / "nul.toml"), "-o", str(folder / "nul.parquet"), "--workers", "1"]) == 1
    table = pq.read_table(folder / "nul.parquet").to_pylist()
    assert [r["status"].split(":")[0] for r in table] == ["error", "error"]
    assert "no run finished (2 refused or failed" in capsys.readouterr().err
    from grapefmu.sweep.worker import run_one
    doc = tomllib.loads((folder / "row.toml").read_text())
    doc["excitation"] = {"kind": "csv", "file": "bad\x00name.csv"}
    row = run_one(0, doc, str(folder))
    assert row["status"].startswith("error: excitation.file: ") and "NUL" in row["status"], row["status"]
