"""Input checks shared by the solvers: a breakage kernel (S, b) and per-class vectors.

Each check returns the validated float array or raises :class:`~millflow.errors.InputError`
(or :class:`~millflow.errors.BreakageError`) naming the argument, the 1-based class and
the value, and saying what was expected.
"""
from __future__ import annotations

import numpy as np

from millflow.breakage import validate_b, validate_rates
from millflow.errors import InputError

__all__ = ["kernel", "class_vector"]


def kernel(S, b) -> tuple[np.ndarray, np.ndarray]:
    """Rates S (N,) [1/s] with S_N = 0 and a fractional distribution b (N, N)."""
    S = validate_rates(S, name="S")
    n = S.size
    b = np.asarray(b, dtype=float)
    if b.shape != (n, n):
        raise InputError(f"b has shape {b.shape}; expected ({n}, {n}) to match S of length {n}")
    return S, validate_b(b)


def class_vector(v, n: int, name: str, what: str, *, positive: bool = False) -> np.ndarray:
    """A finite (N,) vector, >= 0 (or > 0 with ``positive``), one value per class."""
    arr = np.asarray(v, dtype=float)
    if arr.shape != (n,):
        raise InputError(f"{name} has shape {arr.shape}; expected ({n},) to match S of length {n}")
    bad = ~np.isfinite(arr) | ((arr <= 0) if positive else (arr < 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        op = "> 0" if positive else ">= 0"
        raise InputError(f"{name}: class {i + 1} is {arr[i]!r}; expected a finite {what} {op}")
    return arr
