"""How the Python side of the FMU reports to the host (standard library only: it runs before the FMU's
requirements are known to be there)."""
from __future__ import annotations

import _ctypes
import ctypes
import importlib.util
import os
import re
import sys
from pathlib import Path

REQUIREMENTS = "requirements.txt"  # in the resources


def stderr_refuse(status: int, message: bytes) -> None:
    sys.stderr.write(f"grapefmu FMU: {message.decode()}\n")


def binaries(resources, identifier: str) -> list[Path]:
    """This FMU's binaries (one per platform) in the extraction whose resources are `resources`."""
    return sorted((Path(resources).parent / "binaries").glob(f"*/{identifier}.so"))


def in_call(libs, name: str, argtypes: list, restype, *args):
    """Call `name` (shim.c) in the one binary of `libs` that is forwarding an FMI call on this thread (grapefmu_in_call):
    (True, its result), or (False, None) when none is (a call from outside an FMI call, or pythonfmu's binary alone).
    The same FMU extracted twice in one process is two binaries, and its Python module and classes are shared by
    both (pythonfmu imports the slave module once): only the binary in the call can make the call's status.
    Each binary is looked up in the process and released again: holding it open would keep it loaded after the
    host unloads the FMU, and pythonfmu's binary behind it must start afresh when the host loads the FMU again."""
    for lib in libs:
        try:
            binary = ctypes.CDLL(str(lib), mode=os.RTLD_NOLOAD | os.RTLD_NOW)
        except OSError:
            continue  # not loaded in this process
        try:
            if not binary.grapefmu_in_call():
                continue
            f = getattr(binary, name)
            f.argtypes, f.restype = argtypes, restype
            return True, f(*args)
        except AttributeError:
            continue
        finally:
            _ctypes.dlclose(binary._handle)
    return False, None


def refuse(libs, status: int, message: bytes) -> None:
    """grapefmu_refuse(status, message) of the binary in the call: logs the message through the host and makes the
    current FMI call return that status (or worse); on stderr when no binary is in a call."""
    if not in_call(libs, "grapefmu_refuse", [ctypes.c_int, ctypes.c_char_p], None, status, message)[0]:
        stderr_refuse(status, message)


def missing_requirements(resources) -> str | None:
    """What this Python lacks of the FMU's requirements, as a message saying how to install them, or None."""
    path = os.path.join(resources, REQUIREMENTS)
    with open(path, encoding="utf-8") as f:
        names = [re.split(r"[ <>=!~;\[]", line.strip(), maxsplit=1)[0] for line in f if line.strip()]
    missing = [n for n in names if importlib.util.find_spec(n) is None]
    if not missing:
        return None
    return (f"this Python ({sys.executable}) lacks {', '.join(missing)}, which the FMU needs; install its "
            f"requirements: {sys.executable} -m pip install -r {path}")
