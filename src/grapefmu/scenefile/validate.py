"""Small checks that turn a bad value into a SceneError naming the key and the allowed range."""
from __future__ import annotations

import math
import re
import reprlib
from typing import Any

from ..errors import SceneError
from ..model.bounds import Bound

_SHOW = reprlib.Repr()
_SHOW.maxlevel, _SHOW.maxlist, _SHOW.maxdict, _SHOW.maxstring, _SHOW.maxlong, _SHOW.maxother = 3, 6, 6, 60, 30, 60


def show(value: Any) -> str:
    """A value as it goes into an error message: short and one line, however long or deep the value is."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 100:
        return f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    return _SHOW.repr(value).replace("\n", "\\n")


def number(key: str, value: Any, lo: float, hi: float, *, lo_open: bool = False,
           hi_open: bool = False, unit: str = "") -> float:
    """Return `value` as a float if it is a finite number inside the range, else raise."""
    return within(key, value, Bound(lo, hi, lo_open, hi_open, unit))


def within(key: str, value: Any, b: Bound) -> float:
    """Return `value` as a float if it is a finite number inside the bound b (a model field's: model/bounds.py),
    else raise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(key, f"expected {b.allowed}, got {type(value).__name__} {show(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise SceneError(key, f"expected {b.allowed}, got {show(value)}") from None
    if not b.holds(x):
        raise SceneError(key, f"expected {b.allowed}, got {show(value)}")
    return x


def integer(key: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(key, f"expected an integer in [{lo}, {hi}], got {show(value)}")
    if not lo <= value <= hi:
        raise SceneError(key, f"expected an integer in [{lo}, {hi}], got {show(value)}")
    return value


def choice(key: str, value: Any, allowed: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in allowed:
        raise SceneError(key, f"expected one of {', '.join(repr(a) for a in allowed)}, got {show(value)}")
    return value


def boolean(key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise SceneError(key, f"expected true or false, got {show(value)}")
    return value


def table(key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise SceneError(key, f"expected a table, got {type(value).__name__}")
    return value


def no_unknown_keys(key: str, tbl: dict, known: set[str]) -> None:
    unknown = sorted(set(tbl) - known)
    if unknown:
        where = f"{key}." if key else ""
        name = unknown[0] if re.fullmatch(r"[A-Za-z0-9_-]{1,64}", unknown[0]) else show(unknown[0])
        raise SceneError(f"{where}{name}", f"unknown key; allowed keys here: {', '.join(sorted(known))}")


def linear(key: str, value: Any, b: Bound) -> tuple[float, float, float]:
    """A linear vector [x, y, z], or the planar pair [x, z] (y = 0)."""
    if not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
        raise SceneError(key, f"expected [x, y, z] (or the planar [x, z]) of {b.allowed}, got {show(value)}")
    v = tuple(within(f"{key}[{k}]", x, b) for k, x in enumerate(value))
    return (v[0], 0.0, v[1]) if len(v) == 2 else v


def vector(key: str, value: Any, size: int, b: Bound) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise SceneError(key, f"expected a list of {size} of {b.allowed}, got {show(value)}")
    return tuple(within(f"{key}[{k}]", x, b) for k, x in enumerate(value))
