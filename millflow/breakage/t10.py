"""Breakage distributions from the t10 family (Narayanan & Whiten, 1988).

A drop-weight or impact test reports t_n: the mass fraction of the broken product
finer than 1/n of the parent size, for n = 2, 4, 10, 25, 50, 75. For a given ore the
t_n lie on one family of curves of t10 alone, measured for that ore: the tn-t10
table. With that table and one value of t10 the cumulative breakage function is
fixed:

    Phi(r) = fraction of broken product finer than r times the parent size,
    Phi(1) = 1,  Phi(1/n) = t_n(t10),

and B_ij = Phi(x_{i-1}/x_j) with Austin's index convention (B_{j+1,j} = 1, as in
eqs. 6 and 8). Between the known points Phi is interpolated by PCHIP in ln r
(monotone, no overshoot). Below the finest point r = 1/n_max it is extended as a
power law, Phi ∝ r^m, with the slope m of the last interval in log-log. This
extension is the one assumption beyond the table; it is stated, not hidden.
Used in hybrid back-calculation (B fixed from a measured t10, only S fitted).

There is no built-in table: the tn-t10 relation is ore-specific. Read yours with
:func:`read_t10_table`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from millflow.breakage.distributions import b_from_B, validate_B
from millflow.errors import BreakageError, InputError
from millflow.inputs import read_csv
from millflow.grid import as_sizes

__all__ = ["T10Table", "read_t10_table", "t10_B", "T10Breakage"]


@dataclass(frozen=True)
class T10Table:
    """The tn-t10 family of one ore: t_n [-] (fractions) at each tabulated t10 [-].

    Attributes
    ----------
    t10 : (K,) increasing t10 values [-].
    n : (M,) the n of each t_n column (e.g. 2, 4, 25, 50, 75; 10 is implied).
    tn : (K, M) t_n at each t10 [-].
    """

    t10: np.ndarray
    n: np.ndarray
    tn: np.ndarray = field(repr=False)

    def __post_init__(self):
        t10 = np.asarray(self.t10, dtype=float)
        n = np.asarray(self.n, dtype=float)
        tn = np.asarray(self.tn, dtype=float)
        if t10.ndim != 1 or t10.size < 2 or np.any(np.diff(t10) <= 0):
            raise InputError(f"t10 table: t10 must be at least 2 increasing values, got {t10!r}")
        if tn.shape != (t10.size, n.size):
            raise InputError(f"t10 table: tn has shape {tn.shape}; expected ({t10.size}, {n.size})")
        if np.any(n <= 1) or np.any(n == 10):
            raise InputError(f"t10 table: n must be > 1 and not 10 (t10 is the table's key), got {n!r}")
        if not np.all(np.isfinite(tn)) or np.any((tn < 0) | (tn > 1)):
            raise InputError("t10 table: every t_n must be a fraction in [0, 1] (not percent)")
        object.__setattr__(self, "t10", t10)
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "tn", tn)

    def points(self, t10: float) -> tuple[np.ndarray, np.ndarray]:
        """(r, Phi) at r = 1 and r = 1/n for all n incl. 10, coarse -> fine, for one t10.

        t_n are interpolated linearly in t10 between rows; t10 outside the table is an
        error (the family is only known where it was measured)."""
        if not (self.t10[0] <= t10 <= self.t10[-1]):
            raise InputError(f"t10 = {t10!r} is outside the table's range "
                             f"[{self.t10[0]:g}, {self.t10[-1]:g}]; the family is not known there")
        tn = np.array([np.interp(t10, self.t10, self.tn[:, k]) for k in range(self.n.size)])
        n = np.append(self.n, 10.0)
        phi = np.append(tn, t10)
        order = np.argsort(n)
        r = np.concatenate(([1.0], 1.0 / n[order]))
        phi = np.concatenate(([1.0], phi[order]))
        if np.any(np.diff(phi) > 1e-12):
            raise BreakageError(f"t10 = {t10:g}: t_n rise with n ({dict(zip(n[order], phi[1:]))}); "
                                "expected t_n to fall as n grows (finer sizes pass less)")
        return r, phi


def read_t10_table(path) -> T10Table:
    """Read a tn-t10 table from CSV: a column ``t10`` and columns ``t2``, ``t4``, ``t25``,
    ``t50``, ``t75`` (any subset of t<n>), all as fractions in [0, 1]."""

    try:
        df = read_csv(path, "file")  # "<path>: file not found", encodings named
    except InputError as exc:
        raise InputError(f"t10 table {exc}") from None
    if "t10" not in df.columns:
        raise InputError(f"t10 table {path}: no column 't10' (columns: {list(df.columns)})")
    cols = [c for c in df.columns if c.startswith("t") and c[1:].isdigit() and c != "t10"]
    if not cols:
        raise InputError(f"t10 table {path}: expected columns t2, t4, t25, t50, t75 (some of them)")
    df = df.sort_values("t10")
    return T10Table(df["t10"].to_numpy(float), np.array([float(c[1:]) for c in cols]), df[cols].to_numpy(float))


def _phi(r_known: np.ndarray, phi_known: np.ndarray):
    """Phi(r) for r in (0, 1]: PCHIP in ln r through the points, power law below."""
    lr = np.log(r_known[::-1])  # increasing
    lp = phi_known[::-1]
    from scipy.interpolate import PchipInterpolator  # imported here: loading a flowsheet need not pay for it

    spline = PchipInterpolator(lr, lp)
    slope = (np.log(phi_known[-2]) - np.log(phi_known[-1])) / (np.log(r_known[-2]) - np.log(r_known[-1])) \
        if phi_known[-1] > 0 else 0.0

    def phi(r):
        r = np.asarray(r, dtype=float)
        out = np.empty_like(r)
        inside = r >= r_known[-1]
        out[inside] = spline(np.log(np.minimum(r[inside], 1.0)))
        out[~inside] = phi_known[-1] * (r[~inside] / r_known[-1]) ** slope
        return np.clip(out, 0.0, 1.0)  # PCHIP stays in range; clip only rounding

    return phi


def t10_B(x, t10: float, table: T10Table) -> np.ndarray:
    """Cumulative breakage matrix B (N, N) from the t10 family (module docstring).

    x : class sizes [m] (upper edges, coarse -> fine) or a SizeGrid; t10 [-]."""
    xs = as_sizes(x)
    phi = _phi(*table.points(float(t10)))
    N = xs.size
    B = np.zeros((N, N))
    for j in range(N - 1):
        B[j + 1:, j] = phi(xs[j:N - 1] / xs[j])  # x_{i-1}/x_j for i = j+1..N-1
    return validate_B(B, xs)


@dataclass(frozen=True)
class T10Breakage:
    """Breakage from a measured t10 and the ore's tn-t10 table; a distribution model
    (callable x -> b, with ``.B(x)`` and ``.b(x)``) like the other forms."""

    t10: float
    table: T10Table = field(repr=False)

    def __post_init__(self):
        if not (0.0 < float(self.t10) < 1.0):
            raise InputError(f"T10Breakage: t10 = {self.t10!r}; expected a fraction in (0, 1)")

    def B(self, x) -> np.ndarray:
        return t10_B(x, self.t10, self.table)

    def b(self, x) -> np.ndarray:
        return b_from_B(self.B(x), x)

    __call__ = b
