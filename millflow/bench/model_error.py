"""Benchmark suite ``model-error``: the non-linear kinetics and mills.

One kernel at N = 100 classes (2^(1/4) grid from 10 mm, power-law rates eq. 5 with
alpha = 1 and tau S_1 = 100, normalized B eq. 6: phi 0.4, gamma 0.8, beta 3, feed in the
three top classes, tau = 600 s) with constant-kernel aggregation (beta0 = 1e-3 1/s, volumes
in units of the sink size cubed) and, for the mills, fines cushioning
S_i = k_i (1 + F)^(-1), F the mass below 1/30 of the top size. Tables:

- ``targets``: the issue's goals. Batch breakage + aggregation to <= 1e-8 (< 50 ms): the
  error is against a reference solve of the same discrete equations (Radau, rtol 1e-13)
  -- the exact solutions of :mod:`millflow.nonlinear.exact` validate the discretisation
  in the tests (second order in the grid ratio), a benchmark at 1e-8 can only be against
  the discrete system. Linear kinetics through the same API against batch_solve itself
  (ratio ~1: no cost added). Perfectly mixed mill with aggregation and cushioning, Newton
  to 1e-12 (< 10 ms), tanks in series 10 cells (< 50 ms); ratios against the linear
  exact solve of the same mill (the baseline).
- ``work_precision``: error against run time of the batch ODE (BDF, Radau) over
  tolerances, of the axial-dispersion Newton over the number of volumes (error against
  a grid refined to 1e-11), and the micromixing limits.
- ``speed``: the non-linear mills against the code at commit 43330ce, kept as a faithful
  copy in :mod:`millflow.bench._nonlinear_baseline` (full Newton, a fresh Jacobian and LU at
  every iteration, the population Jacobian by an N^3 product, axial nodes in a Python loop
  with one LU and one inverse per node): perfect mixer and 10 tanks in series at N = 100,
  axial dispersion Pe 10 on 64 volumes (checked against 32) at N = 40 and N = 100. CPU
  time, median of interleaved rounds (baseline, new, baseline, new, ...) in one process;
  ``speedup`` = baseline / new, ``max_abs_error`` the two answers' difference.
"""
from __future__ import annotations

import statistics
import time

import numpy as np

DESCRIPTION = ("non-linear kinetics and mills: batch + aggregation, PM and TIS Newton, work-precision, speed "
               "against the 43330ce code")

TAU = 600.0
N = 100
#: tolerances of the batch target row: the loosest that meets 1e-8 against the reference
BATCH_RTOL, BATCH_ATOL = 1e-6, 1e-10
BATCH_METHOD = f"LSODA rtol {BATCH_RTOL:g} atol {BATCH_ATOL:g}"  # batch_nonlinear's default method
TARGETS_MS = {"batch_aggregation": 50.0, "well_mixed_nonlinear": 10.0, "tanks10_nonlinear": 50.0}


def scene(n: int = N, beta0: float = 1e-3, cushion: bool = True):
    """(grid, kinetics, linear kinetics, feed) of the benchmark."""
    from millflow.breakage import b_from_B, normalized_B, power_law_rates
    from millflow.grid import SizeGrid
    from millflow.nonlinear import Aggregation, constant_kernel, kinetics

    grid = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    S = power_law_rates(grid.x, 100.0 / TAU, 1.0, grid.x[0])
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    w = None
    if cushion:
        w = np.zeros((n, n))
        w[:, grid.x <= grid.x[0] / 30] = 1.0
    kin = kinetics(S, b, w=w, lam=-1.0 if cushion else 0.0,
                   aggregation=Aggregation(constant_kernel(beta0), grid.x[-1]), grid=grid)
    return grid, kin, kinetics(S, b), feed


def _time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        if sum(times) > 3.0:
            break
    return statistics.median(times), min(times), out


def targets(quick: bool) -> list[dict]:
    from millflow.batch import batch_solve
    from millflow.mill.well_mixed import solve_well_mixed
    from millflow.mill import nonlinear as nl
    from millflow.nonlinear import batch_nonlinear

    reps = 3 if quick else 9
    rows = []
    grid, kin_b, lin, feed = scene(cushion=False)
    t = [TAU]
    ref = batch_nonlinear(kin_b, feed, t, method="Radau", rtol=1e-13, atol=1e-17, error_estimate=False).M
    med, mn, res = _time(lambda: batch_nonlinear(kin_b, feed, t, rtol=BATCH_RTOL, atol=BATCH_ATOL,
                                                 error_estimate=False), reps)
    base, _, _ = _time(lambda: batch_solve(lin.S, lin.b, feed, t), reps)
    rows.append({"table": "targets", "case": "batch_aggregation", "method": BATCH_METHOD, "n_classes": N,
                 "runtime_s": med, "min_s": mn, "max_abs_error": float(np.abs(res.M - ref).max()),
                 "mass_balance_error": res.mass_balance_error, "target_ms": TARGETS_MS["batch_aggregation"],
                 "ratio_vs_baseline": med / base, "baseline": "linear exact batch_solve"})
    med2, mn2, res2 = _time(lambda: batch_nonlinear(kin_b, feed, t, rtol=BATCH_RTOL, atol=BATCH_ATOL), reps)
    rows.append({"table": "targets", "case": "batch_aggregation", "method": BATCH_METHOD + " + error estimate",
                 "n_classes": N, "runtime_s": med2, "min_s": mn2, "max_abs_error": float(np.abs(res2.M - ref).max()),
                 "error_estimate": res2.error_estimate, "mass_balance_error": res2.mass_balance_error,
                 "ratio_vs_baseline": med2 / base, "baseline": "linear exact batch_solve"})
    med3, mn3, res3 = _time(lambda: batch_nonlinear(lin, feed, t), reps * 5)
    base3, _, r3 = _time(lambda: batch_solve(lin.S, lin.b, feed, t), reps * 5)
    rows.append({"table": "targets", "case": "batch_linear_same_api", "method": res3.method, "n_classes": N,
                 "runtime_s": med3, "min_s": mn3, "max_abs_error": float(np.abs(res3.M - r3.M).max()),
                 "mass_balance_error": res3.mass_balance_error, "ratio_vs_baseline": med3 / base3,
                 "baseline": "batch_solve directly"})
    grid, kin, lin, feed = scene()
    base_pm, _, _ = _time(lambda: solve_well_mixed(lin.S, lin.b, feed, TAU), reps * 5)
    med, mn, r = _time(lambda: nl.well_mixed(kin, feed, TAU), reps)
    rows.append({"table": "targets", "case": "well_mixed_nonlinear", "method": r.method, "n_classes": N,
                 "runtime_s": med, "min_s": mn, "residual": r.residual, "max_abs_error": r.error_estimate,
                 "iterations": r.iterations, "mass_balance_error": r.mass_balance_error,
                 "target_ms": TARGETS_MS["well_mixed_nonlinear"], "ratio_vs_baseline": med / base_pm,
                 "baseline": "linear exact perfect mixer"})
    med, mn, r = _time(lambda: nl.tanks_in_series(kin, feed, TAU, 10), reps)
    rows.append({"table": "targets", "case": "tanks10_nonlinear", "method": r.method, "n_classes": N,
                 "runtime_s": med, "min_s": mn, "residual": r.residual, "max_abs_error": r.error_estimate,
                 "iterations": r.iterations, "mass_balance_error": r.mass_balance_error,
                 "target_ms": TARGETS_MS["tanks10_nonlinear"], "ratio_vs_baseline": med / (10 * base_pm),
                 "baseline": "10 linear exact perfect mixers"})
    return rows


def work_precision(quick: bool) -> list[dict]:
    import rtd
    from millflow.mill import nonlinear as nl
    from millflow.nonlinear import batch_nonlinear

    rows = []
    grid, kin, lin, feed = scene()
    t = [TAU]
    ref = batch_nonlinear(kin, feed, t, method="Radau", rtol=1e-13, atol=1e-17, error_estimate=False).M
    rtols = (1e-4, 1e-8) if quick else (1e-4, 1e-6, 1e-8, 1e-10)
    for method in ("BDF", "Radau"):
        for rtol in rtols:
            med, _, r = _time(lambda: batch_nonlinear(kin, feed, t, method=method, rtol=rtol, atol=rtol * 1e-4,
                                                      error_estimate=False), 1 if quick else 3)
            rows.append({"table": "work_precision", "case": "batch_nonlinear", "method": f"{method} rtol {rtol:g}",
                         "rtol": rtol,
                         "n_classes": N, "runtime_s": med, "max_abs_error": float(np.abs(r.M - ref).max()),
                         "mass_balance_error": r.mass_balance_error})
    n_ax = 40
    grid, kin, lin, feed = scene(n_ax)
    fine = nl.axial_dispersion(kin, feed, TAU, 10.0, tol=1e-9 if quick else 1e-11).product
    for m in (8, 16, 32) if quick else (8, 16, 32, 64):
        t0 = time.perf_counter()
        r = nl.axial_dispersion(kin, feed, TAU, 10.0, m_cells=m)
        rows.append({"table": "work_precision", "case": "axial_nonlinear_Pe10", "method": f"{m} volumes, Newton",
                     "n_classes": n_ax, "runtime_s": time.perf_counter() - t0,
                     "max_abs_error": float(np.abs(r.product - fine).max()), "error_estimate": r.error_estimate,
                     "residual": r.residual, "iterations": r.iterations, "mass_balance_error": r.mass_balance_error})
    for tol in (1e-6, 1e-8):
        t0 = time.perf_counter()
        r = nl.axial_dispersion(kin, feed, TAU, 10.0, tol=tol)
        rows.append({"table": "work_precision", "case": "axial_nonlinear_Pe10",
                     "method": f"refined to {tol:g} ({r.info['control_volumes']} volumes)", "n_classes": n_ax,
                     "runtime_s": time.perf_counter() - t0, "max_abs_error": float(np.abs(r.product - fine).max()),
                     "error_estimate": r.error_estimate, "mass_balance_error": r.mass_balance_error})
    grid, kin, lin, feed = scene()
    for model in (rtd.PerfectMixing(TAU), rtd.TanksInSeries(TAU, 3)):
        t0 = time.perf_counter()
        mm = nl.micromixing_limits(kin, feed, model)
        rows.append({"table": "work_precision", "case": f"micromixing_{type(model).__name__}",
                     "method": "segregation + Zwietering", "n_classes": N, "runtime_s": time.perf_counter() - t0,
                     "max_abs_error": mm.error_estimate, "spread": mm.spread,
                     "mass_balance_error": float(abs(mm.max_mixedness.sum() + mm.info["overflow"][1] - 1.0))})
    return rows


def _interleaved(fns: dict, rounds: int):
    """CPU time [s] of each callable: medians over ``rounds`` interleaved rounds (one call of
    each per round, in turn), and each one's last result."""
    times = {k: [] for k in fns}
    out = {}
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.process_time()
            out[k] = fn()
            times[k].append(time.process_time() - t0)
    return {k: statistics.median(v) for k, v in times.items()}, out


def speed(quick: bool) -> list[dict]:
    """The non-linear mills against the 43330ce code (module docstring)."""
    from millflow.bench import _nonlinear_baseline as old
    from millflow.mill import nonlinear as nl

    rows = []
    grid, kin, lin, feed = scene()
    cases = [("well_mixed_nonlinear", N, lambda: old.well_mixed(kin, feed, TAU), lambda: nl.well_mixed(kin, feed, TAU)),
             ("tanks10_nonlinear", N, lambda: old.tanks_in_series(kin, feed, TAU, 10),
              lambda: nl.tanks_in_series(kin, feed, TAU, 10))]
    for n_ax in (40,) if quick else (40, N):
        g, k_ax, _, f_ax = scene(n_ax)
        cases.append((f"axial_Pe10_64_volumes_N{n_ax}", n_ax,
                      lambda k=k_ax, f=f_ax: old.axial_dispersion(k, f, TAU, 10.0, m_cells=64),
                      lambda k=k_ax, f=f_ax: nl.axial_dispersion(k, f, TAU, 10.0, m_cells=64)))
    for case, n, base, new in cases:
        rounds = 3 if quick else (11 if n == N and "axial" not in case else 5)
        med, out = _interleaved({"base": base, "new": new}, rounds)
        r = out["new"]
        rows.append({"table": "speed", "case": case, "method": r.method, "n_classes": n, "runtime_s": med["new"],
                     "baseline_s": med["base"], "speedup": med["base"] / med["new"],
                     "ratio_vs_baseline": med["new"] / med["base"],
                     "baseline": "43330ce algorithms (millflow.bench._nonlinear_baseline), interleaved CPU time",
                     "max_abs_error": float(np.abs(r.product - out["base"].product).max()),
                     "error_estimate": r.error_estimate, "iterations": r.iterations,
                     "factorizations": r.info.get("factorizations"), "mass_balance_error": r.mass_balance_error})
    return rows


def run(quick: bool = False) -> list[dict]:
    return targets(quick) + work_precision(quick) + speed(quick)


def _f(v, spec):
    return "-" if v is None else format(v, spec)


def format_table(rows) -> str:
    out = [f"{'table':<15} {'case':<28} {'method':<32} {'ms':>9} {'error':>9} {'target ms':>9} {'x baseline':>10} "
           f"{'speedup':>8}"]
    for r in rows:
        out.append(f"{r['table']:<15} {r['case'][:28]:<28} {r['method'][:32]:<32} {1e3 * r['runtime_s']:9.2f} "
                   f"{_f(r.get('max_abs_error'), '9.1e')} {_f(r.get('target_ms'), '9.0f')} "
                   f"{_f(r.get('ratio_vs_baseline'), '10.2f')} {_f(r.get('speedup'), '8.2f')}")
    return "\n".join(out)
