"""Small checks that turn a bad value into a SceneError naming the key and the allowed range."""
from __future__ import annotations

import math
from typing import Any

from ..errors import SceneError


def number(key: str, value: Any, lo: float, hi: float, *, lo_open: bool = False,
           hi_open: bool = False, unit: str = "") -> float:
    """Return `value` as a float if it is a finite number inside the range, else raise."""
    lb = "(" if lo_open else "["
    rb = ")" if hi_open else "]"
    allowed = f"a number in {lb}{lo:g}, {hi:g}{rb}{(' ' + unit) if unit else ''}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(key, f"expected {allowed}, got {type(value).__name__} {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise SceneError(key, f"expected {allowed}, got {value!r}")
    if x < lo or x > hi or (lo_open and x == lo) or (hi_open and x == hi):
        raise SceneError(key, f"expected {allowed}, got {value!r}")
    return x


def integer(key: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(key, f"expected an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= value <= hi:
        raise SceneError(key, f"expected an integer in [{lo}, {hi}], got {value!r}")
    return value


def choice(key: str, value: Any, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise SceneError(key, f"expected one of {', '.join(repr(a) for a in allowed)}, got {value!r}")
    return value


def boolean(key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise SceneError(key, f"expected true or false, got {value!r}")
    return value


def table(key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise SceneError(key, f"expected a table, got {type(value).__name__}")
    return value


def no_unknown_keys(key: str, tbl: dict, known: set[str]) -> None:
    unknown = sorted(set(tbl) - known)
    if unknown:
        where = f"{key}." if key else ""
        raise SceneError(f"{where}{unknown[0]}", f"unknown key; allowed keys here: {', '.join(sorted(known))}")


def vector2(key: str, value: Any, lo: float, hi: float, unit: str = "") -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError(key, f"expected a pair [x, y] of numbers in [{lo:g}, {hi:g}] {unit}, got {value!r}")
    return (number(f"{key}[0]", value[0], lo, hi, unit=unit), number(f"{key}[1]", value[1], lo, hi, unit=unit))


def vector(key: str, value: Any, size: int, lo: float, hi: float, unit: str = "") -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise SceneError(key, f"expected a list of {size} numbers in [{lo:g}, {hi:g}] {unit}, got {value!r}")
    return tuple(number(f"{key}[{k}]", x, lo, hi, unit=unit) for k, x in enumerate(value))
