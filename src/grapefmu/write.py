"""`write_run(run, path)`: a run to CSV, Parquet or MCAP, chosen by the file's type."""
from __future__ import annotations

from pathlib import Path

from .errors import GrapefmuError
from .results.run import Run


def write_run(run: Run, path: str | Path) -> None:
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        from .results.writers import write_csv
        write_csv(run, path)
    elif suffix == ".parquet":
        from .results.writers import write_parquet
        write_parquet(run, path)
    elif suffix == ".mcap":
        from .recording.mcap_writer import write_mcap
        write_mcap(run, path)
    else:
        raise GrapefmuError(f"{path}: unknown file type {suffix!r}; use .csv, .parquet or .mcap")
