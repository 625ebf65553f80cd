"""`write_run(run, path)`: a run to CSV, Parquet or MCAP, chosen by the file's type."""
from __future__ import annotations

import importlib
from pathlib import Path

from .results.run import Run
from .results.writers import check_target

#: every file type write_run writes, with the module and function that write it (imported on use)
WRITERS = {
    ".csv": ("grapefmu.results.writers", "write_csv"),
    ".parquet": ("grapefmu.results.writers", "write_parquet"),
    ".mcap": ("grapefmu.recording.mcap_writer", "write_mcap"),
}


def check_output(path: str | Path, option: str = "output") -> Path:
    """Refuse, before the run, a path write_run could not write (unknown type, a directory, not writable)."""
    return check_target(path, WRITERS, option)


def write_run(run: Run, path: str | Path) -> None:
    module, name = WRITERS[check_output(path).suffix.lower()]
    getattr(importlib.import_module(module), name)(run, path)
