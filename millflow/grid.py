"""Size grids: the classes on which every population balance in millflow is solved.

A :class:`SizeGrid` holds the upper edges ``upper_m`` [m] of N size classes, strictly
decreasing: class 1 is the coarsest, class N the finest, which is the sink (it does
not break, S_N = 0). Class i spans (x_{i+1}, x_i]; the sink spans (0, x_N].
The representative size of a class is its upper edge, x_i = upper_m[i-1] (Austin's
convention, docs/equations.md "Size classes"); every rate S_i and distribution B_ij in
millflow is evaluated at these x_i. Grids are usually geometric (each edge a fixed
ratio, 2^(1/2) for sieve series, 2^(1/4) or finer for numerical work, below the one
above); :meth:`SizeGrid.refine` splits every class ratio r into r^(1/k) and keeps the
old edges, which is what grid-independence studies (Principle IV) need: a solution on
the refined grid reduces exactly to the original edges (:func:`millflow.psd.regrid`).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from millflow.errors import GridError

__all__ = ["SizeGrid", "SCHEMES", "SAFETY_FACTOR", "richardson", "as_sizes", "class_label", "validate_edges"]

#: Roache's safety factor of the two-grid convergence index (grid error estimates).
SAFETY_FACTOR = 3.0


def richardson(coarse: float, fine: float, order: float, factor: float = 2.0,
               safety: float = SAFETY_FACTOR) -> tuple[float, float]:
    """(extrapolated value, estimated relative grid error of ``coarse``) from two grids.

    ``fine`` is on the grid whose class width in ln x is 1/``factor`` of the coarse one;
    ``order`` the order p of the discretisation. Q_ext = Q_f + (Q_f - Q_c)/(factor^p - 1);
    the error is safety |Q_c - Q_ext| / |Q_ext| (Roache's grid convergence index of the
    coarse grid; the safety factor 3 covers the pre-asymptotic range that two grids
    cannot detect). NaN when either value is not finite.
    """
    if not (math.isfinite(coarse) and math.isfinite(fine)):
        return float("nan"), float("nan")
    ext = fine + (fine - coarse) / (factor ** order - 1.0)
    return ext, safety * abs(coarse - ext) / max(abs(ext), 1e-300)

#: Discretisation schemes of continuous-size forms (see :class:`SizeGrid`).
SCHEMES = ("class_average", "upper_edge")

# Relative tolerance under which successive class ratios count as one geometric ratio.
_RATIO_RTOL = 1e-9


def class_label(i: int, x=None) -> str:
    """Name a class for messages: ``"class 7 (x = 0.00012 m)"``.

    Parameters
    ----------
    i : int
        0-based array index (the label is 1-based, as in docs/equations.md).
    x : array_like, optional
        Representative (upper) sizes [m]; the size is shown when given.
    """
    if x is None or i >= len(x):
        return f"class {i + 1}"
    return f"class {i + 1} (x = {float(x[i]):.6g} m)"


#: Largest size a grid may hold [m]: 10 m, above any mill feed. Beyond it a size is a unit
#: mistake, and rate laws such as A (x/x0)^alpha overflow; refusing it names the edge
#: instead of returning infinities. (No lower limit: fine geometric grids reach far
#: below a molecule harmlessly, every rate law underflowing to 0 there.)
MAX_SIZE_M = 10.0


def validate_edges(edges, name: str = "upper_m") -> np.ndarray:
    """Check that class edges are 1-D, finite, > 0 and strictly decreasing.

    Parameters
    ----------
    edges : array_like
        Upper class edges [m], coarse -> fine.
    name : str
        Argument name used in error messages.

    Returns
    -------
    numpy.ndarray
        A float64 copy of ``edges``.

    Raises
    ------
    GridError
        Naming the 1-based index and the value of the first bad edge.
    """
    try:
        arr = np.array(edges, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GridError(f"{name}: cannot read sizes as numbers ({exc})") from exc
    if arr.ndim != 1 or arr.size < 1:
        raise GridError(f"{name}: expected a non-empty 1-D array of sizes [m], got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        k = bad[0]
        raise GridError(f"{name}[{k}] (edge {k + 1}) = {float(arr[k])!r}: sizes must be finite")
    bad = np.flatnonzero(arr <= 0)
    if bad.size:
        k = bad[0]
        raise GridError(f"{name}[{k}] (edge {k + 1}) = {float(arr[k])!r} m: sizes must be > 0")
    bad = np.flatnonzero(arr > MAX_SIZE_M)
    if bad.size:
        k = bad[0]
        raise GridError(f"{name}[{k}] (edge {k + 1}) = {float(arr[k]):.6g} m: expected a particle size of at most "
                        f"{MAX_SIZE_M:g} m (is the unit right?)")
    bad = np.flatnonzero(np.diff(arr) >= 0)
    if bad.size:
        k = bad[0] + 1
        raise GridError(
            f"{name}[{k}] (edge {k + 1}) = {arr[k]:.6g} m is not below the edge above it "
            f"({arr[k - 1]:.6g} m): sizes must be strictly decreasing, coarse -> fine"
        )
    return arr


def as_sizes(grid_or_x) -> np.ndarray:
    """Representative sizes x [m] of a :class:`SizeGrid` or of a plain array.

    A plain array is validated like grid edges (finite, > 0, strictly decreasing), so
    every function taking ``x`` accepts either form.
    """
    if isinstance(grid_or_x, SizeGrid):
        return grid_or_x.upper_m
    return validate_edges(grid_or_x, name="x")


@dataclass(frozen=True, eq=False)
class SizeGrid:
    """N size classes given by their upper edges [m], class 1 coarsest, class N the sink.

    Class i spans (upper_m[i], upper_m[i-1]] in 0-based terms, i.e. (x_{i+1}, x_i]
    1-based; the sink class N spans (0, x_N] and never breaks (S_N = 0).
    Representative size: the upper edge, ``x = upper_m`` (Austin's convention).

    Parameters
    ----------
    upper_m : array_like
        Upper class edges [m], strictly decreasing, finite, > 0. Stored as a read-only
        float64 array.
    scheme : str
        How continuous-size forms (rates, breakage, classification curves) are put on
        the classes: "class_average" (default; averages over each class, second order in
        the class width, :mod:`millflow.breakage.averaged`) or "upper_edge" (Austin's
        values at the upper edges, first order). Discrete S_i, b_ij are used as given
        under either.

    Examples
    --------
    >>> g = SizeGrid.geometric(1e-3, 2 ** 0.5, 5)
    >>> g.n, round(g.ratio, 6)
    (5, 1.414214)
    >>> g.refine(2).n
    9
    """

    upper_m: np.ndarray
    scheme: str = "class_average"

    def __post_init__(self):
        if self.scheme not in SCHEMES:
            raise GridError(f"scheme = {self.scheme!r}: expected one of {', '.join(SCHEMES)}")
        arr = validate_edges(self.upper_m, name="upper_m")
        check_classes(arr.size)
        arr.setflags(write=False)
        object.__setattr__(self, "upper_m", arr)

    # ----------------------------------------------------------------- constructors
    @classmethod
    def geometric(cls, top_m: float, ratio: float, n: int) -> "SizeGrid":
        """Geometric grid: x_i = top_m / ratio^(i-1), i = 1..n.

        Parameters
        ----------
        top_m : float
            Upper edge of class 1 [m].
        ratio : float
            Size ratio between neighbouring edges, x_i / x_{i+1} > 1 (e.g. 2**0.5).
        n : int
            Number of classes including the sink, >= 1.
        """
        _check_ratio(ratio)
        _check_positive(top_m, "top_m")
        if int(n) != n or n < 1:
            raise GridError(f"n = {n!r}: the number of classes must be an integer >= 1")
        check_classes(int(n))
        return cls(float(top_m) * float(ratio) ** -np.arange(int(n), dtype=float))

    @classmethod
    def from_edges(cls, edges_m) -> "SizeGrid":
        """Grid from explicit upper edges [m], coarse -> fine (e.g. a sieve series).

        A trailing 0 (the lower edge of the sink) may be included and is dropped.
        """
        arr = np.array(edges_m, dtype=float)
        if arr.ndim == 1 and arr.size > 1 and arr[-1] == 0.0:
            arr = arr[:-1]
        return cls(validate_edges(arr, name="edges_m"))

    @classmethod
    def between(cls, top_m: float, bottom_m: float, ratio: float) -> "SizeGrid":
        """Geometric grid from ``top_m`` down to ``bottom_m`` [m] with the given ratio.

        The finest edge (the sink's upper size x_N) is the first edge at or below
        ``bottom_m``; it equals ``bottom_m`` when top_m/bottom_m is an integer power of
        ``ratio`` (to 1e-9 in the exponent), and is otherwise at most one ratio finer.
        """
        _check_ratio(ratio)
        _check_positive(top_m, "top_m")
        _check_positive(bottom_m, "bottom_m")
        if bottom_m >= top_m:
            raise GridError(f"bottom_m = {bottom_m!r} m must be below top_m = {top_m!r} m")
        steps = math.log(top_m / bottom_m) / math.log(ratio)
        check_classes(math.ceil(steps) + 1, f"top {top_m:g} m, bottom {bottom_m:g} m, ratio {ratio!r}")
        n_steps = round(steps) if abs(steps - round(steps)) < 1e-9 else math.ceil(steps)
        grid = cls.geometric(top_m, ratio, n_steps + 1)
        if abs(steps - n_steps) < 1e-9:
            # land exactly on the requested bottom so sieve sizes match grid edges
            edges = grid.upper_m.copy()
            edges[-1] = float(bottom_m)
            grid = cls(edges)
        return grid

    def refine(self, k: int) -> "SizeGrid":
        """Split every class ratio r = x_i/x_{i+1} into k equal ratios r^(1/k).

        The original edges are kept bit for bit, so results on the refined grid reduce
        exactly to this one. The sink stays (0, x_N]: the refined grid has
        (N - 1) k + 1 classes.
        """
        if int(k) != k or k < 1:
            raise GridError(f"k = {k!r}: the refinement factor must be an integer >= 1")
        k = int(k)
        x = self.upper_m
        if k == 1 or x.size == 1:
            return self
        check_classes((x.size - 1) * k + 1, f"refine({k})")
        frac = np.arange(k, dtype=float) / k
        # geometric subdivision: x_i * (x_{i+1}/x_i)^(m/k), m = 0..k-1
        pieces = x[:-1, None] * (x[1:, None] / x[:-1, None]) ** frac[None, :]
        pieces[:, 0] = x[:-1]  # exact old edges (power of 0 is exact, this documents it)
        return SizeGrid(np.concatenate([pieces.ravel(), x[-1:]]), self.scheme)

    def with_scheme(self, scheme: str) -> "SizeGrid":
        """The same edges with another discretisation scheme (see :class:`SizeGrid`)."""
        return SizeGrid(self.upper_m, scheme)

    # ------------------------------------------------------------------ properties
    @property
    def x(self) -> np.ndarray:
        """Representative sizes [m]: the upper edges (Austin)."""
        return self.upper_m

    @property
    def n(self) -> int:
        """Number of classes N, the sink included."""
        return int(self.upper_m.size)

    @property
    def lower_m(self) -> np.ndarray:
        """Lower class edges [m]: x_{i+1} for i < N and 0 for the sink."""
        return np.append(self.upper_m[1:], 0.0)

    @property
    def ratio(self) -> float | None:
        """The common ratio x_i/x_{i+1} if the grid is geometric (rtol 1e-9), else None."""
        if self.n < 2:
            return None
        r = self.upper_m[:-1] / self.upper_m[1:]
        if np.allclose(r, r[0], rtol=_RATIO_RTOL, atol=0.0):
            return float(np.exp(np.mean(np.log(r))))
        return None

    def label(self, i: int) -> str:
        """``"class i+1 (x = ... m)"`` for the 0-based index i."""
        return class_label(i, self.upper_m)

    def size_coord(self):
        """The sizes as an xarray coordinate ``size`` [m] with units and long_name."""
        import xarray as xr

        # a Variable on its fastpath: a DataArray of a bare ndarray would have xarray's
        # duck-array probe import dask.array (about a second) when dask is installed
        return xr.DataArray(xr.Variable("size", self.upper_m.copy(),
                                        {"units": "m", "long_name": "upper size of class (Austin convention)"},
                                        fastpath=True), name="size")

    def __len__(self) -> int:
        return self.n

    def __eq__(self, other) -> bool:
        if not isinstance(other, SizeGrid):
            return NotImplemented
        return bool(np.array_equal(self.upper_m, other.upper_m)) and self.scheme == other.scheme

    def __hash__(self) -> int:
        return hash(self.upper_m.tobytes())

    def __repr__(self) -> str:
        r = self.ratio
        rs = "" if r is None else f", ratio={r:.6g}"
        sc = "" if self.scheme == "class_average" else f", scheme={self.scheme!r}"
        return f"SizeGrid(n={self.n}, top={self.upper_m[0]:.6g} m, sink below {self.upper_m[-1]:.6g} m{rs}{sc})"


def memory_budget_bytes() -> float:
    """Largest array a solve may allocate: ``MILLFLOW_MEMORY_BUDGET_GB`` GiB (default 4)."""
    raw = os.environ.get("MILLFLOW_MEMORY_BUDGET_GB", "4")
    try:
        gib = float(raw)
    except ValueError:
        raise GridError(f"MILLFLOW_MEMORY_BUDGET_GB = {raw!r}: expected a number of GiB") from None
    return gib * 2.0**30


def check_classes(n: int, how: str = "") -> None:
    """Refuse a grid whose breakage matrix exceeds the memory budget.

    Refuse, before anything is allocated, a grid whose N x N breakage matrix (every
    solve forms one) exceeds the memory budget; the message gives the size it would need.
    """
    need = 8.0 * float(n) * float(n)
    budget = memory_budget_bytes()
    if need > budget:
        where = f" ({how})" if how else ""
        raise GridError(f"a grid of {n:.4g} classes{where} needs {need / 2**30:.3g} GiB for one N x N breakage "
                        f"matrix, above the memory budget of {budget / 2**30:.3g} GiB (MILLFLOW_MEMORY_BUDGET_GB); "
                        "use a coarser ratio or fewer classes")


def check_run_memory(n: int, matrices: int, refined_n: int | None = None, what: str = "the run") -> float:
    """Refuse a run whose N x N matrices together exceed the memory budget, before it allocates.

    ``matrices`` of them on the grid of ``n`` classes (a flowsheet holds a transfer matrix
    per unit besides b and B), as many again on ``refined_n`` classes when a grid check
    runs beside the first solution. Returns the bytes estimated.
    """
    need = 8.0 * matrices * (float(n) ** 2 + (float(refined_n) ** 2 if refined_n else 0.0))
    budget = memory_budget_bytes()
    if need > budget:
        check = f" and {refined_n} classes for the grid check" if refined_n else ""
        raise GridError(f"{what} on {n} classes{check} needs about {need / 2**30:.3g} GiB ({matrices} N x N "
                        f"matrices per grid), above the memory budget of {budget / 2**30:.3g} GiB "
                        "(MILLFLOW_MEMORY_BUDGET_GB); use a coarser ratio or fewer classes"
                        + (", or --no-grid-check" if refined_n else ""))
    return need


def _check_ratio(ratio) -> None:
    if not (np.isfinite(ratio) and ratio > 1.0):
        raise GridError(f"ratio = {ratio!r}: expected x_i/x_(i+1) > 1 (e.g. 2**0.5), finite")


def _check_positive(value, name: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise GridError(f"{name} = {value!r}: expected a finite size > 0 [m]")
    if value > MAX_SIZE_M:
        raise GridError(f"{name} = {value:.6g} m: expected a particle size of at most {MAX_SIZE_M:g} m "
                        "(is the unit right?)")
