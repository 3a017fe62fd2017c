"""Benchmark of flowsheet solving: one linear system vs sequential-modular tear iterations.

Case ``closed_circuit_N100_cells10`` (the issue-5 target: < 20 ms without I/O and
plots): the closed-circuit ball mill of flowsheets/closed_circuit_ball_mill.toml on a
geometric grid of N = 100 classes (8 mm down to 2 um) with a 10-cell (tanks in
series) mill, solved by :func:`millflow.flowsheet.solve` from the parsed file (unit
blocks, mill transfer matrix, exit check, sparse LU: everything but reading the file
and writing results). Baseline: the same circuit solved the classic way, direct
substitution on the torn underflow stream (mill feed = fresh + underflow, discharge =
P mill feed, underflow = diag(c) discharge) until the relative change is below 1e-13,
with P and c built once; ``max_abs_error`` is the largest difference between the two
[kg/s]. Every example flowsheet in flowsheets/ is also solved and timed.
Timings are medians of repeated runs (single-threaded BLAS, set by the bench command).
"""
from __future__ import annotations

import statistics
import time
import tomllib
from pathlib import Path

import numpy as np

from millflow.flowsheet import from_dict, solve
from millflow.flowsheet.results import circulating_loads, mass_balance

__all__ = ["DESCRIPTION", "run", "format_table", "closed_circuit_case", "shipped_circuit_case", "growth_rows",
           "growth_exponent", "FLOWSHEET_DIR", "CLOSED_CIRCUIT_TOML"]

DESCRIPTION = "flowsheet solve: closed-circuit ball mill N = 100, 10 cells (target < 20 ms); examples"

#: Example flowsheets of a source checkout, relative to the working folder (run from the
#: checkout's root; the installed package never looks beside itself for them).
FLOWSHEET_DIR = Path("flowsheets")
TARGET_S = 0.020


#: The closed-circuit ball mill of flowsheets/closed_circuit_ball_mill.toml (kept here so the
#: suite runs from an installed package too); grid and cells are set by closed_circuit_case.
CLOSED_CIRCUIT_TOML = """
title = "Closed-circuit ball mill with hydrocyclones (benchmark)"
[grid]
top_um = 8000
bottom_um = 2
n = 100
[materials.ore]
rate = {form = "power", A_per_min = 0.9, alpha = 1.0, x0_um = 1000}
breakage = {form = "normalized", phi = 0.55, gamma = 0.8, beta = 3.5}
[units.fresh_feed]
type = "feed"
solids_tph = 250
[units.fresh_feed.psd]
form = "sieves"
size_um = [6700, 4750, 3350, 2360, 1700, 1180, 850, 600, 425, 300, 212, 150, 106, 75, 53]
passing_pct = [100, 93, 80, 66, 54, 44, 36, 29, 24, 19.5, 16, 13, 10.5, 8.5, 7]
[units.chute]
type = "mixer"
[units.ball_mill]
type = "mill"
material = "ore"
tau_min = 3.5
transport = {model = "tanks_in_series", n = 10}
power_kW = 3800
[units.cyclones]
type = "hydrocyclone"
curve = "whiten"
d50c_um = 140
alpha = 3.0
beta = 0.0
bypass = 0.30
[units.overflow_product]
type = "product"
[streams]
fresh = {from = "fresh_feed", to = "chute"}
mill_feed = {from = "chute", to = "ball_mill"}
mill_discharge = {from = "ball_mill", to = "cyclones"}
underflow = {from = "cyclones.underflow", to = "chute"}
overflow = {from = "cyclones.overflow", to = "overflow_product"}
"""


def closed_circuit_case(n: int = 100, cells: int = 10):
    """The benchmark flowsheet: closed-circuit ball mill, N classes, a mill of ``cells`` tanks."""
    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": n}
    data["units"]["ball_mill"]["transport"] = {"model": "tanks_in_series", "n": cells}
    return from_dict(data, source=f"closed_circuit_ball_mill (N = {n}, {cells} cells)")


def _median_time(fun, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fun()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def _substitution_baseline(fs, tol: float = 1e-13, maxiter: int = 100000):
    """Sequential-modular solve of the closed circuit by direct substitution on the underflow."""
    grid = fs.grid
    P = fs.units["ball_mill"].blocks(grid)[0]["out"]
    c = fs.units["cyclones"].efficiency(grid)
    fresh = fs.units["fresh_feed"].source()["out"]
    u = np.zeros(grid.n)
    for it in range(1, maxiter + 1):
        discharge = P @ (fresh + u)
        u_new = c * discharge
        if np.max(np.abs(u_new - u)) <= tol * np.max(np.abs(u_new)):
            return u_new, it
        u = u_new
    return u, maxiter


def run(quick: bool = False) -> list[dict]:
    """Rows: the N = 100 target case, its substitution baseline, then every example flowsheet."""
    repeats = 5 if quick else 21
    rows = []
    fs = closed_circuit_case()
    solve(fs)  # warm-up (imports, caches)
    t_lin, sol = _median_time(lambda: solve(fs), repeats)
    t_base, (u, its) = _median_time(lambda: _substitution_baseline(fs), max(3, repeats // 4))
    err = float(np.max(np.abs(sol.flow("underflow") - u)))
    mb = mass_balance(sol)
    rows.append({"case": "closed_circuit_N100_cells10", "method": "one linear solve", "runtime_s": t_lin,
                 "max_abs_error": err, "mass_balance_error": max([mb["overall"], *mb["units"].values()]),
                 "ratio_vs_baseline": t_lin / t_base, "target_s": TARGET_S, "meets_target": t_lin < TARGET_S,
                 "circulating_load": circulating_loads(sol)["underflow"], "n_unknowns": sol.solver["n_unknowns"]})
    rows.append({"case": "closed_circuit_N100_cells10", "method": f"substitution on underflow ({its} iterations)",
                 "runtime_s": t_base, "max_abs_error": err, "ratio_vs_baseline": 1.0})
    rows.extend(growth_rows(quick))
    from millflow.flowsheet import load

    for path in sorted(FLOWSHEET_DIR.glob("*.toml")):  # examples, when run from a checkout's root
        fsx = load(path)
        solve(fsx)
        t, s = _median_time(lambda: solve(fsx), repeats)
        mb = mass_balance(s)
        rows.append({"case": path.stem, "method": s.solver["structure"], "runtime_s": t,
                     "mass_balance_error": max([mb["overall"], *mb["units"].values()]),
                     "n_unknowns": s.solver["n_unknowns"]})
    return rows


#: Cost growth the circuit solve should not exceed (cost ~ N^1.6 from N = 100 to 800).
TARGET_GROWTH = 1.6
#: Closed circuit N = 100: the solve should be >= 3x faster than substitution (ratio <= 1/3).
TARGET_RATIO = 1.0 / 3.0


def shipped_circuit_case(n: int = 100, cells: int = 10):
    """The shipped example's circuit as the file drives it (rates per energy, S = S^E P / H, mill
    given by its hold-up, tau = H / F: torn on its throughput), on N classes, ``cells`` tanks."""
    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": n}
    data["materials"]["ore"]["rate"] = {"form": "power", "A_E_t_per_kWh": 0.675, "alpha": 1.0, "x0_um": 1000}
    mill = data["units"]["ball_mill"]
    del mill["tau_min"]
    mill["holdup_t"] = 47.5
    mill["transport"] = {"model": "tanks_in_series", "n": cells}
    return from_dict(data, source=f"closed_circuit_ball_mill, energy and hold-up (N = {n}, {cells} cells)")


def _interleaved(funs: dict, rounds: int) -> dict:
    """Median CPU time of the process (time.process_time: on a loaded machine wall time mostly
    measures the wait for a core) of each callable, in interleaved rounds (one call each)."""
    times = {k: [] for k in funs}
    for _ in range(rounds):
        for k, fun in funs.items():
            t0 = time.process_time()
            fun()
            times[k].append(time.process_time() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def growth_exponent(ns, times) -> float:
    """Least-squares slope of log(time) against log(N): cost ~ N^slope over the measured range."""
    return float(np.polyfit(np.log(np.asarray(ns, float)), np.log(np.asarray(times, float)), 1)[0])


def growth_rows(quick: bool = False) -> list[dict]:
    """Closed circuit (10-cell mill) from N = 100 up to 800 (400 when quick), both forms:
    per-time rates and tau (linear: one solve) against substitution on the underflow with the
    unit matrices built once per call (interleaved rounds, medians), and the shipped form
    (energy and hold-up: the mill torn on its throughput); the fitted growth exponents."""
    ns = (100, 200, 400) if quick else (100, 200, 400, 800)
    rows, t_lin, t_base, t_ship = [], [], [], []
    for n in ns:
        rounds = 3 if n >= 400 else (5 if quick else 15)
        fs, fship = closed_circuit_case(n), shipped_circuit_case(n)
        solve(fs), solve(fship)  # warm-up
        t = _interleaved({"linear": lambda: solve(fs), "base": lambda: _substitution_baseline(fs),
                          "shipped": lambda: solve(fship)}, rounds)
        its = _substitution_baseline(fs)[1]
        tear = solve(fship).solver["tear"]
        t_lin.append(t["linear"]), t_base.append(t["base"]), t_ship.append(t["shipped"])
        rows.append({"case": f"closed_circuit_N{n}_cells10", "method": "per-time: one linear solve",
                     "runtime_s": t["linear"], "ratio_vs_baseline": t["linear"] / t["base"], "n": n})
        rows.append({"case": f"closed_circuit_N{n}_cells10", "method": f"substitution, matrices built once ({its} it.)",
                     "runtime_s": t["base"], "ratio_vs_baseline": 1.0, "n": n})
        rows.append({"case": f"closed_circuit_N{n}_cells10", "runtime_s": t["shipped"], "n": n,
                     "method": f"energy + hold-up: tear, {tear['iterations']} iterations",
                     "ratio_vs_baseline": t["shipped"] / t["base"]})
    rows.append({"case": f"growth N = {ns[0]}..{ns[-1]}", "method": "fitted exponents (cost ~ N^p)",
                 "runtime_s": float("nan"), "growth_linear": growth_exponent(ns, t_lin),
                 "growth_baseline": growth_exponent(ns, t_base), "growth_shipped": growth_exponent(ns, t_ship),
                 "ratio_N100": t_lin[0] / t_base[0], "target_growth": TARGET_GROWTH, "target_ratio": TARGET_RATIO,
                 "meets_growth": growth_exponent(ns, t_lin) <= TARGET_GROWTH,
                 "meets_ratio": t_lin[0] / t_base[0] <= TARGET_RATIO})
    return rows


def format_table(rows) -> str:
    """Human-readable table of :func:`run` rows."""
    lines = [f"{'case':32s} {'method':52s} {'time [ms]':>10s} {'mass bal.':>9s} {'max err':>9s} {'ratio':>7s}"]
    for r in rows:
        mb = r.get("mass_balance_error")
        er = r.get("max_abs_error")
        rt = r.get("ratio_vs_baseline")
        lines.append(f"{r['case']:32s} {r['method'][:52]:52s} {1e3 * r['runtime_s']:10.2f} "
                     f"{'' if mb is None else f'{mb:.1e}':>9s} {'' if er is None else f'{er:.1e}':>9s} "
                     f"{'' if rt is None else f'{rt:.3f}':>7s}")
    for r in rows:
        if "growth_linear" in r:
            lines.append(f"{r['case']}: per-time solve N^{r['growth_linear']:.2f} (target <= N^{r['target_growth']}: "
                         f"{'met' if r['meets_growth'] else 'NOT met'}), substitution N^{r['growth_baseline']:.2f}, "
                         f"energy + hold-up N^{r['growth_shipped']:.2f}; N = 100 solve / substitution "
                         f"{r['ratio_N100']:.2f} (target <= {r['target_ratio']:.2f}: "
                         f"{'met' if r['meets_ratio'] else 'NOT met'})")
        if "target_s" in r:
            lines.append(f"target: {r['case']} in < {1e3 * r['target_s']:.0f} ms: "
                         f"{'met' if r['meets_target'] else 'NOT met'} ({1e3 * r['runtime_s']:.2f} ms)")
    return "\n".join(lines)
