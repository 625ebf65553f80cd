"""The numba decorators every compiled module uses (one place for the compile options)."""
from __future__ import annotations

import numba as nb

jit = nb.njit(cache=True, error_model="numpy")
#: small helpers are inlined into their callers: a call boundary costs more than their arithmetic
inline = nb.njit(cache=True, error_model="numpy", inline="always")
