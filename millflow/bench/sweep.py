"""Benchmark of sweeps: many closed-circuit cases on a Dask LocalCluster.

Case: the closed-circuit ball mill of :mod:`millflow.bench.flowsheet` on N = 60 classes
with a 5-cell mill, a grid of cases over the mill's tau and the cyclones' d50c. Rows:

- ``single solve in a loop`` (baseline, same process): each case's flowsheet built whole
  from the document, solved and summarised (:func:`millflow.flowsheet.summary`), case
  after case, as a plain loop does it; its per-case time is the unit of the ratios.
- ``sweep serial``: :func:`millflow.sweep.run_sweep` with ``scheduler="serial"``
  (chunking and the Dataset, no Dask).
- ``sweep LocalCluster 2 workers``: the same cases on a 2-worker LocalCluster (cluster
  start-up included); ``ratio_vs_baseline`` is its core time per case (wall x 2 / cases)
  over the baseline's per case (target <= 2), ``max_rel_diff`` the largest relative
  difference from the serial Dataset (the same numbers: rounding only, target 1e-12).

Targets: 10,000 cases in < 60 s on 2 cores; per-case cost within 2x of a single
solve in a loop; the LocalCluster Dataset equal to the serial one to rounding. ``--quick``
runs 400 cases.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["DESCRIPTION", "run", "format_table"]

DESCRIPTION = "sweeps: closed circuit N = 60, 5 cells, tau x d50c grid; serial vs 2-worker LocalCluster"
TARGET_WALL_S_10K = 60.0
TARGET_RATIO = 2.0


def _write_case(folder: Path) -> Path:
    from millflow.synthetic import CLOSED_CIRCUIT_TOML

    text = CLOSED_CIRCUIT_TOML
    lines, skip = [], False
    for line in text.splitlines():  # replace the [grid] table and the mill's transport
        if line.strip() == "[grid]":
            lines += ["[grid]", "top_um = 8000", "bottom_um = 2", "n = 60"]
            skip = True
            continue
        if skip and line.startswith("["):
            skip = False
        if skip:
            continue
        if line.strip().startswith("transport"):
            line = 'transport = {model = "tanks_in_series", n = 5}'
        lines.append(line)
    path = folder / "closed_circuit_N60_cells5.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _plain_case(data: dict, case: dict, source: str) -> dict:
    """A case the plain way: the document copied with the case's values, built, solved, summarised."""
    import copy

    from millflow.flowsheet import from_dict, solve, summary
    from millflow.sweep.cases import set_key

    d = copy.deepcopy(data)
    for key, value in case.items():
        set_key(d, key, value)
    return summary(solve(from_dict(d, source=source)))


def run(quick: bool = False) -> list[dict]:
    from millflow.inputs import read_toml
    from millflow.sweep import parse_vary, run_sweep
    from millflow.sweep.cases import grid_cases

    side = 20 if quick else 100
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = _write_case(Path(tmp))
        vary = [parse_vary(f"units.ball_mill.tau_min=2:6:{side}"), parse_vary(f"units.cyclones.d50c_um=80:200:{side}")]
        cases = grid_cases(vary)
        data = read_toml(path, "flowsheet file")
        n_base = min(len(cases), 300)
        _plain_case(data, cases[0], str(path))  # warm-up (imports, caches)
        t0 = time.perf_counter()
        for c in cases[:n_base]:
            _plain_case(data, c, str(path))
        per_case = (time.perf_counter() - t0) / n_base
        rows.append({"case": f"{len(cases)} cases", "method": f"single solve in a loop ({n_base} cases timed)",
                     "runtime_s": per_case * len(cases), "per_case_s": per_case, "ratio_vs_baseline": 1.0})
        t0 = time.perf_counter()
        serial = run_sweep(path, vary, scheduler="serial", progress=False)
        t_serial = time.perf_counter() - t0
        rows.append({"case": f"{len(cases)} cases", "method": "sweep serial", "runtime_s": t_serial,
                     "per_case_s": t_serial / len(cases), "ratio_vs_baseline": t_serial / len(cases) / per_case})
        workers = 2
        t0 = time.perf_counter()
        local = run_sweep(path, vary, scheduler="local", workers=workers, progress=False)
        t_local = time.perf_counter() - t0
        diff = 0.0
        for var in ("p80_um", "p50_um", "circulating_load", "specific_energy_kWh_per_t"):
            a, b = np.asarray(serial[var], float), np.asarray(local[var], float)
            ok = np.isfinite(a) & np.isfinite(b)
            if not np.array_equal(np.isfinite(a), np.isfinite(b)):
                diff = float("inf")
            elif ok.any():
                diff = max(diff, float(np.max(np.abs(a[ok] - b[ok]) / np.maximum(np.abs(a[ok]), 1e-300))))
        core_per_case = t_local * workers / len(cases)
        target_wall = TARGET_WALL_S_10K * len(cases) / 10_000
        rows.append({"case": f"{len(cases)} cases", "method": f"sweep LocalCluster {workers} workers "
                                                              f"({os.cpu_count()} cores here)",
                     "runtime_s": t_local, "per_case_s": core_per_case,
                     "ratio_vs_baseline": core_per_case / per_case, "max_rel_diff": diff,
                     "target_s": target_wall,
                     "meets_target": bool(t_local < target_wall and core_per_case / per_case <= TARGET_RATIO
                                          and diff <= 1e-12)})
    return rows


def format_table(rows) -> str:
    head = f"{'case':<14} {'method':<44} {'wall s':>8} {'per case ms':>12} {'x loop':>7} {'max rel diff':>12}"
    lines = [head, "-" * len(head)]
    for r in rows:
        d = r.get("max_rel_diff")
        lines.append(f"{r['case']:<14} {r['method']:<44} {r['runtime_s']:>8.2f} {1e3 * r['per_case_s']:>12.2f} "
                     f"{r['ratio_vs_baseline']:>7.2f} {'' if d is None else f'{d:.1e}':>12}")
    last = rows[-1]
    lines.append(f"target: wall < {last['target_s']:.3g} s (60 s per 10,000 cases), core time per case <= "
                 f"{TARGET_RATIO:g}x the loop, same Dataset to 1e-12: {'met' if last['meets_target'] else 'NOT met'}")
    return "\n".join(lines)
