"""Benchmark of start-up: whole ``millflow`` processes against plain Python imports.

Every row is a fresh process (``sys.executable``, the caller's environment with the BLAS
thread count pinned to one), timed from launch to exit; the rounds are interleaved
(baseline, command, baseline, command, ...) so that load on the machine falls on both
alike, and each row reports the median over the rounds. Rows and targets:

- ``python -c "import numpy"``: baseline of ``millflow --version`` (target <= 1.3x);
- ``python -c "import numpy, scipy, xarray"``: baseline of ``millflow run --no-plots``
  of a small open circuit (feed, mill, screen, two products; target <= 2x);
- ``millflow run`` (plots written): the share of the run spent on plots,
  (default - no plots) / default, target <= 30 %;
- ``import millflow``: the heavy modules it loads (target: none of scipy.integrate,
  scipy.stats, pandas, xarray, matplotlib), counted in the child's ``sys.modules``.

The load average of the machine at the start and the end is reported: a loaded machine
stretches every row, the ratios less so.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from millflow._lazy import HEAVY, heavy_modules_loaded  # noqa: F401  (re-exported names of the suite)

__all__ = ["DESCRIPTION", "run", "format_table", "HEAVY", "SMALL_FLOWSHEET_TOML", "heavy_modules_loaded"]

DESCRIPTION = "start-up: millflow --version, run --no-plots, run with plots as whole processes vs plain imports"

TARGET_VERSION = 1.3
TARGET_RUN = 2.0
TARGET_PLOT_SHARE = 0.30

#: A small flowsheet: an open-circuit ball mill (perfect mixing) with a discharge screen.
SMALL_FLOWSHEET_TOML = """
title = "Open-circuit ball mill with screen (start-up benchmark)"
[grid]
top_um = 6700
bottom_um = 10
ratio = 1.189207115
[materials.ore]
rate = {form = "power", A_per_min = 0.7, alpha = 1.1, x0_um = 1000}
breakage = {form = "normalized", phi = 0.5, gamma = 0.9, beta = 4.0}
[units.feed]
type = "feed"
solids_tph = 120
[units.feed.psd]
form = "rosin_rammler"
x63_um = 700
n = 1.1
[units.ball_mill]
type = "mill"
material = "ore"
tau_min = 9
transport = {model = "perfect_mixing"}
[units.screen]
type = "screen"
d50_um = 1500
m = 6
bypass = 0.0
[units.scats]
type = "product"
[units.product]
type = "product"
[streams]
mill_feed = {from = "feed", to = "ball_mill"}
mill_discharge = {from = "ball_mill", to = "screen"}
oversize = {from = "screen.oversize", to = "scats"}
undersize = {from = "screen.undersize", to = "product"}
"""


def _env() -> dict:
    """The timed processes' environment: one BLAS thread, and byte-code written as Python
    does by default (the untimed warm-up run writes it): with PYTHONDONTWRITEBYTECODE set,
    an editable checkout's modules would be compiled from source in every timed process
    while the baselines' libraries load their installed byte-code."""
    from millflow._lazy import import_path_env

    env = import_path_env(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _time(cmd: list[str], env: dict, cwd: str) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[-300:]}")
    return dt


def run(quick: bool = False) -> list[dict]:
    rounds = 3 if quick else 9
    py = sys.executable
    env = _env()
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="millflow-bench-startup-") as tmp:
        sheet = Path(tmp) / "small.toml"
        sheet.write_text(SMALL_FLOWSHEET_TOML, encoding="utf-8")
        mf = [py, "-m", "millflow"]
        cmds = {
            "import numpy": [py, "-c", "import numpy"],
            "millflow --version": mf + ["--version"],
            "import numpy, scipy, xarray": [py, "-c", "import numpy, scipy, xarray"],
            "millflow run --no-plots": mf + ["run", str(sheet), "--no-plots", "--quiet", "--overwrite",
                                             "--out", str(Path(tmp) / "out_noplots")],
            "millflow run": mf + ["run", str(sheet), "--quiet", "--overwrite", "--out", str(Path(tmp) / "out")],
        }
        times = {k: [] for k in cmds}
        for k in cmds:  # warm the file cache (and byte-code) once, untimed
            _time(cmds[k], env, tmp)
        for _ in range(rounds):
            for k, cmd in cmds.items():
                times[k].append(_time(cmd, env, tmp))
    med = {k: statistics.median(v) for k, v in times.items()}
    load = f"{load0:.2f} -> {os.getloadavg()[0]:.2f}"
    rows = []

    def row(case, baseline, target, ratio):
        rows.append({"case": case, "method": "whole process", "runtime_s": med.get(case), "baseline": baseline,
                     "baseline_s": med.get(baseline), "ratio_vs_baseline": ratio, "target": target,
                     "met": bool(ratio <= target), "rounds": rounds, "load_average": load})

    row("millflow --version", "import numpy", TARGET_VERSION, med["millflow --version"] / med["import numpy"])
    row("millflow run --no-plots", "import numpy, scipy, xarray", TARGET_RUN,
        med["millflow run --no-plots"] / med["import numpy, scipy, xarray"])
    share = max(0.0, med["millflow run"] - med["millflow run --no-plots"]) / med["millflow run"]
    row("millflow run", "millflow run --no-plots", TARGET_PLOT_SHARE, share)
    rows[-1]["method"] = "plot share of the run"
    heavy = heavy_modules_loaded()
    rows.append({"case": "import millflow", "method": "sys.modules of a fresh process", "runtime_s": None,
                 "heavy_modules": heavy, "target": "none of " + ", ".join(HEAVY), "met": not heavy,
                 "rounds": 1, "load_average": load})
    return rows


def format_table(rows: list[dict]) -> str:
    out = [f"{'case':<26} {'measure':<30} {'median s':>9} {'baseline':<28} {'base s':>8} {'ratio':>7} "
           f"{'target':>7}  met"]
    for r in rows:
        if r["case"] == "import millflow":
            out.append(f"{r['case']:<26} {r['method']:<30} {'':>9} {'':<28} {'':>8} "
                       f"{len(r['heavy_modules']):>7} {0:>7}  {'yes' if r['met'] else 'no'}"
                       + (f" (loads {', '.join(r['heavy_modules'])})" if r["heavy_modules"] else ""))
            continue
        out.append(f"{r['case']:<26} {r['method']:<30} {r['runtime_s']:>9.3f} {r['baseline']:<28} "
                   f"{r['baseline_s']:>8.3f} {r['ratio_vs_baseline']:>7.2f} {r['target']:>7.2f}  "
                   f"{'yes' if r['met'] else 'no'}")
    out.append(f"medians of {rows[0]['rounds']} interleaved rounds; load average {rows[0]['load_average']}; "
               "plot share = (run - run --no-plots) / run")
    return "\n".join(out)
