"""Benchmark of per-case costs: percentile sizes, steady_mill's overhead, populations.

Every row times a method and its baseline in the same process, in interleaved rounds
(median of the rounds), with one BLAS thread, as CPU time of the process
(``time.process_time``: on a loaded machine wall time mostly measures the wait for a
core; with one BLAS thread CPU time is the work):

- ``percentile sizes``: P80 and P50 of a PSD on N = 100 classes by
  :func:`millflow.psd.percentile_sizes` against the same reading built the plain way
  (numpy's cubic fit through the four edges around the crossing, or scipy's
  ``PchipInterpolator`` in ln x where that cubic is not monotone, and Brent's root finder
  per percentile; the largest relative difference of the sizes is reported);
- ``steady_mill overhead``: :func:`millflow.mill.steady_mill` of a perfectly mixed mill
  at N = 50 minus the bare triangular solve
  (:func:`millflow.mill.well_mixed.solve_well_mixed`), target <= 0.1 ms; the same for
  the fast path :meth:`millflow.mill.Mill.product` (validated once, no Dataset);
- ``sweep case``: the cases of a 10 x 10 grid (mill tau x cyclone d50c on the closed
  circuit of ``millflow bench sweep``) as a sweep's chunk runs them (:class:`millflow.sweep.CaseSolver`:
  base flowsheet built once per round, the changed units rebuilt, each variant once, the
  case solved and reduced to its key figures, the chunk in one single-threaded BLAS
  context) against :func:`millflow.flowsheet.solve` of each case's flowsheet built
  beforehand (the bare solve), target <= 1.2x per case; also against those solves inside
  one BLAS thread limit (the solve's work alone);
- ``population``: :func:`millflow.mill.steady_population` of P = 2,000 rate vectors at
  N = 100 in mills per second (targets: >= 1e6 perfect mixing, >= 1e5 tanks in series),
  and of P = 200 for the transports solved by segregated flow or cell networks (plug
  flow, axial dispersion, recirculating cells, non-integer tanks in series), against
  steady_mill called member by member; ``max_rel_diff`` compares the products of 20
  members with steady_mill's.
"""
from __future__ import annotations

import math
import os
import statistics
import time

import numpy as np

__all__ = ["DESCRIPTION", "run", "format_table"]

DESCRIPTION = "per case: percentile sizes, steady_mill overhead, population solves (mills/s)"
TARGET_OVERHEAD_S = 1e-4
TARGET_SWEEP_RATIO = 1.2
TARGET_MILLS_PER_S = {"perfect mixing": 1e6, "tanks in series n=3": 1e5, "tanks in series n=10": 1e5}


def _populations():
    import rtd

    return (("perfect mixing", rtd.PerfectMixing(600.0)), ("tanks in series n=3", rtd.TanksInSeries(600.0, 3)),
            ("tanks in series n=10", rtd.TanksInSeries(600.0, 10)), ("plug flow", rtd.PlugFlow(600.0)),
            ("axial dispersion Pe 8", rtd.AxialDispersion(600.0, 8.0)),
            ("recirculating cells 4, r 1", rtd.RecirculatingCells(600.0, 4, 1.0)),
            ("tanks in series n=2.5", rtd.TanksInSeries(600.0, 2.5)))


def _interleaved(funs: dict, rounds: int, inner: int) -> dict:
    times = {k: [] for k in funs}
    for f in funs.values():
        f()
    for _ in range(rounds):
        for k, f in funs.items():
            t0 = time.process_time()
            for _ in range(inner):
                f()
            times[k].append((time.process_time() - t0) / inner)
    return {k: statistics.median(v) for k, v in times.items()}


def _scene(n, members=0, seed=0):
    from millflow.breakage import b_from_B, normalized_B, power_law_rates
    from millflow.grid import SizeGrid

    g = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    b = b_from_B(normalized_B(g.x, 0.4, 0.8, 3.0))
    S = power_law_rates(g.x, 0.05, 1.0, g.x[0])
    S[-1] = 0.0
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    if members:
        rng = np.random.default_rng(seed)
        S = S * rng.uniform(0.3, 3.0, (members, 1))
        S[:, -1] = 0.0
    return g, S, b, feed


def _old_percentile(x, f, percent):
    """The same reading built the plain way: numpy's cubic fit through the four edges
    around the crossing where it is monotone there (else scipy's PCHIP), each with an
    interpolant object and Brent's root finder."""
    from scipy.interpolate import PchipInterpolator
    from scipy.optimize import brentq

    P = np.cumsum(f[::-1])[::-1]
    P[0] = 1.0
    q = percent / 100
    k = int(np.flatnonzero(P >= q)[-1])
    u = np.log(x)
    fun = None
    if 1 <= k and k + 2 <= P.size - 1:
        c = np.polyfit(u[k - 1:k + 3] - u[k + 1], P[k - 1:k + 3], 3)
        t = np.linspace(0.0, u[k] - u[k + 1], 65)
        if np.all(np.polyval(np.polyder(c), t) >= 0):
            fun = lambda v: float(np.polyval(c, v - u[k + 1]))  # noqa: E731
    if fun is None:
        with np.errstate(over="ignore", divide="ignore"):
            spline = PchipInterpolator(u[::-1], P[::-1], extrapolate=False)
        fun = lambda v: float(spline(v))  # noqa: E731
    return math.exp(brentq(lambda v: fun(v) - q, u[k + 1], u[k], xtol=1e-14, rtol=4 * np.finfo(float).eps))


def run(quick: bool = False) -> list[dict]:
    import rtd

    from millflow.mill import steady_mill
    from millflow.mill.population import steady_population
    from millflow.mill.well_mixed import solve_well_mixed
    from millflow.psd import percentile_sizes

    rounds = 5 if quick else 11
    load = f"{os.getloadavg()[0]:.2f}"
    rows = []
    g, S, b, feed = _scene(100)
    from millflow.mill.well_mixed import solve_well_mixed as _wm

    frac = _wm(S, b, feed, 600.0)
    frac = frac / frac.sum()
    med = _interleaved({"new": lambda: percentile_sizes(g.x, frac, [80, 50]),
                        "old": lambda: (_old_percentile(g.x, frac, 80), _old_percentile(g.x, frac, 50))},
                       rounds, 50)
    new, old = percentile_sizes(g.x, frac, [80, 50]), [_old_percentile(g.x, frac, q) for q in (80, 50)]
    rows.append({"case": "P80 + P50, N = 100", "method": "percentile_sizes", "runtime_s": med["new"],
                 "baseline": "cubic fit / PchipInterpolator + brentq", "baseline_s": med["old"],
                 "ratio_vs_baseline": med["new"] / med["old"],
                 "max_rel_diff": float(np.max(np.abs(new - old) / np.asarray(old))), "load_average": load})
    g, S, b, feed = _scene(50)
    tr = rtd.PerfectMixing(600.0)
    med = _interleaved({"steady_mill": lambda: steady_mill(S, b, feed, tr),
                        "bare": lambda: solve_well_mixed(S, b, feed, 600.0)}, rounds, 20)
    over = med["steady_mill"] - med["bare"]
    rows.append({"case": "steady_mill, perfect mixing, N = 50", "method": "steady_mill (Dataset)",
                 "runtime_s": med["steady_mill"], "baseline": "solve_well_mixed", "baseline_s": med["bare"],
                 "ratio_vs_baseline": med["steady_mill"] / med["bare"], "overhead_s": over,
                 "target_overhead_s": TARGET_OVERHEAD_S, "met": over <= TARGET_OVERHEAD_S, "load_average": load})
    from millflow.mill import Mill

    mill = Mill(S, b, tr)
    med = _interleaved({"fast": lambda: mill.product(feed),
                        "bare": lambda: solve_well_mixed(S, b, feed, 600.0)}, rounds, 50)
    over = med["fast"] - med["bare"]
    rows.append({"case": "steady_mill, perfect mixing, N = 50", "method": "Mill.product (fast path)",
                 "runtime_s": med["fast"], "baseline": "solve_well_mixed", "baseline_s": med["bare"],
                 "ratio_vs_baseline": med["fast"] / med["bare"], "overhead_s": over,
                 "target_overhead_s": TARGET_OVERHEAD_S, "met": over <= TARGET_OVERHEAD_S, "load_average": load})
    rows.append(_sweep_case_row(rounds, load))
    members = 400 if quick else 2000
    g, S, b, feed = _scene(100, members)
    for name, tr in _populations():
        segregated = name not in TARGET_MILLS_PER_S
        P = members // 10 if segregated else members  # the eigenbasis costs ~N^3/6 a member
        loop_n = 20
        med = _interleaved({"pop": lambda tr=tr, P=P: steady_population(S[:P], b, feed, tr),
                            "loop": lambda tr=tr: [steady_mill(S[k], b, feed, tr) for k in range(loop_n)]},
                           max(3, rounds // 2), 1)
        rate, base_rate = P / med["pop"], loop_n / med["loop"]
        got = steady_population(S[:loop_n], b, feed, tr)
        ref = np.array([steady_mill(S[k], b, feed, tr)["product"].values for k in range(loop_n)])
        target = TARGET_MILLS_PER_S.get(name)
        rows.append({"case": f"population {name}, N = 100, P = {P}", "method": "steady_population",
                     "runtime_s": med["pop"], "mills_per_s": rate, "baseline": "steady_mill per member",
                     "baseline_mills_per_s": base_rate, "ratio_vs_baseline": base_rate / rate,
                     "max_rel_diff": float(np.max(np.abs(got - ref)) / np.max(np.abs(ref))),
                     "target_mills_per_s": target, "met": None if target is None else rate >= target,
                     "load_average": load})
    return rows


def _sweep_case_row(rounds: int, load: str) -> dict:
    """Sweep cases against bare solves of the same cases. The cases: a 10 x 10 grid of the
    mill's tau and the cyclones' d50c on the closed circuit of ``millflow bench sweep``.
    Timed per case, in interleaved rounds of the 100 cases:

    - millflow: what a sweep's chunk runs (``millflow.sweep.run._solve_chunk``: a
      :class:`millflow.sweep.CaseSolver` built for the round, its base flowsheet included,
      then each case's changed units rebuilt (each variant once), the case solved and
      reduced to its key figures, the chunk inside one single-threaded BLAS context);
    - baseline ("the bare solve"): :func:`millflow.flowsheet.solve` of each case's flowsheet
      built beforehand, outside the timed region, and solved once before the rounds (as the
      sweep's mills, its mills hold their class-averaged breakage: prebuilt inputs); each
      call sets and restores the BLAS thread limit, as a user's loop of solves does;
    - second baseline: the same solves inside one single-threaded BLAS context (the solve's
      work alone), ``ratio_vs_solve_work``.

    ``max_rel_diff``: the largest relative difference between the chunk's figures and
    :func:`millflow.flowsheet.results.key_figures` of the bare solves (the same numbers)."""
    import copy
    import math
    import tempfile
    from pathlib import Path

    from millflow.bench.sweep import _write_case
    from millflow.flowsheet import from_dict, solve
    from millflow.flowsheet.results import key_figures
    from millflow.inputs import read_toml
    from millflow.sweep import parse_vary
    from millflow.sweep.cases import grid_cases, set_key
    from millflow.sweep.run import _products, _solve_chunk
    from millflow.threads import single_threaded_blas

    with tempfile.TemporaryDirectory() as tmp:
        path = _write_case(Path(tmp))
        data = read_toml(path, "flowsheet file")
    source = str(path)
    cases = grid_cases([parse_vary("units.ball_mill.tau_min=2:6:10"), parse_vary("units.cyclones.d50c_um=80:200:10")])
    built = []
    for case in cases:
        d = copy.deepcopy(data)
        for k, v in case.items():
            set_key(d, k, v)
        built.append(from_dict(d, source=source))

    def bare():
        for fs in built:
            solve(fs)

    def bare_work():
        with single_threaded_blas():
            for fs in built:
                solve(fs)

    med = _interleaved({"case": lambda: _solve_chunk(data, cases, source), "solve": bare, "work": bare_work},
                       rounds, 1)
    n = len(cases)
    per_case, per_solve, per_work = med["case"] / n, med["solve"] / n, med["work"] / n
    got = _solve_chunk(data, cases, source)
    products = _products(data)
    diff = 0.0
    for g, fs in zip(got, built):
        ref = key_figures(solve(fs), products)
        pairs = [(g[k][s], ref[k][s]) for k in ("p80_um", "p50_um", "circulating_load") for s in ref[k]]
        pairs += [(g[k], ref[k]) for k in ("specific_energy_kWh_per_t", "mass_balance_error")]
        for a, b in pairs:
            if a is None or b is None:
                diff = diff if a is b else math.inf
            elif a != b:
                diff = max(diff, abs(a - b) / max(abs(b), 1e-300))
    return {"case": "sweep case, closed circuit N = 60, 5 cells", "method": "sweep chunk (10 x 10 grid)",
            "runtime_s": per_case, "baseline": "solve (flowsheets built before)", "baseline_s": per_solve,
            "ratio_vs_baseline": per_case / per_solve, "solve_work_s": per_work,
            "ratio_vs_solve_work": per_case / per_work, "max_rel_diff": diff, "target_ratio": TARGET_SWEEP_RATIO,
            "met": per_case / per_solve <= TARGET_SWEEP_RATIO, "load_average": load}


def format_table(rows: list[dict]) -> str:
    out = []
    for r in rows:
        extra = ""
        if "overhead_s" in r:
            extra = f"overhead {1e3 * r['overhead_s']:.3f} ms (target <= {1e3 * r['target_overhead_s']:.1f} ms: " \
                    f"{'met' if r['met'] else 'not met'})"
        elif "mills_per_s" in r:
            extra = (f"{r['mills_per_s']:.3g} mills/s vs {r['baseline_mills_per_s']:.3g} per member, "
                     f"max rel diff {r['max_rel_diff']:.1e}"
                     + ("" if r["target_mills_per_s"] is None else
                        f" (target >= {r['target_mills_per_s']:.0e}: {'met' if r['met'] else 'not met'})"))
        elif "target_ratio" in r:
            extra = (f"(target <= {r['target_ratio']:g}x: {'met' if r['met'] else 'not met'}); "
                     f"x{r['ratio_vs_solve_work']:.3g} the solves inside one BLAS limit, max rel diff "
                     f"{r['max_rel_diff']:.1e}")
        elif "max_rel_diff" in r:
            extra = f"max rel diff {r['max_rel_diff']:.1e}"
        out.append(f"{r['case']:<46} {r['method']:<22} {1e3 * r['runtime_s']:>9.4f} ms  vs {r['baseline']:<28} "
                   f"x{r['ratio_vs_baseline']:<8.3g} {extra}")
    out.append(f"medians of interleaved rounds; load average {rows[0]['load_average']}")
    return "\n".join(out)
