"""The range of every number a scene holds, declared once beside its field and read by the scene-file parser and by
the model's own check alike: a scene built in code (`dataclasses.replace`) meets the ranges a scene file meets."""
from __future__ import annotations

import math
from numbers import Real
from dataclasses import MISSING, field, fields
from typing import Any, NamedTuple


class Bound(NamedTuple):
    """[lo, hi] (an end excluded where open) in `unit`; a number outside it, or not finite, is refused."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""

    @property
    def allowed(self) -> str:
        """The range as an error message states it: 'a number in (0, 10] kg'."""
        return (f"a number in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
                f"{(' ' + self.unit) if self.unit else ''}")

    def holds(self, x: float) -> bool:
        return math.isfinite(x) and (self.lo < x if self.lo_open else self.lo <= x) and \
            (x < self.hi if self.hi_open else x <= self.hi)


def bounded(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False, unit: str = "",
            default: Any = MISSING) -> Any:
    """A dataclass field whose value (each element of a tuple value) must lie in Bound(lo, hi, ...)."""
    return field(default=default, metadata={"bound": Bound(lo, hi, lo_open, hi_open, unit)})


def bound(cls: type, name: str) -> Bound:
    """The Bound declared on the field `name` of the dataclass `cls`."""
    return _bounds(cls)[name][0]


def refusal(obj: Any, key: str, positive: tuple[str, ...] = ()) -> tuple[str, str] | None:
    """(key.field, why) for the first field of the dataclass `obj` outside its bound, or None (key "" for a top-level
    object: the field's name alone). A field whose default is None may be None: a setting its user decides. The
    fields named in `positive` must be above their bound's lower end (a size this obj uses, whose default 0 says it
    has none)."""
    for name, (b, optional) in _bounds(type(obj)).items():
        value = getattr(obj, name)
        if value is None and optional:
            continue
        if name in positive:
            b = b._replace(lo_open=True)
        for k, x in enumerate(value) if isinstance(value, tuple) else ((None, value),):
            if isinstance(x, bool) or not isinstance(x, Real) or not b.holds(float(x)):
                where = f"{key}.{name}" if key else name
                return (f"{where}{'' if k is None else f'[{k}]'}", f"expected {b.allowed}, got {x!r}")
    return None


_BY_CLASS: dict[type, dict[str, tuple[Bound, bool]]] = {}


def _bounds(cls: type) -> dict[str, tuple[Bound, bool]]:
    """Each bounded field's Bound, and whether it may be None (its default is)."""
    if cls not in _BY_CLASS:
        _BY_CLASS[cls] = {f.name: (f.metadata["bound"], f.default is None) for f in fields(cls)
                          if "bound" in f.metadata}
    return _BY_CLASS[cls]


__all__ = ["Bound", "bound", "bounded", "refusal"]
