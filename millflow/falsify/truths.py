"""Truths: the processes that generate the synthetic measurements of a falsification study.

A truth is any object with

- ``name`` (str) and ``strength`` (float): what it is and how strong its model error is;
- ``params`` (dict name -> float): its parameters, compared with the estimates of the
  assumed model where the names are shared (e.g. the breakage parameters ``ln_A0``,
  ``alpha``, ``phi``, ``gamma``, ``beta`` of eqs. 5-6);
- ``mass_fractions(design)`` -> array (G, N): the noiseless mass fractions on
  ``design.grid`` of every sample ``design.sample_keys()`` (G samples).

Built-in truths, all exact (linear algebra of the linear core, no ODE):

- :class:`LinearTruth`: any linear model the fitting package can state
  (:class:`~millflow.fitting.ModelSpec`) at given parameters; with ``mode="mill"`` this
  is a linear mill with a real RTD (tanks in series, axial dispersion, recirculating
  cells; :class:`millflow.mill.Mill`, eq. 3 generalised by the transport) and/or
  internal classification d_i*. Helpers :func:`rtd_truth`, :func:`classification_truth`.
- :class:`SlowingDownTruth`: batch grinding with rates S_i(t) = S_i0 kappa(t) (Austin's
  slowing-down, kappa a function of time only). Then dM/dt = kappa(t) K M, whose
  solution is the linear one at the transformed time theta(t) = int_0^t kappa (eq. 4
  with t -> theta): exact, by :func:`millflow.batch.batch_grind` at theta.
- :class:`CallableTruth`: the adapter for non-linear truths computed elsewhere
  (millflow.nonlinear: aggregation, population-dependent rates). It wraps a callable
  ``f(times_s) -> (T, N)`` mass fractions on the design grid, one per condition.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from millflow.errors import InputError, SolverError
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.mill.transport import is_axial, is_axial_dispersion, is_network, shape_parameter
from millflow.nonlinear.kinetics import slowing_down, theta_of
from millflow.psd import from_sieves

__all__ = ["Truth", "LinearTruth", "SlowingDownTruth", "CallableTruth", "rtd_truth", "is_rtd_truth",
           "classification_truth", "BREAKAGE_TRUTH"]

#: Default breakage parameters of the truths (eq. 5 at x0 = 1 mm, ln of A [1/s]; eq. 6).
BREAKAGE_TRUTH = {"ln_A0": math.log(1.0 / 60.0), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}


@runtime_checkable
class Truth(Protocol):
    """What a truth provides: ``name``, ``strength``, ``params`` and the data it makes."""

    name: str
    strength: float
    params: dict

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid, one row per sample."""
        ...


def _theta(spec: ModelSpec, params: dict) -> np.ndarray:
    missing = [n for n in spec.param_names if n not in params]
    if missing:
        raise InputError(f"truth parameters: missing {missing} for the truth model {spec.label()!r}")
    return np.array([float(params[n]) for n in spec.param_names])


@dataclass(frozen=True)
class LinearTruth:
    """A linear model of :mod:`millflow.fitting.models` at fixed parameters (exact)."""

    spec: ModelSpec
    params: dict
    name: str = "linear"
    strength: float = 0.0

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid per sample, from the assumed model's own forward model."""
        model = ForwardModel(self.spec, design.data(), design.grid)
        M = model.predict_grid(_theta(self.spec, self.params))[0]
        if not np.isfinite(M).all():
            raise SolverError(f"truth {self.name!r}: the model {self.spec.label()!r} is not finite at {self.params}")
        return M


def is_rtd_truth(ttype) -> bool:
    """True for the truth types that are a transport of :func:`rtd_truth`.

    Parameters
    ----------
    ttype : a truth type (``truth.type`` of a falsification config).

    Returns
    -------
    bool
        True for well-mixed cells with a number of cells (tanks in series, recirculating
        cells) and the closed axial-dispersion vessel.
    """
    try:
        return shape_parameter(ttype) is not None and not is_axial_dispersion(ttype, open_vessel=True)
    except ValueError:  # not a transport name
        return False


def rtd_truth(transport: str, strength: float, params: dict | None = None, *, r: float = 1.0,
              classification: str | None = None, n_screen: float | None = None) -> LinearTruth:
    """A linear mill with a real RTD (tanks in series, axial dispersion or recirculating cells).

    A linear mill with a real RTD: ``tanks_in_series`` (strength = n), ``axial_dispersion``
    (strength = Pe), ``recirculating_cells`` (strength = n, with back-flow ratio ``r``);
    tau from the design's ``tau_s`` column. Optional classification ``screen_power`` with
    exponent ``n_screen`` at every cell outlet (cell transports) or along the axis.
    """
    key = shape_parameter(transport) if is_rtd_truth(transport) else None  # cells n, the closed vessel's pe
    if key is None:
        raise InputError(f"truth.type = {transport!r}: expected tanks_in_series, axial_dispersion or "
                         "recirculating_cells")
    val = float(strength)
    if key == "n":
        if val != int(val) or val < 1:
            raise InputError(f"truth.strength = {strength!r}: the number of cells of {transport} must be an "
                             "integer >= 1")
        val = int(val)
    tp = {key: val, **({"r": float(r)} if is_network(transport) else {})}
    cls = classification if n_screen is not None else None
    where = "cells" if cls and not is_axial(transport) else None
    spec = ModelSpec(mode="mill", transport=transport, transport_params=tp, tau_column="tau_s",
                     classification=cls, where=where)
    p = {**BREAKAGE_TRUTH, **(params or {})}
    if cls:
        p["n_screen"] = float(n_screen)
    return LinearTruth(spec, p, name=transport, strength=float(strength))


def classification_truth(strength: float, params: dict | None = None) -> LinearTruth:
    """A perfectly mixed mill with internal classification of strength ``n_screen``.

    A perfectly mixed mill with internal classification d_i* = (x_i/x0)^-n_screen
    (``screen_power`` with a single screen: the design needs a ``screen_mm`` column),
    strength = n_screen (0: no classification).
    """
    spec = ModelSpec(mode="well_mixed", tau_column="tau_s", classification="screen_power")
    p = {**BREAKAGE_TRUTH, **(params or {}), "n_screen": float(strength)}
    return LinearTruth(spec, p, name="classification", strength=float(strength))


@dataclass(frozen=True)
class SlowingDownTruth:
    """Batch grinding with S_i(t) = S_i0 kappa(t) (eqs. 4-6), exact at theta = int_0^t kappa.

    kappa(t) = 1 / (1 + strength * t / t_ref) by default (rates fall as the charge gets
    finer; strength 0 is first-order breakage), theta = (t_ref/strength) ln(1 + strength t/t_ref);
    t_ref defaults to the design's last sampling time. Or give ``kappa`` (a callable of
    t [s], positive): theta is then integrated by adaptive quadrature (scipy ``quad``,
    relative tolerance 1e-12).
    """

    strength: float = 0.0
    params: dict = field(default_factory=lambda: dict(BREAKAGE_TRUTH))
    kappa: Callable | None = field(default=None, compare=False)
    t_ref_s: float | None = None
    name: str = "slowing_down"

    def __post_init__(self):
        if not (math.isfinite(self.strength) and self.strength >= 0):
            raise InputError(f"truth.strength = {self.strength!r}: expected a finite number >= 0 for slowing-down")

    @property
    def kinetic_truth(self) -> dict:
        """The fit's parameter of this truth (``s_slow``).

        The fit's parameter of this truth (``s_slow``; the default hyperbolic kappa and
        t_ref = the last sampling time, as the fit's defaults; none for a user kappa or t_ref).
        """
        return {} if self.kappa is not None or self.t_ref_s is not None else {"s_slow": self.strength}

    def theta(self, t, t_ref: float) -> np.ndarray:
        """Transformed time theta(t) = int_0^t kappa [s]."""
        t = np.asarray(t, float)
        if self.kappa is not None:
            return theta_of(t, self.kappa)
        s = self.strength / t_ref
        return t.copy() if s == 0 else np.log1p(s * t) / s

    def linear_parts(self, design):
        """(S (C, N) [1/s], b (N, N), feeds (C, N)) of the first-order core (eq. 5, eq. 6)."""
        spec = ModelSpec(mode="batch")
        model = ForwardModel(spec, design.data(), design.grid)
        p = {k: np.array([v]) for k, v in zip(spec.param_names, _theta(spec, self.params))}
        S = model.rates(p)[0]
        b = model.frac_b(p, 1)[0]
        feed = from_sieves(np.asarray(design.sieves_m), np.asarray(design.feed_passing), design.grid, oversize="lump")
        return S, b, feed

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid per sample, with slowing-down in time."""
        if not design.is_batch:
            raise InputError("truth slowing_down needs a batch design (design.times_s)")
        t = np.asarray(design.times_s)
        theta = self.theta(t, self.t_ref_s or float(t[-1]))
        S, b, feed = self.linear_parts(design)
        per_cond = slowing_down(S[0], b, feed, t, theta=theta).M  # same rates for every condition
        return np.concatenate([per_cond for _ in sorted(design.conditions)])


@dataclass(frozen=True)
class CallableTruth:
    """Adapter for truths computed by other code (e.g. millflow.nonlinear).

    ``func(times_s) -> (T, N)`` returns the noiseless mass fractions on the design grid
    at the batch sampling times (SI seconds), rows summing to 1; ``funcs`` maps a
    condition name to its callable, or one callable serves every condition. ``params``
    are the truth's values of parameters the assumed model shares (e.g. the breakage
    parameters of the rates being slowed or aggregated). The adapter checks shape,
    finiteness, non-negativity and the mass balance of what it is given (to 1e-9: a
    truth that loses mass is a broken truth, not model error) and raises otherwise.
    """

    funcs: object
    params: dict
    name: str = "callable"
    strength: float = 0.0

    def mass_fractions(self, design) -> np.ndarray:
        """Mass fractions on the design's grid per sample, from the user's callable."""
        if not design.is_batch:
            raise InputError(f"truth {self.name!r}: a callable truth needs a batch design (design.times_s)")
        t = np.asarray(design.times_s)
        out = []
        for c in sorted(design.conditions):
            f = self.funcs.get(c) if isinstance(self.funcs, dict) else self.funcs
            if f is None:
                raise InputError(f"truth {self.name!r}: no callable for condition {c!r}")
            M = np.asarray(f(t), float)
            if M.shape != (t.size, design.grid.n):
                raise InputError(f"truth {self.name!r}, condition {c!r}: callable returned shape {M.shape}; "
                                 f"expected {(t.size, design.grid.n)} (times x grid classes)")
            if not np.isfinite(M).all() or np.any(M < -1e-12):
                raise InputError(f"truth {self.name!r}, condition {c!r}: mass fractions must be finite and >= 0")
            defect = float(np.abs(M.sum(axis=1) - 1.0).max())
            if defect > 1e-9:
                raise SolverError(f"truth {self.name!r}, condition {c!r}: mass fractions sum to 1 within {defect!r}; "
                                  "expected 1e-9")
            out.append(M)
        return np.concatenate(out)
