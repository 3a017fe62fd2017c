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
looked for from the working folder, at ``../shared/data/sprite-knife-mill`` or ``$MILLFLOW_KNIFE_DATA``):
the knife-mill example's 12-fold leave-one-run-out prediction with the global search in
every fold (examples/knife_mill/knife_mill.toml, shipped with the bench as package data:
8 parameters, 151-class grid, DE popsize 10, maxiter 150, 8 starts). ``ratio_vs_baseline``
is the run time over the 20 s target (62.6 s measured before the fit called the core's
population solves).
"""
from __future__ import annotations

import os
import time
from importlib import resources

# the synthetic problem lives in millflow.synthetic (the tests use it too); kept here by its old names
from millflow.synthetic import BOUNDS, TRUTH, make_batch_problem  # noqa: F401

DESCRIPTION = "global 5-parameter fit (DE + 20 local starts) to 8 times x 30 sieves, 60-class grid"

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


#: The knife-mill example's fit configuration: package data of the bench, a copy of the
#: repository's examples/knife_mill/knife_mill.toml kept equal by a test (the installed
#: package reads no repository).
KNIFE_CONFIG = ("data", "knife_mill.toml")


def knife_data_dir() -> str | None:
    """The SPRITE knife-mill folder if present (read in place, never copied):
    ``$MILLFLOW_KNIFE_DATA``, else ``../shared/data/sprite-knife-mill`` from the working
    folder; None when neither is a folder (the case is then left out)."""
    for path in (os.environ.get("MILLFLOW_KNIFE_DATA"), os.path.join("..", "shared", "data", "sprite-knife-mill")):
        if path and os.path.isdir(path):
            return os.path.normpath(os.path.abspath(path))
    return None


def run_knife_loo(data_dir: str) -> dict:
    """The knife-mill example's 12-fold leave-one-run-out, timed."""
    from millflow.fitting.config import load_config
    from millflow.fitting.validate import leave_out

    with resources.as_file(resources.files("millflow.bench").joinpath(*KNIFE_CONFIG)) as config:
        cfg = load_config(config, data_dir=data_dir)
    model = cfg.model()
    import os
    import resource

    def cpu_now():  # this process and its finished workers (the folds run in forked workers)
        c = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + c.ru_utime + c.ru_stime

    workers = min(12, os.cpu_count() or 1)
    start, cpu = time.perf_counter(), cpu_now()
    loo = leave_out(model, cfg.params, "each", quiet=True, **dict(cfg.optimizer))
    runtime, cpu = time.perf_counter() - start, cpu_now() - cpu
    return {"case": "knife_mill_loo_12fold",
            "method": f"12 x (DE+8 LSQ starts), 151-class eq. 3, folds on {workers} processes",
            "runtime_s": runtime, "cpu_s": cpu, "workers": workers, "max_abs_error": float("nan"),
            "loo_mean_rmse": float(loo["mean_rmse"]), "ratio_vs_baseline": runtime / 20.0}


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
