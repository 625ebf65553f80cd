"""Full ros2msg definitions (with dependencies) read from the installed interface packages, as MCAP's
ros2msg schema encoding and rosbag2 expect them."""
from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
              "int64", "uint64", "string", "wstring"}
SEP = "=" * 80


def share_dirs() -> list[Path]:
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    return [Path(p) / "share" for p in prefixes]


@lru_cache(maxsize=None)
def msg_text(datatype: str) -> str:
    """The .msg text of pkg/msg/Type (or pkg/Type)."""
    pkg, _, name = datatype.replace("/msg/", "/").partition("/")
    for d in share_dirs():
        f = d / pkg / "msg" / f"{name}.msg"
        if f.exists():
            return f.read_text()
    raise FileNotFoundError(f"no message definition for {datatype} under {', '.join(map(str, share_dirs()))}")


def _dependencies(datatype: str) -> list[str]:
    pkg = datatype.replace("/msg/", "/").split("/")[0]
    deps = []
    for line in msg_text(datatype).splitlines():
        parts = line.split("#", 1)[0].split()
        if len(parts) < 2 or "=" in " ".join(parts[1:]):
            continue  # blank, comment or constant
        base = parts[0].split("[")[0].split("<=")[0]
        if base in PRIMITIVES:
            continue
        deps.append(base if "/" in base else f"{pkg}/{base}")
    return deps


@lru_cache(maxsize=None)
def full_definition(datatype: str) -> str:
    """The message's text followed by every nested type's, each under `MSG: pkg/Type`."""
    seen, order = set(), []

    def visit(t):
        for d in _dependencies(t):
            key = d.replace("/msg/", "/")
            if key not in seen:
                seen.add(key)
                order.append(key)
                visit(key)
    visit(datatype)
    parts = [msg_text(datatype).rstrip("\n")]
    parts += [f"{SEP}\nMSG: {d}\n{msg_text(d).rstrip(chr(10))}" for d in order]
    return "\n".join(parts) + "\n"
