"""A small TOML writer for scene documents (tables, arrays of tables, numbers, strings, bools, lists),
so that a scene built in code carries the same reproducible text as one read from a file."""
from __future__ import annotations

import json
import math
from typing import Any

from ..errors import GrapefmuError


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise GrapefmuError(f"cannot write {type(v).__name__} {v!r} to a scene TOML")


def dumps(doc: dict[str, Any]) -> str:
    lines = []
    tables = []
    for k, v in doc.items():
        if isinstance(v, dict):
            tables.append((k, v, False))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.append((k, v, True))
        else:
            lines.append(f"{k} = {_value(v)}")
    for k, v, many in tables:
        for item in (v if many else [v]):
            lines.append("")
            lines.append(f"[[{k}]]" if many else f"[{k}]")
            lines.extend(f"{kk} = {_value(vv)}" for kk, vv in item.items())
    return "\n".join(lines) + "\n"
