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


def refuse_function(resources, identifier: str):
    """grapefmu_refuse(status, message) of this FMU's own binary (shim.c): logs the message through the host
    and makes the current FMI call return that status. The binary is looked up in the process at each call
    and released again: holding it open would keep it loaded after the host unloads the FMU, and pythonfmu's
    binary behind it must start afresh when the host loads the FMU again."""
    libs = sorted((Path(resources).parent / "binaries").glob(f"*/{identifier}.so"))

    def refuse(status: int, message: bytes) -> None:
        for lib in libs:
            try:
                binary = ctypes.CDLL(str(lib), mode=os.RTLD_NOLOAD | os.RTLD_NOW)
            except OSError:
                continue  # not the one this process loaded
            try:
                binary.grapefmu_refuse.argtypes = [ctypes.c_int, ctypes.c_char_p]
                binary.grapefmu_refuse(status, message)
                return
            except AttributeError:
                pass
            finally:
                _ctypes.dlclose(binary._handle)
        stderr_refuse(status, message)

    return refuse


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
