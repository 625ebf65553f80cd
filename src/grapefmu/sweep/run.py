"""Run a sweep on an executor, journal each finished row, and write the Parquet table at the end.

Rows are appended to `<output>.journal.jsonl` (flushed and fsynced per row) as runs finish. An
interrupted sweep started again with the same spec and output skips the runs already in the
journal; the Parquet file is written atomically, sorted by run_id, only when every run is done.
`workers=0` runs every run in the calling process (no process to start: small sweeps, tests, a caller that
runs many short sweeps one after another, as risk/ does).
"""
from __future__ import annotations

import itertools
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


#: how long a Dask scheduler has to answer before the sweep is refused (Dask's own default waits 30 s)
SCHEDULER_TIMEOUT_S = 5.0


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
    client = _connect(scheduler) if scheduler else None  # an unreachable scheduler: refused before any file is written
    try:
        where = (f"Dask scheduler {scheduler}" if scheduler else "this process" if workers == 0
                 else f"{workers or os.cpu_count()} local processes")
        _say(progress, f"sweep: {len(runs)} runs ({spec.mode}) of {spec.base.get('name', 'scene')} on {where}")
        if done:
            _say(progress, f"sweep: resuming, {len(done)} of {len(runs)} runs already done")
        if progress and not scheduler:
            from ..solver.warmup import notice
            notice()  # the workers compile (or load) the core before their first run
        # (re)write the journal with only complete rows, so a line torn by a kill is not appended to
        journal.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(journal) as tmp, open(tmp, "w") as fh:
            fh.write(json.dumps({"fingerprint": spec.fingerprint}) + "\n")
            fh.writelines(json.dumps(done[k]) + "\n" for k in sorted(done))
        bar = _Bar(len(runs), len(done), progress)
        try:
            with open(journal, "a") as fh:
                for row in _execute(spec, runs, todo, workers, client):
                    row = {"run_id": row["run_id"], **runs[row["run_id"]], **{c: row[c] for c in RESULT_COLUMNS}}
                    fh.write(json.dumps(row) + "\n")
                    fh.flush()
                    os.fsync(fh.fileno())
                    done[row["run_id"]] = row
                    bar.update(row["status"] != "ok")
        except BaseException:
            bar.close()
            if not done:  # nothing finished: no journal to resume from
                journal.unlink(missing_ok=True)
            raise
    finally:
        if client is not None:
            client.close()
    _write_parquet([done[k] for k in range(len(runs))], spec, output)
    journal.unlink()
    return output


def _connect(scheduler: str):
    """A Dask client of the scheduler, or one line saying why not within SCHEDULER_TIMEOUT_S."""
    try:
        from distributed import Client
    except ImportError as e:
        raise GrapefmuError(f"--scheduler: a Dask scheduler needs Dask distributed (pip install 'grapefmu[dask]'): "
                            f"{e}") from None
    try:
        return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError, TypeError) as e:
        raise GrapefmuError(f"--scheduler {scheduler}: no Dask scheduler answered within {SCHEDULER_TIMEOUT_S:g} s "
                            f"({' '.join(str(e).split()) or type(e).__name__}); nothing was run") from None


def _quiet_worker() -> None:
    """A local worker leaves SIGINT (a terminal's Ctrl-C reaches the whole process group) to the driver, which
    stops it: no traceback from every worker."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _execute(spec: SweepSpec, runs: list[dict], todo: list[int], workers: int | None,
             client) -> Iterator[dict[str, Any]]:
    base_dir = str(spec.base_dir)
    if client is not None:
        from distributed import wait
        submit = lambda k: client.submit(run_one, k, scene_doc(spec, runs[k]), base_dir,  # noqa: E731
                                         key=f"grapefmu-run-{spec.fingerprint}-{k}", pure=False)
        window = 4 * max(sum(client.nthreads().values()), 1)
        yield from _windowed(submit, todo, window, lambda fs: wait(fs, return_when="FIRST_COMPLETED"))
        return
    if workers == 0:
        yield from (run_one(k, scene_doc(spec, runs[k]), base_dir) for k in todo)
        return
    yield from _local(spec, runs, todo, workers or os.cpu_count() or 1, base_dir)


def _local(spec: SweepSpec, runs: list[dict], todo: list[int], n: int, base_dir: str) -> Iterator[dict[str, Any]]:
    """Local worker processes (spawned), at most 4 n runs in flight; an interruption or a failure terminates
    the workers at once instead of waiting for the runs they are in."""
    import multiprocessing as mp
    import queue

    finished: queue.SimpleQueue = queue.SimpleQueue()
    pool = mp.get_context("spawn").Pool(n, initializer=_quiet_worker)
    try:
        def submit(k: int) -> None:
            pool.apply_async(run_one, (k, scene_doc(spec, runs[k]), base_dir), callback=finished.put,
                             error_callback=finished.put)

        pending = iter(todo)
        in_flight = 0
        for k in itertools.islice(pending, 4 * n):
            submit(k)
            in_flight += 1
        while in_flight:
            try:
                row = finished.get(timeout=0.2)  # a short wait: SIGINT is handled between waits
            except queue.Empty:
                continue
            in_flight -= 1
            if isinstance(row, BaseException):
                raise row
            yield row
            k = next(pending, None)
            if k is not None:
                submit(k)
                in_flight += 1
        pool.close()
        pool.join()
    finally:
        pool.terminate()  # a no-op once closed and joined


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
    records = [{c: r.get(c) for c in cols} for r in rows]
    for key in keys:  # one Arrow type per column: a key whose values mix kinds is written as their JSON text
        kinds = {_kind(r[key]) for r in records if r[key] is not None}
        if kinds == {"int", "float"}:
            for r in records:
                r[key] = None if r[key] is None else float(r[key])
        elif len(kinds) > 1:
            for r in records:
                r[key] = None if r[key] is None else json.dumps(r[key])
    table = pa.Table.from_pylist(records)
    table = table.replace_schema_metadata({"grapefmu_sweep_fingerprint": spec.fingerprint,
                                           "grapefmu_sweep_spec": spec.text})
    with atomic_path(output) as tmp:
        pq.write_table(table, tmp)


def _kind(x) -> str:
    """A value's kind for its Parquet column (a bool is not an int here)."""
    return "bool" if isinstance(x, bool) else type(x).__name__


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
        self.open = self.done < self.total
        if not self.open:
            sys.stderr.write("\n")
        sys.stderr.flush()

    def close(self) -> None:
        """End a bar left without its newline (an interruption): the message that follows gets its own line."""
        if getattr(self, "open", False):
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.open = False


