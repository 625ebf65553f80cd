"""Write a run to CSV or Parquet (grapefmu.write.write_run picks the writer by file type). Every writer goes through a temporary file and a rename,
so an interrupted write never leaves a half-written file under the requested name."""
from __future__ import annotations

import contextlib
import functools
import glob
import hashlib
import json
import os
import re
import socket
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from ..errors import GrapefmuError
from ..scenefile import scene_toml
from .run import Run

#: a temporary file is `.{name}.{host}-{pid}.{random}.grapefmu-part` beside its target: recognisably ours, and
#: the next writer of the same target on the same host removes it once its writer's process is gone
PART_SUFFIX = ".grapefmu-part"
#: characters the temporary name adds to the target's (host tag, pid, random part, suffix)
PART_EXTRA = 48


@functools.cache
def _host_tag() -> str:
    return hashlib.blake2b(socket.gethostname().encode(), digest_size=3).hexdigest()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    except (OverflowError, ValueError):
        return False  # not a pid this system can have
    return True


def _part_prefix(path: Path) -> str:
    return f".{path.name}.{_host_tag()}-{os.getpid()}."


def remove_stale_parts(path: str | Path) -> list[Path]:
    """Remove the temporary files of `path` that a killed writer on this host left (its process is gone)."""
    path = Path(path)
    own = re.compile(re.escape(f".{path.name}.{_host_tag()}-") + r"(\d{1,10})\.[A-Za-z0-9_]+" + re.escape(PART_SUFFIX))
    removed = []
    for name in glob.glob(glob.escape(f".{path.name}.{_host_tag()}-") + "*" + PART_SUFFIX, root_dir=path.parent):
        m = own.fullmatch(name)
        if m and int(m[1]) != os.getpid() and not _alive(int(m[1])):
            with contextlib.suppress(OSError):
                (path.parent / name).unlink()
                removed.append(path.parent / name)
    return removed


def one_of(types: Iterable[str]) -> str:
    """(".a", ".b", ".c") as ".a, .b or .c"."""
    t = list(types)
    return t[0] if len(t) == 1 else f"{', '.join(t[:-1])} or {t[-1]}"


def check_target(path: str | Path, types: Iterable[str] | None, option: str) -> Path:
    """Refuse, before any work is done, an output that could not be written: an empty name, an unknown type
    (types: the suffixes the writer knows; None for a directory), a directory where a file is asked for or
    the reverse, a parent that is a file or not writable, a name too long for the file system.
    The GrapefmuError names `option`, the path and what is allowed."""
    text = os.fspath(path)
    kind = "a directory" if types is None else f"a file name ending in {one_of(types)}"
    bad_name = not text.strip() or "\0" in text
    where = f"{option} {text!r}" if bad_name else f"{option} {text}"
    if bad_name:
        raise GrapefmuError(f"{where}: expected {kind}")
    p = Path(text)
    if types is not None and p.suffix.lower() not in types:
        raise GrapefmuError(f"{where}: unknown file type {p.suffix or '(none)'}; expected {kind}")
    try:
        if types is not None and p.is_dir():
            raise GrapefmuError(f"{where}: is a directory; expected {kind}")
        if p.exists() and not (p.is_dir() if types is None else p.is_file()):
            raise GrapefmuError(f"{where}: exists and is not {'a directory' if types is None else 'a regular file'}")
        home = p if types is None else p.parent
        while not home.exists() and home != home.parent:  # directories that atomic_path will create
            home = home.parent
        if not home.is_dir():
            raise GrapefmuError(f"{where}: {home} is a file, not a directory")
        try:
            name_max = os.pathconf(home, "PC_NAME_MAX")
        except (OSError, ValueError):
            name_max = 255
        if types is not None and len(os.fsencode(p.name)) + PART_EXTRA > name_max:
            raise GrapefmuError(f"{where}: file name too long; at most {name_max - PART_EXTRA} bytes here")
        probe = None
        try:  # the one sure test (permissions, ACLs, read-only mounts, and root): make a temporary file there
            fd, probe = tempfile.mkstemp(prefix=_part_prefix(p), suffix=PART_SUFFIX, dir=home)
            os.close(fd)
        except OSError as e:
            raise GrapefmuError(f"{where}: cannot write in directory {home}: {e.strerror or e}") from None
        finally:  # however it ends: a signal between making and removing it left it behind
            _remove_own_parts(p, home, probe)
    except OSError as e:
        raise GrapefmuError(f"{where}: {e.strerror or e}") from None
    return p


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; move it into place only if the block succeeds. The temporary
    file is removed however the block ends (an exception, or SIGINT/SIGTERM, which the CLI turns into one);
    what a killed writer left behind is removed by the next writer of the same target (remove_stale_parts)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_parts(path)
    tmp = None
    try:
        try:
            fd, tmp = tempfile.mkstemp(prefix=_part_prefix(path), suffix=PART_SUFFIX, dir=path.parent)
        except OSError as e:
            raise GrapefmuError(f"{path}: cannot write in directory {path.parent}: {e.strerror or e}") from None
        os.close(fd)
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        _remove_own_parts(path, path.parent, tmp)


def _remove_own_parts(path: Path, home: Path, tmp: str | None) -> None:
    """Remove the temporary file tmp of `path` in `home`; without its name (a signal the moment mkstemp made it,
    before the name got back to the caller), every temporary file of this process for `path` there."""
    prefix = _part_prefix(path)
    for part in [Path(tmp)] if tmp is not None else home.glob(f"{glob.escape(prefix)}*{PART_SUFFIX}"):
        with contextlib.suppress(FileNotFoundError):
            part.unlink()


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
    meta = {"grapefmu.scene": scene_toml(run.scene), "grapefmu.summary": json.dumps(run.summary(), default=str)}
    table = pa.table({k: pa.array(v) for k, v in cols.items()}).replace_schema_metadata(meta)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
