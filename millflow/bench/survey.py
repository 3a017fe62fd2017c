"""Benchmark suite ``survey``: reconciling a plant survey and fitting a circuit to it.

Case: a two-stage closed grinding circuit (primary mill, sump and cyclones; secondary
mill and cyclones; 10 streams) on a 40-class grid (2^(1/4) from 8 mm), surveyed on
every grid edge (39 sieves, 40 classes) with the fresh-feed flow measured, a sieve
analysis of every stream and noise from the default error model (seeded).

- ``balance``: ``millflow.survey.reconcile`` of that survey (budget 1 s);
- ``fit_8p``: the circuit fit of 8 parameters (eq. 5 A and alpha, both cyclones' d50c,
  sharpness and bypass) to the reconciled survey, 2 local starts, no leave-one-out
  (budget 60 s).

``ratio_vs_budget`` = run time / budget (< 1 meets it); the baseline timed in the same
process is one flowsheet solve (``ratio_vs_solve``). Medians of ``repeats`` balances.
"""
from __future__ import annotations

import time

import numpy as np

DESCRIPTION = "survey reconciliation (10 streams x 40 classes, budget 1 s) and an 8-parameter circuit fit (60 s)"

CIRCUIT = {
    "title": "two-stage closed circuit (benchmark)",
    "grid": {"top_um": 8000, "bottom_um": 10.0, "ratio": 2 ** 0.25},
    "materials": {"ore": {"rate": {"form": "power", "A_per_min": 0.9, "alpha": 1.0, "x0_um": 1000},
                          "breakage": {"form": "normalized", "phi": 0.55, "gamma": 0.8, "beta": 3.5}}},
    "units": {
        "fresh_feed": {"type": "feed", "solids_tph": 250,
                       "psd": {"form": "rosin_rammler", "x63_um": 1000, "n": 1.4}},
        "chute1": {"type": "mixer"},
        "mill1": {"type": "mill", "material": "ore", "tau_min": 3.0, "transport": {"model": "tanks_in_series", "n": 3}},
        "cyc1": {"type": "hydrocyclone", "curve": "whiten", "d50c_um": 300, "alpha": 3.0, "beta": 0.0,
                 "bypass": 0.3},
        "chute2": {"type": "mixer"},
        "mill2": {"type": "mill", "material": "ore", "tau_min": 2.5, "transport": {"model": "tanks_in_series", "n": 3}},
        "cyc2": {"type": "hydrocyclone", "curve": "whiten", "d50c_um": 100, "alpha": 2.5, "beta": 0.0,
                 "bypass": 0.25},
        "sump": {"type": "tank"},
        "product": {"type": "product"},
    },
    "streams": {
        "fresh": {"from": "fresh_feed", "to": "chute1"},
        "mill1_feed": {"from": "chute1", "to": "mill1"},
        "mill1_discharge": {"from": "mill1", "to": "sump"},
        "cyc1_feed": {"from": "sump", "to": "cyc1"},
        "cyc1_under": {"from": "cyc1.underflow", "to": "chute1"},
        "cyc1_over": {"from": "cyc1.overflow", "to": "chute2"},
        "mill2_feed": {"from": "chute2", "to": "mill2"},
        "mill2_discharge": {"from": "mill2", "to": "cyc2"},
        "cyc2_under": {"from": "cyc2.underflow", "to": "chute2"},
        "cyc2_over": {"from": "cyc2.overflow", "to": "product"},
    },
}
FIT = {"materials.ore.rate.A_per_min": (0.3, 3.0), "materials.ore.rate.alpha": (0.4, 1.8),
       "units.cyc1.d50c_um": (100.0, 800.0), "units.cyc1.alpha": (1.0, 6.0), "units.cyc1.bypass": (0.05, 0.6),
       "units.cyc2.d50c_um": (40.0, 300.0), "units.cyc2.alpha": (1.0, 6.0), "units.cyc2.bypass": (0.05, 0.6)}


def make_case(seed: int = 0):
    """(solution, survey, truth) of the benchmark circuit."""
    from millflow.flowsheet import from_dict, solve
    from millflow.survey.synthetic import synthetic_survey

    sol = solve(from_dict(CIRCUIT, source="<bench survey>"))
    sieves = sol.flowsheet.grid.x[1:]  # 39 sieves: 40 classes with the one above the top sieve
    survey, truth = synthetic_survey(sol, sieves, np.random.default_rng(seed))
    return sol, survey, truth


def run(quick: bool = False) -> list[dict]:
    from millflow.flowsheet import from_dict, solve
    from millflow.survey import reconcile
    from millflow.survey.fit import fit_circuit

    sol, survey, truth = make_case()
    t = time.perf_counter()
    solve(from_dict(CIRCUIT, source="<bench survey>"))
    base = time.perf_counter() - t
    times = []
    for _ in range(3 if quick else 7):
        t = time.perf_counter()
        bal = reconcile(survey)
        times.append(time.perf_counter() - t)
    rt = float(np.median(times))
    st = bal.structure
    rows = [{"case": f"balance {st.S} streams x {st.K} classes", "method": "reconcile", "runtime_s": rt,
             "budget_s": 1.0, "ratio_vs_budget": rt / 1.0, "ratio_vs_solve": rt / base, "solve_s": base,
             "chi_square_p": bal.chi_square["p_value"], "dof": bal.chi_square["dof"],
             "mass_balance_error": bal.balance_error}]
    if not quick:
        t = time.perf_counter()
        cf = fit_circuit(bal, list(FIT), FIT, starts=2, leave_one_out=False)
        rt = time.perf_counter() - t
        d = cf.to_dict()["parameters"]
        true = {n: _get(CIRCUIT, n) for n in FIT}
        worst = max(abs(d[n]["value"] - true[n]) / d[n]["se"] for n in FIT)
        rows.append({"case": "circuit fit 8 parameters", "method": "2 local starts", "runtime_s": rt,
                     "budget_s": 60.0, "ratio_vs_budget": rt / 60.0, "ratio_vs_solve": rt / base, "solve_s": base,
                     "max_error_in_se": worst, "nfev": cf.result.nfev})
    return rows


def _get(doc, path):
    for part in path.split("."):
        doc = doc[part]
    return doc


def format_table(rows) -> str:
    out = []
    for r in rows:
        extra = (f"chi-square p {r['chi_square_p']:.2f} on {r['dof']} dof" if "dof" in r else
                 f"largest |estimate - truth| {r['max_error_in_se']:.2f} SE, {r['nfev']} solves")
        out.append(f"{r['case']:<34} {r['runtime_s']:8.3f} s  ({r['ratio_vs_budget']:.2f} of the {r['budget_s']:g} s "
                   f"budget; {r['ratio_vs_solve']:.0f}x one solve)  {extra}")
    return "\n".join(out)
