"""Continuous mills: transport from :mod:`rtd`, breakage from the core, classification d*.

A mill is a feed PSD f and solids rate, breakage rates S [1/s] and distribution b
(any form of :mod:`millflow.breakage`), a transport model from :mod:`rtd` (tau in s)
and optionally the normalised discharge rates d_i* = tau d_i (classification, eq. 1).
The mill assembles only the terms its definition declares and runs the cheapest
method that is exact for them (``METHODS``):

- ``well_mixed``: ``rtd.PerfectMixing``, eq. (3) by one triangular solve;
- ``cells``: tanks in series (integer n), ``rtd.RecirculatingCells`` or any
  ``rtd.CompartmentNetwork``: every cell well mixed, classification at the discharge
  or at every cell outlet, one exact block solve (:mod:`millflow.mill.cells`);
- ``plug_flow``: ``rtd.PlugFlow``, the batch solution at contact time tau (eq. 4),
  classification along the axis = class i travelling at d_i* u (rates S/d*);
- ``segregated``: any other ``rtd`` model without classification, product
  E_hat(-K) f (exact for first-order breakage, :mod:`millflow.mill.segregated`);
- ``axial_fv``: ``rtd.AxialDispersion`` with size-dependent axial velocity or
  dispersion, finite volumes with Richardson extrapolation: the closed vessel on [0, 1]
  (:mod:`millflow.mill.axial`), the open vessel on the whole line with a sampled or flux
  discharge (:mod:`millflow.mill.axial_open`); also the fallback of axial dispersion when
  the eigenbasis of segregated flow cancels;
- ``quadrature`` (on request only): segregated flow as int E(t) exp(K t) f dt by adaptive
  quadrature, for rates whose eigenbasis cancels (slow: seconds);
- ``composed``: ``rtd.Series`` (each part grinds the previous part's product: the
  transform of a series is the product of the parts') and ``rtd.Parallel`` (feed split
  by the weights), every part by its own method.

Hold-up is reported per unit solids feed rate [s] (mass in the mill / feed mass rate;
it sums to the mean residence time of the solids) and as mass fractions. For a
well-mixed cell with classification M_i H / F = tau p_i / d_i*; the fractions sum to 1
by construction, the hold-up per feed rate equals tau only when d* is consistent with
tau (sum tau p_i / d_i* = tau).

Results are xarray Datasets: dimension ``size`` (coordinate ``size``, the upper class
sizes [m], when x is given, as in every millflow Dataset; ``size_class`` the class number),
``cell``, ``position``, ``location``; attributes ``method``, ``error_estimate``,
``runtime_s``, ``mass_balance_error``.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import xarray as xr

from millflow._dataset import dataset
from millflow.errors import InputError, SolverError
from millflow.mill.accuracy import check_accuracy
from millflow.mill.scene import (AXIAL_KINDS, METHODS, WHERE, _check_feed, _part_scene, _Scene, _scene,
                                 _tau, choose_method)
from millflow.mill.axial import solve_axial
from millflow.mill.axial_open import solve_axial_open
from millflow.mill.cells import solve_cells
from millflow.mill.dataset import _GRID_NOTE, _fractions, _samples, _size_coords  # noqa: F401  (their home)
from millflow.mill.segregated import plug_flow, segregated, segregated_quadrature
from millflow.mill.well_mixed import solve_well_mixed

__all__ = ["METHODS", "steady_mill", "transfer_matrix", "choose_method", "WHERE"]

def _solve_composed(sc: _Scene, feed, *, tol: float, holdup: bool, cache: dict | None = None):
    """Series and parallel compositions of transports.

    Series: each part grinds the previous part's product (first-order breakage:
    E_hat of a series is the product of the parts' E_hat, applied in turn); Parallel:
    the feed split by the weights. Hold-ups add.
    """
    parts = sc.transport.parts
    weights = getattr(sc.transport, "weights", None)
    product, hold, error, methods = 0.0, 0.0, 0.0, []
    stream = feed
    for k, part in enumerate(parts):
        sub = _part_scene(sc, part)
        inflow = stream if weights is None else weights[k] * feed
        r = _solve(sub, inflow, tol=tol, holdup=holdup, cache=cache)
        methods.append(r["method"])
        error += r["error"]
        if holdup:
            hold = hold + r["holdup"]
        if weights is None:
            stream = r["product"]
        else:
            product = product + r["product"]
    product = stream if weights is None else product
    return product, (hold if holdup else None), error, methods


def _well_mixed(sc, feed, out, *, tol, holdup, cache):
    tau = _tau(sc.transport)
    p = solve_well_mixed(sc.S, sc.b, feed, tau, sc.d)
    dd = 1.0 if sc.d is None else (sc.d if np.ndim(feed) == 1 else sc.d[:, None])
    out.update(product=p, holdup=tau * p / dd, error=_triangular_error(p))
    out["cell_holdup"] = (tau * p / dd)[np.newaxis]
    return sc


def _cells(sc, feed, out, *, tol, holdup, cache):
    sol = solve_cells(sc.S, sc.b, feed, sc.network, sc.d, sc.where)
    # rounding of the triangular/banded solves, and at least the mass balance's own error
    # (an actual error; the banded solves of retained classes can exceed N eps)
    lost = float(np.abs(sol.product.sum(axis=0) - np.asarray(feed).sum(axis=0)).max(initial=0.0))
    out.update(product=sol.product, holdup=sol.holdup.sum(axis=0), error=max(_triangular_error(sol.product), lost))
    out["cell_holdup"] = sol.holdup
    out["extras"].update(solver=sol.method, kernel=sol.kernel)
    return sc


def _keep_blocks(out, cache, key):
    """The spectral decomposition a solve returned, kept in a Mill's cache."""
    blocks = out["extras"].pop("blocks", None)
    if blocks is not None and cache is not None:
        cache[key] = blocks


def _plug_flow(sc, feed, out, *, tol, holdup, cache):
    d = sc.d
    rates = sc.S if d is None else sc.S / d
    blocks = None if cache is None else cache.get("plug")
    p, h, err, info = plug_flow(rates, sc.b, feed, _tau(sc.transport), holdup=holdup, blocks=blocks)
    if d is not None and h is not None:
        h = h / (d if np.ndim(feed) == 1 else d[:, None])
    out.update(product=p, holdup=h, error=err)
    out["extras"].update(info)
    _keep_blocks(out, cache, "plug")
    return sc


def _segregated(sc, feed, out, *, tol, holdup, cache):
    blocks = None if cache is None else cache.get("segregated")
    try:
        p, h, err, info = segregated(sc.S, sc.b, feed, sc.transport, holdup=holdup, blocks=blocks)
    except SolverError as exc:
        if sc.forced or sc.kind not in AXIAL_KINDS:
            raise
        p, err, info = None, np.inf, {"fallback_reason": str(exc)}
    scale = float(np.abs(feed).sum(axis=0).max()) if np.size(feed) else 0.0
    too_large = err > max(tol, 1e-10) * max(scale, 1.0)
    if not sc.forced and sc.kind not in AXIAL_KINDS and too_large:
        info["advice"] = ("the eigenbasis cancels for these rates; method='quadrature' integrates "
                          "E(t) exp(K t) f over t instead (slower, exact to its tolerance)")
    out["extras"].update(info)
    _keep_blocks(out, cache, "segregated")
    if sc.kind in AXIAL_KINDS and not sc.forced and too_large:
        # rates so close over many classes that the eigenbasis cancels: the finite
        # volumes never divide by rate differences
        out["extras"]["fallback"] = f"segregated error estimate {err:.1e} > tol; axial_fv"
        return dataclasses.replace(sc, method="axial_fv")
    out.update(product=p, holdup=h, error=err)
    return sc


def _quadrature(sc, feed, out, *, tol, holdup, cache):
    p, h, err, info = segregated_quadrature(sc.S, sc.b, feed, sc.transport, holdup=holdup, tol=min(tol, 1e-10))
    out.update(product=p, holdup=h, error=err)
    out["extras"].update(info)
    return sc


def _composed(sc, feed, out, *, tol, holdup, cache):
    p, h, err, methods = _solve_composed(sc, feed, tol=tol, holdup=holdup, cache=cache)
    out.update(product=p, holdup=h, error=err)
    out["extras"]["parts"] = ", ".join(methods)
    return sc


def _axial_solution(sc, feed, tol):
    T = sc.transport
    if sc.kind == "axial_open":
        return solve_axial_open(sc.S, sc.b, feed, T.tau, T.pe, d=sc.d, w=sc.dispersion,
                                discharge=sc.discharge or "sampled", tol=tol)
    return solve_axial(sc.S, sc.b, feed, T.tau, T.pe, d=sc.d, w=sc.dispersion, tol=tol)


def _axial_fv(sc, feed, out, *, tol, holdup, cache):
    sol = _axial_solution(sc, feed, tol)
    out.update(product=sol.product, holdup=sol.holdup, error=sol.error_estimate)
    out["axial"] = sol
    out["extras"].update(order=sol.order, control_volumes=int(sol.z.size - 1))
    if sc.kind == "axial_open":
        out["extras"]["discharge"] = sc.discharge or "sampled"
    if sol.history and sol.history[0][0] == "plug-flow limit":
        out["extras"]["limit"] = "; ".join(f"{what} (estimate {est:.2g})" for what, est in sol.history)
        out["extras"].pop("control_volumes")
    elif sol.error_estimate > tol:
        stopped = [m for what, m in sol.history if what == "memory budget"]
        memory = (f"grid refinement stopped before {stopped[0]} volumes: that grid would hold more than a quarter "
                  "of the memory budget (MILLFLOW_MEMORY_BUDGET_GB) for these columns" if stopped else None)
        advice = "; ".join(a for a in (_axial_advice(sc), memory) if a)
        if advice:
            out["extras"]["advice"] = advice
    return sc


def _axial_advice(sc) -> str | None:
    """Why the finite volumes missed the tolerance, when the reason is the Peclet number."""
    n = sc.S.size
    v = np.ones(n) if sc.d is None else sc.d
    w = sc.dispersion if sc.dispersion is not None else (v if sc.kind == "axial_open" else np.ones(n))
    ratio = v / w
    pe = float(sc.transport.pe)
    if pe * float(ratio.max()) <= 16384:
        return None
    return (f"the finest grid (16384 volumes) does not resolve the largest class Peclet number Pe d*/dispersion "
            f"= {pe * float(ratio.max()):.3g}, and the plug-flow limit needs every class's Peclet number to be "
            f"large, here down to {pe * float(ratio.min()):.3g} (a class retained by classification breaks in a "
            "dispersion layer at the feed end); the estimate is honest")


#: Method name -> solver(scene, feed, out, *, tol, holdup, cache) -> scene. A solver fills
#: ``out`` and returns its scene, or a scene with another method to fall back to.
SOLVERS = {"well_mixed": _well_mixed, "cells": _cells, "plug_flow": _plug_flow, "segregated": _segregated,
           "quadrature": _quadrature, "composed": _composed, "axial_fv": _axial_fv}


def _solve(sc: _Scene, feed, *, tol: float, holdup: bool = True, cache: dict | None = None):
    """Dispatch to the method (:data:`SOLVERS`).

    Dispatch to the method (:data:`SOLVERS`). Returns dict with product, holdup,
    error, extras, method.

    ``cache`` (a Mill's) keeps the spectral decomposition of the breakage matrix
    between calls of the plug-flow and segregated paths.
    """
    out = {"extras": {}}
    nxt = SOLVERS[sc.method](sc, feed, out, tol=tol, holdup=holdup, cache=cache)
    while nxt.method != sc.method:  # a fallback (segregated -> axial_fv)
        sc = nxt
        nxt = SOLVERS[sc.method](sc, feed, out, tol=tol, holdup=holdup, cache=cache)
    out["method"] = sc.method
    return out


def _triangular_error(p) -> float:
    # forward substitution with an M-matrix: every entry has relative error ~ N eps
    return float(np.abs(p).max() * p.shape[0] * np.finfo(float).eps) if np.size(p) else 0.0


def transfer_matrix(S, b, transport, d=None, *, where=None, dispersion=None, discharge=None, method=None,
                    tol: float = 1e-8, on_inaccuracy: str = "raise") -> np.ndarray:
    """Transfer matrix P (N, N) of a linear mill: product = P @ feed.

    Columns sum to 1 (mass conserving). Perfect mixing and tanks in series are
    triangular solves with the identity as right-hand side (fast enough to build
    whole circuits from); segregated flow applies E_hat(-K) to the identity; axial
    dispersion with classification solves the discretised PDE for N right-hand sides
    (O(N^3 M), the slow one).

    Parameters
    ----------
    S : (N,) specific breakage rates [1/s], S_N = 0.
    b : (N, N) fractional breakage distribution.
    transport : rtd model, tau in s.
    d : (N,) normalised discharge rates d_i* > 0, or None (no classification).
    where, dispersion, discharge, method, tol, on_inaccuracy : as :func:`steady_mill` (each column is
        the product of a unit feed: its sum's distance from 1 is its mass-balance error).

    Examples
    --------
    >>> import numpy as np, rtd
    >>> P = transfer_matrix([1.0, 0.0], [[0, 0], [1, 0]], rtd.PerfectMixing(2.0))
    >>> P.round(6).tolist()
    [[0.333333, 0.0], [0.666667, 1.0]]
    """
    from millflow.mill.nonlinear_mill import is_kinetics

    if is_kinetics(S) and not S.is_linear:
        raise InputError("transfer_matrix: the kinetics are non-linear, so the product is not a matrix times the "
                         "feed; expected first-order kinetics, or steady_mill / Mill.product for one feed")
    if is_kinetics(S):
        from millflow.mill.nonlinear_mill import check_no_b

        check_no_b(S, b, "transfer_matrix")
        S, b = S.S, S.b
    sc = _scene(S, b, transport, d, where, dispersion, method, discharge)
    solved = _solve(sc, np.eye(sc.S.size), tol=tol, holdup=False)
    P = solved["product"]
    check_accuracy("transfer_matrix", solved["method"], float(np.max(np.abs(P.sum(axis=0) - 1.0))),
                   float(solved["error"]), tol, on_inaccuracy, solved["extras"].get("advice"))
    return P


# ------------------------------------------------------------------------ results
def _profile(sc: _Scene, feed, solved, positions):
    """Hold-up density tau c_i(z) [s] at fractional positions, or None."""
    if positions is None:
        return None
    pos = np.atleast_1d(np.asarray(positions, dtype=float))
    if pos.ndim != 1 or np.any(~np.isfinite(pos)) or np.any((pos < 0) | (pos > 1)):
        raise InputError(f"positions = {positions!r}; expected fractions of the mill length in [0, 1]")
    if sc.kind == "plug":
        from millflow.batch import batch_grind
        tau = _tau(sc.transport)
        rates = sc.S if sc.d is None else sc.S / sc.d
        flux = batch_grind(rates, sc.b, feed, tau * pos)
        return pos, tau * flux / (1.0 if sc.d is None else sc.d)
    if sc.kind in AXIAL_KINDS:
        sol = solved.get("axial")
        if sol is None:  # segregated product; the profile needs the PDE
            sol = _axial_solution(sc, feed, 1e-7)
        dens = np.stack([np.interp(pos, sol.z, sol.density[:, i]) for i in range(sc.S.size)], axis=1)
        return pos, dens
    raise InputError(f"positions are given but transport {sc.transport!r} has no axis; expected "
                     "rtd.PlugFlow or rtd.AxialDispersion (use locations 'cell:K' for cells)")


def steady_mill(S, b, feed, transport, d=None, *, where=None, dispersion=None, discharge=None, method=None,
                x=None, positions=None, locations=None, tol: float = 1e-8,
                on_inaccuracy: str = "raise") -> xr.Dataset:
    """Steady state of a continuous mill (eqs. 1-3 with any rtd transport).

    Parameters
    ----------
    S : (N,) specific breakage rates [1/s], coarse -> fine, S_N = 0 (sink); or a
        :class:`millflow.nonlinear.Kinetics` (non-linear kinetics, with b = None), solved by
        :mod:`millflow.mill.nonlinear` for every transport (:mod:`millflow.mill.nonlinear_mill`).
    b : (N, N) fractional breakage distribution b_ij (strictly lower triangular).
    feed : (N,) solids feed flows per class (any mass-rate unit, e.g. fractions of a
        unit feed rate); the product has the same unit.
    transport : an rtd model with tau in s (PerfectMixing, PlugFlow, TanksInSeries,
        RecirculatingCells, CompartmentNetwork, AxialDispersion, Series, Parallel, ...).
    d : (N,) normalised discharge rates d_i* = tau d_i > 0, or None.
    where : where classification acts: "discharge" (default for cells: exit flows),
        "cells" (every cell outlet), a sequence of 1-based cell numbers (the outlets of
        those cells), "axis" (plug flow and axial dispersion: axial velocity of class i
        is d_i* u).
    dispersion : (N,) relative axial dispersion of each class (AxialDispersion only; default 1
        for the closed vessel, d for the open one).
    discharge : open-vessel axial dispersion only: "sampled" (default; v c at z = 1, what
        the open density measures; needs one Peclet number Pe d_i*/dispersion_i for all
        classes) or "flux" (net flux through the discharge plane; any d, dispersion); see
        :mod:`millflow.mill.axial_open`.
    method : one of :data:`METHODS` to force a method (e.g. for cross-checks); None
        picks the cheapest exact one.
    x : (N,) upper class sizes [m] or a SizeGrid, for the ``size`` coordinate (also under its old name ``x``).
    positions : fractional axial positions in [0, 1] for profiles (plug, axial).
    locations : sampling locations ('discharge', 'feed', 'holdup', 'cell:K', 'z:Y'),
        a list or a dict name -> spec; gives variable ``sample`` (location, size).
    tol : tolerance relative to the total feed: the discretised paths refine until their
        error estimate (max abs error of the product) is below it, and every path's
        mass-balance error and error estimate are checked against it.
    on_inaccuracy : "raise" (default): a result above ``tol`` raises SolverError;
        "warn": it is returned with an AccuracyWarning.

    Returns
    -------
    xarray.Dataset with ``product`` and ``product_fraction`` (size), ``feed``,
    ``holdup`` [s] (hold-up per unit feed rate) and ``holdup_fraction``; for cells
    ``cell_holdup`` (cell, size) [s]; with positions ``profile`` (position, size) [s]
    (hold-up density per unit fractional length) and ``profile_fraction``; with
    locations ``sample``. Attributes ``method``, ``error_estimate``, ``runtime_s``,
    ``mass_balance_error``, ``transport``, ``classification``.

    Examples
    --------
    >>> import rtd
    >>> ds = steady_mill([1.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], rtd.PerfectMixing(2.0))
    >>> ds.attrs["method"], round(float(ds["product"][0]), 6)
    ('well_mixed', 0.333333)
    """
    from millflow.mill.nonlinear_mill import is_kinetics

    if is_kinetics(S) and S.is_linear:  # first-order kinetics as a Kinetics object: the linear mill
        from millflow.mill.nonlinear_mill import check_no_b

        check_no_b(S, b, "steady_mill")
        S, b = S.S, S.b
    elif is_kinetics(S):  # non-linear kinetics (millflow.nonlinear.Kinetics, b = None): their own solvers
        from millflow.mill.nonlinear_mill import steady_dataset

        return steady_dataset(S, b, feed, transport, d, where=where, dispersion=dispersion, discharge=discharge,
                              method=method, x=x, positions=positions, locations=locations, tol=tol,
                              on_inaccuracy=on_inaccuracy)
    start = time.perf_counter()
    sc = _scene(S, b, transport, d, where, dispersion, method, discharge)
    feed = _check_feed(feed, sc.S.size)
    if feed.ndim != 1:
        raise InputError(f"feed has shape {feed.shape}; expected ({sc.S.size},) (use transfer_matrix for many feeds)")
    # linear in the feed: solve for the feed scaled to a unit total and scale back, so the
    # accuracy does not depend on the feed's unit or size
    total = float(np.abs(feed).sum())
    scale = total if 0 < total < np.inf else 1.0
    solved = _solve(sc, feed / scale, tol=tol)
    prof = _profile(sc, feed / scale, solved, positions)
    check_accuracy("steady_mill", solved["method"], abs(solved["product"].sum() - feed.sum() / scale),
                   float(solved["error"]), tol, on_inaccuracy, solved["extras"].get("advice"))
    runtime = time.perf_counter() - start
    product, holdup = solved["product"] * scale, solved["holdup"] * scale
    if "cell_holdup" in solved:
        solved["cell_holdup"] = solved["cell_holdup"] * scale
    if prof is not None:
        prof = (prof[0], prof[1] * scale)
    data = {
        "feed": ("size", feed, {"units": "feed units", "long_name": "feed flow"}),
        "product": ("size", product, {"units": "feed units", "long_name": "product (discharge) flow"}),
        "product_fraction": ("size", _fractions(product), {"units": "1", "long_name": "product mass fraction"}),
        "holdup": ("size", holdup, {"units": "s", "long_name": "hold-up per unit feed rate"}),
        "holdup_fraction": ("size", _fractions(holdup), {"units": "1", "long_name": "hold-up mass fraction"}),
    }
    coords = _size_coords(sc.S.size, x)
    if "cell_holdup" in solved:
        data["cell_holdup"] = (("cell", "size"), solved["cell_holdup"],
                               {"units": "s", "long_name": "hold-up of each cell per unit feed rate"})
        n_cells = solved["cell_holdup"].shape[0]
        coords["cell"] = ("cell", np.arange(1, n_cells + 1), {"long_name": "cell (1 = feed end)"})
    if prof is not None:
        coords["position"] = ("position", prof[0], {"units": "1", "long_name": "y / L"})
        data["profile"] = (("position", "size"), prof[1],
                           {"units": "s", "long_name": "hold-up density per unit feed rate and fractional length"})
        data["profile_fraction"] = (("position", "size"), _fractions(prof[1]),
                                    {"units": "1", "long_name": "local hold-up mass fraction"})
    attrs = dict(
        method=solved["method"],
        error_estimate=float(solved["error"]) * scale,
        solver_error_estimate=float(solved["error"]) * scale,
        grid_error_estimate=0.0,
        grid_error_method=_GRID_NOTE,
        runtime_s=float(runtime),
        mass_balance_error=float(abs(product.sum() - feed.sum())),
        transport=repr(transport),
        classification="none" if sc.d is None else f"d* at {sc.where}",
        tau_s=_tau(transport),
    )
    ds = dataset(data, coords, attrs)  # the Dataset xr.Dataset would build, without its merge and alignment
    for key, value in solved["extras"].items():
        ds.attrs[key] = value if not isinstance(value, list) else str(value)
    if locations is not None:
        ds["sample"] = _samples(ds, locations)
    return ds
