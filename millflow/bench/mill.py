"""Benchmark of the continuous mill: error against run time for every path.

One kernel at N = 100 classes (2^(1/4) grid, power-law rates eq. 5 with alpha = 1 and
tau S_1 = 100, normalized B eq. 6: phi 0.4, gamma 0.8, beta 3; feed in the three top
classes; tau = 600 s). Tables:

- ``paths``: every steady path (well_mixed, cells, plug_flow, segregated, composed) timed four
  ways: ``steady_mill`` (validation + solve + xarray Dataset), a new
  ``Mill(...).product`` (validation + solve), a repeated ``Mill.product`` (validated
  once, spectral decomposition kept: the inner loop when only the feed or the RTD
  changes) and ``transfer_matrix``. The
  error is the difference to an independent exact route (dense LU of eq. 3, segregated
  flow for cells, a dense block solve, scipy expm for plug flow, the converged finite
  volumes for axial dispersion); ``ratio_vs_baseline`` = Mill.product time / the time
  of that generic route.
- ``axial``: axial dispersion (Pe 10) with classification, error against the number of
  control volumes, single grids and the Richardson-adaptive solver at several
  tolerances. The classification scales velocity and dispersion by d* (coarse classes
  at 0.3), which has an exact reference: segregated flow with rates S/d*.
  Also velocity-only classification against its own converged solution, and the open
  vessel on the whole line (:mod:`millflow.mill.axial_open`): sampled discharge with
  v = w = d* against segregated flow with the open density and rates S/d*, flux
  discharge with velocity-only classification against its own converged solution.
- ``targets``: the issue's goals (0.5 ms linear mills, 100 ms axial at 1e-6, 20 ms for
  a tanks-in-series transfer matrix used in a circuit).
"""
from __future__ import annotations

import statistics
import time

import numpy as np
import scipy.linalg

import rtd
from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid
from millflow.linalg import breakage_matrix
from millflow.mill import Mill, steady_mill, transfer_matrix
from millflow.mill.axial import solve_axial, solve_axial_grid
from millflow.mill.axial_open import solve_axial_open
from millflow.mill.segregated import segregated

__all__ = ["DESCRIPTION", "run", "format_table", "kernel"]

DESCRIPTION = "continuous mill: error vs run time of every transport path, axial cells vs error"

TAU = 600.0
N_CLASSES = 100
#: Austin's mill: plug flow then one large and two small perfect mixers.
AUSTIN = rtd.Series(rtd.PlugFlow(100.0), rtd.PerfectMixing(300.0), rtd.PerfectMixing(100.0),
                    rtd.PerfectMixing(100.0))


def kernel(n: int = N_CLASSES):
    """(x, S, b, feed) of the benchmark mill."""
    grid = SizeGrid.geometric(1e-2, 2**0.25, n)
    S = power_law_rates(grid.x, 100.0 / TAU, 1.0, grid.x[0])
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return grid.x, S, b, feed


def _time(fn, repeats: int) -> float:
    fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def _dense_block_cells(S, b, f, net):
    """Generic route: the whole (n N) block system as one dense solve."""
    n, N = net.n, S.size
    A = net.system_matrix()
    K = breakage_matrix(S, b)
    J = np.kron(np.eye(N), A) + np.kron(K, np.eye(n))
    g = np.kron(f, (1 - net.bypass) * net.inlet)
    m = np.linalg.solve(-J, g)
    return (m.reshape(N, n) @ (net.outlet / net.volumes)) + net.bypass * f


def _paths(quick: bool) -> list[dict]:
    x, S, b, f = kernel()
    reps = 5 if quick else 30
    K = breakage_matrix(S, b)
    rows = []
    cases = [
        ("perfect_mixing", rtd.PerfectMixing(TAU), "dense LU of eq. 3",
         lambda: np.linalg.solve(np.eye(S.size) - TAU * K, f)),
        ("tanks_in_series_10", rtd.TanksInSeries(TAU, 10), "dense block solve (nN)",
         lambda: _dense_block_cells(S, b, f, rtd.TanksInSeries(TAU, 10).network())),
        ("recirculating_5_r1", rtd.RecirculatingCells(TAU, 5, r=1.0), "dense block solve (nN)",
         lambda: _dense_block_cells(S, b, f, rtd.RecirculatingCells(TAU, 5, r=1.0).network())),
        ("plug_flow", rtd.PlugFlow(TAU), "scipy.linalg.expm(K tau) f",
         lambda: scipy.linalg.expm(K * TAU) @ f),
        ("axial_pe10", rtd.AxialDispersion(TAU, 10.0), "finite volumes, tol 1e-10",
         lambda: solve_axial(S, b, f, TAU, 10.0, tol=1e-10).product),
        ("austin_series", AUSTIN, "segregated flow (eigenbasis)",
         lambda: steady_mill(S, b, f, AUSTIN, method="segregated")["product"].values),
        ("open_axial_pe5", rtd.AxialDispersion(TAU, 5.0, bc="open"), "quadrature of E(t) exp(Kt) f",
         lambda: steady_mill(S, b, f, rtd.AxialDispersion(TAU, 5.0, bc="open"), method="quadrature")["product"].values),
    ]
    for case, model, ref_name, ref_fn in cases:
        ds = steady_mill(S, b, f, model, x=x)
        p = ds["product"].values
        if ref_fn is None:  # no independent exact route: the error estimate only
            ref, t_ref = p, float("nan")
        else:
            ref = ref_fn()
            t_ref = _time(ref_fn, max(3, reps // 5))
        mill = Mill(S, b, model, x=x)
        t_full = _time(lambda: steady_mill(S, b, f, model), reps)
        t_prod = _time(lambda: mill.product(f), reps)
        t_first = _time(lambda: Mill(S, b, model).product(f), reps)
        t_tm = _time(lambda: transfer_matrix(S, b, model), max(3, reps // 3))
        rows.append({
            "table": "paths", "case": case, "method": ds.attrs["method"], "n_classes": S.size,
            "runtime_s": t_full, "product_runtime_s": t_prod, "first_product_runtime_s": t_first,
            "transfer_matrix_runtime_s": t_tm,
            "max_abs_error": float(np.abs(p - ref).max()) if ref_fn is not None else float("nan"),
            "reference": ref_name,
            "error_estimate": ds.attrs["error_estimate"],
            "mass_balance_error": ds.attrs["mass_balance_error"], "min_value": float(p.min()),
            "ratio_vs_baseline": t_prod / t_ref if np.isfinite(t_ref) else float("nan"),
        })
    return rows


def _axial(quick: bool) -> list[dict]:
    x, S, b, f = kernel()
    d = np.where(x > 1e-3, 0.3, 1.0)
    pe = 10.0
    exact = segregated(S / d, b, f, rtd.AxialDispersion(TAU, pe), holdup=False)[0]
    reps = 2 if quick else 5
    rows = []
    grids = (16, 32, 64, 128, 256) if quick else (16, 32, 64, 128, 256, 512, 1024)
    errors = []
    for m in grids:
        p = solve_axial_grid(S, b, f, TAU, pe, m, d, d)[2]
        errors.append(float(np.abs(p - exact).max()))
        rows.append({"table": "axial", "case": "v=w=d*, Pe 10", "method": "fv single grid", "n_classes": S.size,
                     "control_volumes": m, "max_abs_error": errors[-1],
                     "observed_order": float(np.log2(errors[-2] / errors[-1])) if len(errors) > 1 else float("nan"),
                     "runtime_s": _time(lambda: solve_axial_grid(S, b, f, TAU, pe, m, d, d), reps),
                     "mass_balance_error": float(abs(p.sum() - f.sum()))})
    for tol in (1e-4, 1e-6, 1e-8):
        sol = solve_axial(S, b, f, TAU, pe, d, d, tol=tol)
        rows.append({"table": "axial", "case": "v=w=d*, Pe 10", "method": f"fv Richardson tol {tol:g}",
                     "n_classes": S.size, "control_volumes": int(sol.z.size - 1),
                     "max_abs_error": float(np.abs(sol.product - exact).max()),
                     "error_estimate": sol.error_estimate, "observed_order": sol.order,
                     "runtime_s": _time(lambda: solve_axial(S, b, f, TAU, pe, d, d, tol=tol), reps),
                     "mass_balance_error": float(abs(sol.product.sum() - f.sum()))})
    # velocity-only classification (the general case): against its own converged answer
    ref = solve_axial(S, b, f, TAU, pe, d, tol=1e-10).product
    for tol in (1e-6, 1e-8):
        ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe), d, tol=tol)
        rows.append({"table": "axial", "case": "v=d*, Pe 10", "method": f"steady_mill axial_fv tol {tol:g}",
                     "n_classes": S.size, "control_volumes": int(ds.attrs["control_volumes"]),
                     "max_abs_error": float(np.abs(ds["product"].values - ref).max()),
                     "error_estimate": ds.attrs["error_estimate"], "observed_order": ds.attrs["order"],
                     "runtime_s": _time(lambda: steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe), d, tol=tol), reps),
                     "mass_balance_error": ds.attrs["mass_balance_error"]})
    # the open vessel on the whole line: v = w = d* against segregated flow with the open
    # density and rates S/d*; the flux discharge with velocity-only classification against
    # its own converged answer
    open_vessel = rtd.AxialDispersion(TAU, pe, bc="open")
    exact_open = segregated(S / d, b, f, open_vessel, holdup=False)[0]
    cases = [("open v=w=d*, Pe 10", "sampled", None, exact_open)]
    ref_flux = solve_axial_open(S, b, f, TAU, pe, d, np.ones(S.size), discharge="flux", tol=1e-10).product
    cases.append(("open v=d*, Pe 10", "flux", np.ones(S.size), ref_flux))
    for case, discharge, w, ref in cases:
        for tol in (1e-6, 1e-8):
            sol = solve_axial_open(S, b, f, TAU, pe, d, w, discharge=discharge, tol=tol)
            rows.append({"table": "axial", "case": case, "method": f"open fv {discharge} tol {tol:g}",
                         "n_classes": S.size, "control_volumes": int(sol.z.size - 1),
                         "max_abs_error": float(np.abs(sol.product - ref).max()),
                         "error_estimate": sol.error_estimate, "observed_order": sol.order,
                         "runtime_s": _time(lambda: solve_axial_open(S, b, f, TAU, pe, d, w, discharge=discharge,
                                                                     tol=tol), reps),
                         "mass_balance_error": float(abs(sol.product.sum() - f.sum()))})
    return rows


def _targets(paths: list[dict], axial: list[dict], quick: bool) -> list[dict]:
    rows = []
    by_case = {r["case"]: r for r in paths}
    # the segregated-flow target on axial dispersion without classification (method segregated)
    for case, label in (("perfect_mixing", "perfect_mixing"), ("tanks_in_series_10", "tanks_in_series_10"),
                        ("axial_pe10", "segregated (axial_pe10)")):
        r = by_case[case]
        for which, key in (("new Mill(...).product", "first_product_runtime_s"),
                           ("Mill.product, repeated", "product_runtime_s")):
            rows.append({"table": "targets", "case": f"{label} N=100 < 0.5 ms ({which})", "method": r["method"],
                         "runtime_s": r[key], "steady_mill_runtime_s": r["runtime_s"],
                         "target_s": 5e-4, "met": bool(r[key] < 5e-4)})
    r = next(r for r in axial if r["method"] == "fv Richardson tol 1e-06")
    rows.append({"table": "targets", "case": "axial + classification N=100 err < 1e-6 < 100 ms",
                 "method": r["method"], "runtime_s": r["runtime_s"], "max_abs_error": r["max_abs_error"],
                 "target_s": 0.1, "met": bool(r["runtime_s"] < 0.1 and r["max_abs_error"] < 1e-6)})
    r = by_case["tanks_in_series_10"]
    rows.append({"table": "targets", "case": "transfer_matrix tanks in series n=10 N=100 < 20 ms",
                 "method": "cells", "runtime_s": r["transfer_matrix_runtime_s"], "target_s": 0.02,
                 "met": bool(r["transfer_matrix_runtime_s"] < 0.02)})
    return rows


def run(quick: bool = False) -> list[dict]:
    """All rows of the three tables (see the module docstring)."""
    paths = _paths(quick)
    axial = _axial(quick)
    return paths + axial + _targets(paths, axial, quick)


def _f(v, spec, width):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return f"{'-':>{width}}"
    return f"{v:>{width}{spec}}"


def format_table(rows: list[dict]) -> str:
    """Fixed-width text of the three tables (times in ms)."""
    out = ["Steady paths, N = 100 (ms; error vs an independent exact route)"]
    head = (f"{'case':<20}{'method':<12}{'steady_mill':>12}{'1st prod':>9}{'product':>9}{'P matrix':>10}"
            f"{'max_err':>10}{'mass_err':>10}{'ratio':>8}  reference")
    out += [head, "-" * len(head)]
    for r in rows:
        if r.get("table") == "paths":
            out.append(f"{r['case']:<20}{r['method']:<12}{_f(r['runtime_s'] * 1e3, '.3f', 12)}"
                       f"{_f(r['first_product_runtime_s'] * 1e3, '.3f', 9)}"
                       f"{_f(r['product_runtime_s'] * 1e3, '.3f', 9)}"
                       f"{_f(r['transfer_matrix_runtime_s'] * 1e3, '.2f', 10)}"
                       f"{_f(r['max_abs_error'], '.1e', 10)}{_f(r['mass_balance_error'], '.1e', 10)}"
                       f"{_f(r['ratio_vs_baseline'], '.3f', 8)}  {r['reference']}")
    out += ["", "Axial dispersion with classification, N = 100 (control volumes vs error)"]
    head = f"{'case':<20}{'method':<32}{'cells':>7}{'max_err':>10}{'estimate':>10}{'order':>7}{'ms':>9}{'mass_err':>10}"
    out += [head, "-" * len(head)]
    for r in rows:
        if r.get("table") == "axial":
            out.append(f"{r['case']:<20}{r['method']:<32}{r['control_volumes']:>7}{_f(r['max_abs_error'], '.1e', 10)}"
                       f"{_f(r.get('error_estimate'), '.1e', 10)}{_f(r.get('observed_order'), '.2f', 7)}"
                       f"{_f(r['runtime_s'] * 1e3, '.2f', 9)}{_f(r['mass_balance_error'], '.1e', 10)}")
    out += ["", "Targets"]
    for r in rows:
        if r.get("table") == "targets":
            out.append(f"  {r['case']:<75} {r['runtime_s'] * 1e3:8.3f} ms  {'met' if r['met'] else 'NOT met'}")
    return "\n".join(out)
