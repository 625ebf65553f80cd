"""Write a run to CSV or Parquet (grapefmu.write.write_run picks the writer by file type). Every writer goes through a temporary file and a rename,
so an interrupted write never leaves a half-written file under the requested name."""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .run import Run


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; move it into place only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


def write_csv(run: Run, path: str | Path) -> None:
    """time, then every output channel (docs/outputs.md; per pair only the pairs that touched)."""
    cols = run.columns()
    names = list(cols)
    data = np.column_stack([cols[k] for k in names])
    with atomic_path(path) as tmp:
        np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt="%.12g")


def write_parquet(run: Run, path: str | Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = run.columns()
    meta = {"grapefmu.scene": run.scene.source, "grapefmu.summary": json.dumps(run.summary(), default=str)}
    table = pa.table({k: pa.array(v) for k, v in cols.items()}).replace_schema_metadata(meta)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
