"""Benchmark suite ``fit``: global parameter estimation on synthetic batch data.

Case ``global_5p``: eq. 5 rates and eq. 6 breakage (5 parameters: ln_A0, alpha, phi,
gamma, beta), batch grinding sampled at 8 geometric times on 30 sieves (root-2 series),
solved on a 60-class numerical grid, 1 % noise on cumulative passing; differential
evolution with vectorised population evaluation, then 20 local least-squares starts
(DE optimum + 19 Sobol points) and a polish. ``max_abs_error`` is the largest
|estimate - truth| over the parameters; ``ratio_vs_baseline`` the run time over the
10 s budget.

Case ``knife_mill_loo_12fold`` (full run only, when the SPRITE knife-mill data are found:
not part of this repository, they are the measurements published with the open-source SPRITE
suite (Idaho National Laboratory, MIT licence; Lu et al. 2024, Powder Technology 441, 119830),
looked for at ``../shared/data/sprite-knife-mill`` beside the repository or ``$MILLFLOW_KNIFE_DATA``):
the knife-mill example's 12-fold leave-one-run-out prediction with the global search in
every fold (examples/knife_mill/knife_mill.toml: 8 parameters, 151-class grid, DE popsize
10, maxiter 150, 8 starts). ``ratio_vs_baseline`` is the run time over the 20 s target
(62.6 s measured before the fit called the core's population solves).
"""
from __future__ import annotations

import os
import time

import numpy as np
import pandas as pd

DESCRIPTION = "global 5-parameter fit (DE + 20 local starts) to 8 times x 30 sieves, 60-class grid"

#: Parameters of the synthetic batch problems (ln_A0 is ln of A [1/s] at x0 = 1 mm).
TRUTH = {"ln_A0": np.log(1.0 / 60.0), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}
#: Bounds that separate the two branches of eq. 6 (gamma < beta), so the truth is unique.
BOUNDS = {"ln_mu": (-3.0, 6.0), "Lambda": (1.0, 6.0), "ln_A0": (-9.0, 0.0), "alpha": (0.2, 2.5), "phi": (0.0, 1.0),
          "gamma": (0.1, 2.0), "beta": (2.2, 8.0)}


def make_batch_problem(n_times: int = 8, n_sieves: int = 30, n_grid: int = 60, noise: float = 0.01,
                       seed: int = 0, truth: dict | None = None, rate: str = "power", bounds: dict | None = None):
    """Synthetic batch data from known parameters; returns (model, params, truth).

    Sieves: root-2 series down from 4 mm; the numerical grid has the same top and a
    finer ratio chosen so that it has ``n_grid`` classes over the same range (the
    sieve sizes are then generally not grid edges: the model is interpolated, as with
    real data). Feed: all mass in the top sieve interval. Times: geometric 0.5 to
    ``0.5 * 2^(n_times-1)`` min. Noise: N(0, noise^2) added to cumulative passing.
    """
    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.models import ForwardModel, ModelSpec, Parameter
    from millflow.grid import SizeGrid

    truth = dict(TRUTH if truth is None else truth)
    sieves = 4e-3 * 2 ** (-0.5 * np.arange(n_sieves))
    times = 30.0 * 2.0 ** np.arange(n_times)
    ratio = (sieves[0] / sieves[-1]) ** (1.0 / (n_grid - 1))
    grid = SizeGrid.geometric(sieves[0], ratio, n_grid)
    feed = pd.DataFrame({"condition": "c1", "location": "feed", "time_s": 0.0, "size_m": sieves[:2],
                         "passing": [1.0, 0.0]})
    rows = []
    for t in times:
        rows.append(pd.DataFrame({"condition": "c1", "location": "mill", "time_s": t, "size_m": sieves,
                                  "passing": np.linspace(1, 0, n_sieves)}))
    placeholder = psd_data_from_frames(pd.concat([feed] + rows, ignore_index=True))
    spec = ModelSpec(mode="batch", rate=rate, breakage="normalized", x0_m=1e-3)
    model = ForwardModel(spec, placeholder, grid)
    theta = np.array([truth[n] for n in model.param_names])
    clean = model.predict(theta)
    rng = np.random.default_rng(seed)
    noisy = clean + noise * rng.standard_normal(clean.size)
    rows = [feed] + [r.assign(passing=noisy[k * n_sieves:(k + 1) * n_sieves]) for k, r in enumerate(rows)]
    data = psd_data_from_frames(pd.concat(rows, ignore_index=True), strict=False)
    model = ForwardModel(spec, data, grid)
    bounds = {**BOUNDS, **(bounds or {})}
    params = {n: Parameter(n, truth[n], *bounds[n]) for n in model.param_names}
    return model, params, truth


def run(quick: bool = False, knife: bool = True) -> list[dict]:
    """The cases; ``knife=False`` leaves out the knife-mill leave-one-run-out (~30 s)."""
    from millflow.fitting.estimate import fit

    model, params, truth = make_batch_problem(seed=1)
    start, cpu = time.perf_counter(), time.process_time()
    res = fit(model, params, starts=20, popsize=10, maxiter=100 if quick else 200, seed=0, grid_check=False,
              quiet=True)
    runtime, cpu = time.perf_counter() - start, time.process_time() - cpu
    err = max(abs(res.params[n].value - truth[n]) for n in truth)
    return [{"case": "global_5p_batch_8x30_grid60", "method": "DE(vectorised)+20 LSQ starts", "runtime_s": runtime,
             "cpu_s": cpu, "max_abs_error": float(err), "ratio_vs_baseline": runtime / 10.0, "ssr": res.ssr,
             "spread": res.spread, "nfev": res.nfev}] + (_knife_rows(quick) if knife else [])


def _knife_rows(quick: bool) -> list[dict]:
    data_dir = None if quick else knife_data_dir()
    return [] if data_dir is None else [run_knife_loo(data_dir)]


def knife_data_dir() -> str | None:
    """The SPRITE knife-mill folder if present (read in place, never copied)."""
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for path in (os.environ.get("MILLFLOW_KNIFE_DATA"), os.path.join(here, "..", "shared", "data", "sprite-knife-mill"),
                 "/work/shared/data/sprite-knife-mill"):
        if path and os.path.isdir(path):
            return os.path.normpath(path)
    return None


def run_knife_loo(data_dir: str) -> dict:
    """The knife-mill example's 12-fold leave-one-run-out, timed."""
    from millflow.fitting.config import load_config
    from millflow.fitting.validate import leave_out

    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    cfg = load_config(os.path.join(here, "examples", "knife_mill", "knife_mill.toml"), data_dir=data_dir)
    model = cfg.model()
    start, cpu = time.perf_counter(), time.process_time()
    loo = leave_out(model, cfg.params, "each", quiet=True, **dict(cfg.optimizer))
    runtime, cpu = time.perf_counter() - start, time.process_time() - cpu
    return {"case": "knife_mill_loo_12fold", "method": "12 x (DE+8 LSQ starts), 151-class eq. 3", "runtime_s": runtime,
            "cpu_s": cpu, "max_abs_error": float("nan"), "loo_mean_rmse": float(loo["mean_rmse"]),
            "ratio_vs_baseline": runtime / 20.0}


def format_table(rows) -> str:
    out = []
    for r in rows:
        if r["case"].startswith("knife"):
            out.append(f"{r['case']:<32} {r['method']:<30} {r['runtime_s']:7.2f} s  LOO RMSE {r['loo_mean_rmse']:.4f}"
                       f"  ({r['ratio_vs_baseline']:.2f} of the 20 s target)")
        else:
            out.append(f"{r['case']:<32} {r['method']:<30} {r['runtime_s']:7.2f} s  max|err| {r['max_abs_error']:.3g}"
                       f"  ({r['ratio_vs_baseline']:.2f} of the 10 s budget)")
    return "\n".join(out)
