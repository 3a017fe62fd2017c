"""Benchmark of the breakage core: batch grinding (eq. 4) exact path vs solve_ivp.

Three cases, defined once in :func:`core_cases` and shared by the benchmark, the test
(tests/millflow/test_bench_core.py) and the reference script
(benchmarks/reference_core.py):

- ``baseline``: power-law rates (eq. 5, alpha = 1) on a 2^(1/4) grid, normalized B
  (eq. 6: phi 0.4, gamma 0.8, beta 3), feed in the three top classes.
- ``stiff``: rates log-spaced from 1e6 down to 1e-6 1/s (sink 0), times 1e-3..1e3 s.
- ``degenerate``: Austin's rate with a maximum (eq. 7) capped into a run of four
  exactly equal rates around the maximum, and every class on the coarse side paired
  with a class on the fine side whose rate equals it exactly or to 1e-9 relative:
  Reid's (1965) closed form divides by S_i - S_j = 0 there.

For each case and N = 25, 50, 100, 200 classes (N = 25, 100 with ``quick``) the
work-precision table gives, per method and tolerance, the max absolute error over all
classes and times against a 60-digit mpmath reference (cached in
benchmarks/data/core_<case>.json), the minimum value, the mass-balance error and the
median wall time of :func:`millflow.batch.batch_solve`, with the ratio to a plain
``scipy.integrate.solve_ivp(method="BDF", rtol=1e-10, atol=1e-14, jac=K)`` timed in
the same run. A grid-independence table (Principle IV) solves a batch grind with
power-law S and normalized B defined as functions of size on numerical grids of ratio
2^(1/2) ... 2^(1/32), reduces each result to the 2^(1/2) sieve grid with
:func:`millflow.psd.regrid` and reports the cumulative-passing error and observed
order. A targets table checks the issue-2 goals at N = 100.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from millflow.batch import ODE_METHODS, batch_solve
from millflow.breakage import austin_rates, b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid
from millflow.linalg import breakage_matrix
from millflow.psd import cum_passing, regrid

__all__ = ["DESCRIPTION", "CoreCase", "core_cases", "run", "format_table", "load_reference",
           "grid_independence", "REFERENCE_DIR"]

DESCRIPTION = "batch grinding (eq. 4): exact path vs solve_ivp work-precision, grid independence"

CASE_NAMES = ("baseline", "stiff", "degenerate")
SIZES_FULL = (25, 50, 100, 200)
SIZES_QUICK = (25, 100)
ODE_RTOLS = (1e-6, 1e-8, 1e-10)
#: atol of the ODE rows: masses are O(1), so atol = rtol * 1e-3 keeps the relative
#: control on the large classes and does not let the small ones go unchecked.
ATOL_FACTOR = 1e-3
BASELINE = {"method": "BDF", "rtol": 1e-10, "atol": 1e-14}

#: Cached references: benchmarks/data beside the package (source checkout), or
#: the directory named by MILLFLOW_BENCH_DATA.
REFERENCE_DIR = Path(os.environ.get("MILLFLOW_BENCH_DATA", Path(__file__).resolve().parents[2] / "benchmarks" / "data"))

# Targets of issue 2 for the exact path at N = 100, 10 output times.
TARGET_MS = {"baseline": 1.0, "stiff": 5.0, "degenerate": 5.0}
TARGET_ERR = 1e-12
TARGET_MIN = -1e-15
TARGET_MASS = 1e-13


# ------------------------------------------------------------------------ the cases
@dataclass(frozen=True, eq=False)
class CoreCase:
    """One batch grind: rates S [1/s], fractional b, feed (N,), times t_s [s]."""

    name: str
    S: np.ndarray
    b: np.ndarray
    feed: np.ndarray
    t_s: np.ndarray
    description: str

    def sha256(self) -> str:
        """Digest of the float64 inputs; a cached reference is valid only for the same."""
        h = hashlib.sha256()
        for a in (self.S, self.b, self.feed, self.t_s):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
        return h.hexdigest()


def _grid(n: int) -> SizeGrid:
    return SizeGrid.geometric(4e-3, 2.0 ** 0.25, n)


def _feed(n: int) -> np.ndarray:
    feed = np.zeros(n)
    feed[:3] = [0.5, 0.3, 0.2]
    return feed


def _b(grid: SizeGrid) -> np.ndarray:
    return b_from_B(normalized_B(grid, phi=0.4, gamma=0.8, beta=3.0))


def degenerate_rates(grid: SizeGrid) -> np.ndarray:
    """Austin's rate (eq. 7) made degenerate the way measured rates are [1/s].

    The rate rises with size, peaks near 0.8 mm and falls (alpha 1, Lambda 3,
    mu0 1 mm, max 0.05 1/s). It is capped at 0.9 of the maximum, which makes the
    four classes around the peak a run of exactly equal rates; then every class on
    the coarse side of the peak gives its rate to the unused class on the fine side
    with the nearest rate, exactly (even pairs) or times 1 + 1e-9 (odd pairs).
    """
    S = austin_rates(grid, A=1.0, alpha=1.0, mu0=1e-3, Lambda=3.0)
    S *= 0.05 / S.max()
    peak = int(np.argmax(S))
    S = np.minimum(S, 0.9 * S.max())
    S[-1] = 0.0
    plateau = np.flatnonzero(S == S.max())
    used = set(plateau.tolist())
    fine = [j for j in range(int(plateau.max()) + 1, S.size - 1)]
    for k, i in enumerate(range(int(plateau.min()) - 1, -1, -1)):
        free = [j for j in fine if j not in used]
        if not free:
            break
        j = min(free, key=lambda j: abs(S[j] - S[i]))
        S[j] = S[i] if k % 2 == 0 else S[i] * (1.0 + 1e-9)
        used.add(j)
    assert peak in plateau
    return S


def core_cases(n: int) -> dict[str, CoreCase]:
    """The three benchmark cases on n classes (n >= 16), keyed by name.

    All use the 2^(1/4) grid from 4 mm down, normalized B (phi 0.4, gamma 0.8,
    beta 3), feed 0.5/0.3/0.2 in the three top classes and 10 output times.
    """
    if n < 16:
        raise ValueError(f"n = {n}: the core cases need at least 16 classes")
    grid = _grid(n)
    b = _b(grid)
    feed = _feed(n)
    S_base = power_law_rates(grid, A=0.02, alpha=1.0, x0=4e-3)
    S_stiff = np.append(np.logspace(6.0, -6.0, n - 1), 0.0)
    return {
        "baseline": CoreCase("baseline", S_base, b, feed, np.geomspace(1.0, 500.0, 10),
                             "power law S = 0.02 (x/4 mm) 1/s, t = 1..500 s"),
        "stiff": CoreCase("stiff", S_stiff, b, feed, np.geomspace(1e-3, 1e3, 10),
                          "S log-spaced 1e6..1e-6 1/s, t = 1e-3..1e3 s"),
        "degenerate": CoreCase("degenerate", degenerate_rates(grid), b, feed, np.geomspace(1.0, 1e3, 10),
                               "Austin rate with max, run of 4 equal rates, pairs equal or 1e-9 apart"),
    }


def rate_degeneracy(S: np.ndarray) -> dict:
    """How close Reid's formula comes to dividing by zero: over breaking classes j < i,
    the smallest |S_i - S_j| / max(S_i, S_j) and the number of exactly equal pairs."""
    s = S[S > 0]
    d = np.abs(s[:, None] - s[None, :]) / np.maximum(s[:, None], s[None, :])
    iu = np.triu_indices(s.size, 1)
    gaps = d[iu]
    return {"min_rel_gap": float(gaps.min()), "equal_pairs": int((gaps == 0).sum()),
            "near_pairs_below_1e-6": int(((gaps > 0) & (gaps < 1e-6)).sum())}
