"""Non-linear truths of a falsification study: aggregation and population-dependent rates.

Non-linear truths of a falsification study (millflow.nonlinear): aggregation and
population-dependent breakage rates, on top of the first-order core of eqs. 5-6 at the
truth's breakage parameters.

- :class:`AggregationTruth`: breakage + fixed-pivot aggregation with a named kernel
  (constant, sum, product, shear); ``strength`` = beta0 [1/s], volumes in units of
  x_ref^3 (default: the finest sieve). 0 is the linear truth.
- :class:`PopulationTruth`: S_i[M] = S_i (1 + F_fines(M))^(-strength), F_fines the mass
  fraction finer than ``fines_m`` (default: the middle sieve): fines cushion the breakage
  of every class (Bilgili-Scarlett type, w_ij = 1 for the fine classes j). 0 is linear.

Batch designs are solved by :func:`millflow.nonlinear.batch_nonlinear`, continuous
designs as perfectly mixed mills (:func:`millflow.mill.nonlinear.well_mixed`, Newton to
1e-12) at each condition's ``tau_s``, so that the only model error is the kinetics; or,
with ``n_tanks`` > 1, as that many tanks in series (kinetic and RTD model error together).
Mass that aggregation carries above the top class (the overflow) is coarser than every
sieve: a measurement puts it on the top sieve, so it is added to class 1, as the oversize
of the feed is (``from_sieves(oversize="lump")``); ``last_overflow`` records how much.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millflow.errors import InputError, SolverError
from millflow.falsify.truths import BREAKAGE_TRUTH, SlowingDownTruth
from millflow.fitting.kinetics import fines_mask
from millflow.mill.nonlinear import tanks_in_series, well_mixed
from millflow.nonlinear import KERNELS, Aggregation, batch_nonlinear, kinetics

__all__ = ["AggregationTruth", "PopulationTruth"]


def _solve(kin, design, feed, n_tanks: int = 1):
    """(G, N) truth mass fractions for every sample of the design; overflow lumped in class 1."""
    if design.is_batch:
        res = batch_nonlinear(kin, feed, np.asarray(design.times_s), rtol=1e-9, atol=1e-13)
        if not res.error_estimate <= 1e-7:
            raise SolverError(f"non-linear truth: error estimate {res.error_estimate:.3g} > 1e-7")
        M = res.M.copy()
        M[:, 0] += res.overflow_mass
        return np.concatenate([M for _ in sorted(design.conditions)]), float(res.overflow_mass.max())
    tau = dict(zip(design.conditions, design.process_dict()["tau_s"]))
    rows, over = [], 0.0
    for c in sorted(design.conditions):
        if n_tanks == 1:
            r = well_mixed(kin, feed, float(tau[c]), unit=f"non-linear truth, condition {c!r}")
        else:
            r = tanks_in_series(kin, feed, float(tau[c]), n_tanks)
        p = r.product.copy()
        p[0] += r.overflow_mass
        over = max(over, r.overflow_mass)
        rows.extend(p for _ in sorted(design.locations))
    return np.array(rows), over


def _check_tanks(n):
    if not (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
        raise InputError(f"truth.n_tanks = {n!r}: expected an integer >= 1 (1: perfect mixing)")


@dataclass
class AggregationTruth:
    """Breakage + aggregation (kernel ``kernel``, beta0 = ``strength`` [1/s])."""

    strength: float = 0.0
    params: dict = field(default_factory=lambda: dict(BREAKAGE_TRUTH))
    kernel: str = "constant"
    x_ref_m: float | None = None
    n_tanks: int = 1
    name: str = "aggregation"
    last_overflow: float = 0.0

    def __post_init__(self):
        _check_tanks(self.n_tanks)
        if not (math.isfinite(self.strength) and self.strength >= 0):
            raise InputError(f"truth.strength = {self.strength!r}: expected beta0 >= 0 [1/s] for aggregation")
        if self.kernel not in KERNELS:
            raise InputError(f"truth.kernel = {self.kernel!r}: expected one of {sorted(KERNELS)}")

    @property
    def kinetic_truth(self) -> dict:
        """The fit's parameter of this truth (``beta0``).

        The fit's parameter of this truth (``beta0`` of :mod:`millflow.fitting.kinetics`;
        meaningful when the fit uses the same kernel and x_ref).
        """
        return {"beta0": self.strength}

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid per sample, with aggregation."""
        S, b, feed = SlowingDownTruth(0.0, self.params).linear_parts(design)
        x_ref = self.x_ref_m or float(design.sieves_m[-1])
        kin = kinetics(S[0], b, aggregation=Aggregation(KERNELS[self.kernel](self.strength), x_ref), grid=design.grid)
        M, self.last_overflow = _solve(kin, design, feed, self.n_tanks)
        return M


@dataclass
class PopulationTruth:
    """First-order rates slowed by fines: S_i (1 + F_fines)^(-strength)."""

    strength: float = 0.0
    params: dict = field(default_factory=lambda: dict(BREAKAGE_TRUTH))
    fines_m: float | None = None
    n_tanks: int = 1
    name: str = "population"
    last_overflow: float = 0.0

    def __post_init__(self):
        _check_tanks(self.n_tanks)
        if not (math.isfinite(self.strength) and self.strength >= 0):
            raise InputError(f"truth.strength = {self.strength!r}: expected a cushioning exponent >= 0")

    @property
    def kinetic_truth(self) -> dict:
        """The fit's parameter of this truth (``lam_pop`` = -strength, with w = 1 and the same fines size)."""
        return {"lam_pop": -self.strength}

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid per sample, with fines cushioning."""
        S, b, feed = SlowingDownTruth(0.0, self.params).linear_parts(design)
        sieves = np.asarray(design.sieves_m)
        fines = self.fines_m or float(sieves[len(sieves) // 2])
        n = design.grid.n
        w = np.zeros((n, n))
        w[:, fines_mask(design.grid, fines) > 0] = 1.0  # classes at or below the fines size (the fit's mask)
        kin = kinetics(S[0], b, w=w, lam=-self.strength)
        M, _ = _solve(kin, design, feed, self.n_tanks)
        return M
