"""Run a sweep on an executor, journal each finished row, and write the Parquet table at the end.

Rows are appended to `<output>.journal.jsonl` (flushed and fsynced per row) as runs finish. An
interrupted sweep started again with the same spec and output skips the runs already in the
journal; the Parquet file is written atomically, sorted by run_id, only when every run is done.
"""
from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import GrapefmuError
from ..results.writers import atomic_path
from .spec import SweepSpec, scene_doc
from .worker import RESULT_COLUMNS, run_one


def run_sweep(spec: SweepSpec, output: str | Path, *, workers: int | None = None, scheduler: str | None = None,
              progress: bool = True) -> Path:
    output = Path(output)
    journal = output.with_name(output.name + ".journal.jsonl")
    runs = spec.runs()
    if output.exists() and _fingerprint_of(output) == spec.fingerprint:
        _say(progress, f"sweep: {output} already holds all {len(runs)} runs of this spec")
        return output
    done = _read_journal(journal, spec.fingerprint)
    todo = [k for k in range(len(runs)) if k not in done]
    where = f"Dask scheduler {scheduler}" if scheduler else f"{workers or os.cpu_count()} local processes"
    _say(progress, f"sweep: {len(runs)} runs ({spec.mode}) of {spec.base.get('name', 'scene')} on {where}")
    if done:
        _say(progress, f"sweep: resuming, {len(done)} of {len(runs)} runs already done")
    # (re)write the journal with only complete rows, so a line torn by a kill is not appended to
    journal.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(journal) as tmp, open(tmp, "w") as fh:
        fh.write(json.dumps({"fingerprint": spec.fingerprint}) + "\n")
        fh.writelines(json.dumps(done[k]) + "\n" for k in sorted(done))
    bar = _Bar(len(runs), len(done), progress)
    with open(journal, "a") as fh:
        for row in _execute(spec, runs, todo, workers, scheduler):
            row = {"run_id": row["run_id"], **runs[row["run_id"]], **{c: row[c] for c in RESULT_COLUMNS}}
            fh.write(json.dumps(row) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
            done[row["run_id"]] = row
            bar.update(row["status"] != "ok")
    _write_parquet([done[k] for k in range(len(runs))], spec, output)
    journal.unlink()
    return output


def _execute(spec: SweepSpec, runs: list[dict], todo: list[int], workers: int | None,
             scheduler: str | None) -> Iterator[dict[str, Any]]:
    base_dir = str(spec.base_dir)
    if scheduler:
        try:
            from distributed import Client, wait
        except ImportError as e:
            raise GrapefmuError(f"scheduler: a Dask scheduler needs Dask distributed (pip install 'grapefmu[dask]'): {e}") from None
        with Client(scheduler) as client:
            submit = lambda k: client.submit(run_one, k, scene_doc(spec, runs[k]), base_dir,  # noqa: E731
                                             key=f"grapefmu-run-{spec.fingerprint}-{k}", pure=False)
            window = 4 * max(sum(client.nthreads().values()), 1)
            yield from _windowed(submit, todo, window, lambda fs: wait(fs, return_when="FIRST_COMPLETED"))
        return
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor
    from concurrent.futures import wait as wait_local

    n = workers or os.cpu_count() or 1
    with ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("spawn")) as pool:
        submit = lambda k: pool.submit(run_one, k, scene_doc(spec, runs[k]), base_dir)  # noqa: E731
        yield from _windowed(submit, todo, 4 * n, lambda fs: wait_local(fs, return_when=FIRST_COMPLETED))


def _windowed(submit, todo: list[int], window: int, wait_first) -> Iterator[dict[str, Any]]:
    """Keep at most `window` runs in flight: a sweep of a million runs never holds a million scene
    documents at once, and an interruption leaves little work to cancel."""
    queue = iter(todo)
    pending = {submit(k) for _, k in zip(range(window), queue)}
    try:
        while pending:
            done, pending = wait_first(pending)
            pending = set(pending)
            for fut in done:
                yield fut.result()
                k = next(queue, None)
                if k is not None:
                    pending.add(submit(k))
    finally:
        for fut in pending:
            fut.cancel()


def _read_journal(journal: Path, fingerprint: str) -> dict[int, dict]:
    """Finished rows of an interrupted run; a torn last line (killed mid-write) is simply redone."""
    if not journal.exists():
        return {}
    lines = journal.read_text().splitlines()
    try:
        head = json.loads(lines[0]) if lines else {}
    except json.JSONDecodeError:
        head = {}
    if head.get("fingerprint") != fingerprint:
        raise GrapefmuError(f"{journal} belongs to a different sweep spec or scene; delete it or choose another output")
    done = {}
    for line in lines[1:]:
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        done[row["run_id"]] = row
    return done


def _write_parquet(rows: list[dict], spec: SweepSpec, output: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    keys = [p.key for p in spec.parameters]
    cols = ["run_id", *keys, *RESULT_COLUMNS]
    table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
    table = table.replace_schema_metadata({"grapefmu_sweep_fingerprint": spec.fingerprint,
                                           "grapefmu_sweep_spec": spec.text})
    with atomic_path(output) as tmp:
        pq.write_table(table, tmp)


def _fingerprint_of(path: Path) -> str | None:
    import pyarrow.parquet as pq
    try:
        meta = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001  (not a Parquet file we wrote: it will be replaced atomically)
        return None
    return meta.get(b"grapefmu_sweep_fingerprint", b"").decode() or None


def _say(on: bool, text: str) -> None:
    if on:
        print(text, file=sys.stderr)


class _Bar:
    def __init__(self, total: int, done: int, on: bool):
        self.total, self.done, self.failed, self.on = total, done, 0, on
        self.start, self.start_done = time.perf_counter(), done

    def update(self, failed: bool) -> None:
        self.done += 1
        self.failed += failed
        if not self.on:
            return
        wall = time.perf_counter() - self.start
        rate = (self.done - self.start_done) / wall if wall > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        bar = "#" * int(30 * self.done / self.total)
        sys.stderr.write(f"\rsweep [{bar:<30}] {self.done}/{self.total} runs, {self.failed} failed, "
                         f"{wall:.0f} s, eta {eta:.0f} s ")
        if self.done == self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


