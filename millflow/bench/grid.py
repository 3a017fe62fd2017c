"""Benchmark of the size discretisation: P80 error against run time, class averages vs
Austin's upper edges, on the shipped circuits.

Each shipped circuit (the flowsheets/ of the repository, shipped with this suite as package
data: the bench reads no repository) is solved on geometric grids of ratio 2^(1/m) (m = 2,
4, 8, 16, 32; 2, 4, 8 for the aggregating mill, whose non-linear solves take seconds on fine
grids; the top and bottom sizes of its file) under both schemes of
:class:`millflow.grid.SizeGrid` ("class_average", the default, second order; and
"upper_edge", Austin's values at the upper class edges, first order). The error of a
run is the largest relative error of P80 over the circuit's streams against a
reference from deep refinement: the class-averaged solutions on the finest grid refined
2x and 4x (nested), Richardson-extrapolated at order 2 (for the aggregating mill, the
finest grid refined 2x and 4x with m up to 8). ``runtime_s`` is the median
solve time (parsed document to solution, single-threaded BLAS). ``max_abs_error`` holds
the relative P80 error so that ``--plot`` draws error against run time. A last row
gives the cost of ``millflow run``'s work on the closed circuit (solve and grid check)
with class averages over that with upper edges, interleaved medians in one process.
"""
from __future__ import annotations

import copy
import math
import statistics
import time

from millflow.bench._shipped import shipped_document
from millflow.flowsheet import from_dict, solve
from millflow.flowsheet.gridcheck import refine_document
from millflow.flowsheet.results import stream_properties

__all__ = ["DESCRIPTION", "run", "format_table", "CIRCUITS", "document"]

DESCRIPTION = "size discretisation: P80 error vs run time, class averages vs upper edges, shipped circuits"

#: Circuits benchmarked: every shipped flowsheet.
CIRCUITS = ("closed_circuit_ball_mill", "open_circuit_ball_mill", "cement_two_compartment_mill",
            "hammer_mill_screen", "stirred_mill_recirculation", "closed_circuit_wet_cyclones",
            "closed_circuit_aggregating_mill")
#: Grid ratios 2^(1/m) per circuit where not the default (2, 4, 8, 16, 32): the aggregating
#: mill's non-linear solve takes ~8 s at 2^(1/32), 310 classes.
RATIOS = {"closed_circuit_aggregating_mill": (2, 4, 8)}


def document(name: str) -> dict:
    """The shipped flowsheet ``name`` (package data of the bench: a copy of the repository's
    flowsheets/<name>.toml, kept equal by a test), parsed."""
    return shipped_document(name)


def _with_ratio(doc: dict, m: int, scheme: str) -> dict:
    """The document on a geometric grid of ratio 2^(1/m) between its own top and bottom."""
    out = copy.deepcopy(doc)
    g = {k: v for k, v in out["grid"].items() if k not in ("n", "ratio", "scheme")}
    g["ratio"] = 2.0 ** (1.0 / m)
    g["scheme"] = scheme
    out["grid"] = g
    return out


def _p80s(fs) -> tuple[dict, float]:
    t0 = time.perf_counter()
    sol = solve(fs)
    t = time.perf_counter() - t0
    pr = stream_properties(sol)
    return {n: pr[n]["p80_m"] for n in fs.stream_names if math.isfinite(pr[n]["p80_m"])}, t


def _timed(doc, reps: int) -> tuple[dict, float]:
    fs = from_dict(doc)
    runs = [_p80s(fs) for _ in range(reps)]
    return runs[0][0], statistics.median(t for _, t in runs)


def run(quick: bool = False) -> list[dict]:
    circuits = CIRCUITS[:2] if quick else CIRCUITS
    rows = []
    for name in circuits:
        ms = (2, 4, 8) if quick else RATIOS.get(name, (2, 4, 8, 16, 32))
        doc = document(name)
        finest = _with_ratio(doc, ms[-1], "class_average")
        fs = from_dict(finest)
        a, _ = _p80s(from_dict(refine_document(finest, 2, fs.grid)))
        b, _ = _p80s(from_dict(refine_document(finest, 4, fs.grid)))
        ref = {k: b[k] + (b[k] - a[k]) / 3.0 for k in b if k in a}
        for scheme in ("upper_edge", "class_average"):
            for m in ms:
                d = _with_ratio(doc, m, scheme)
                p80, t = _timed(d, 1 if m >= 32 else 3)
                errs = {k: abs(v / ref[k] - 1.0) for k, v in p80.items() if k in ref}
                worst = max(errs, key=errs.get)
                rows.append({"case": f"{name} 2^(1/{m})", "method": f"{name}: {scheme.replace('_', ' ')}",
                             "circuit": name, "scheme": scheme, "ratio": 2.0 ** (1.0 / m),
                             "classes": from_dict(d).grid.n, "runtime_s": t, "p80_rel_error": errs[worst],
                             "max_abs_error": errs[worst], "worst_stream": worst})
    rows.append(run_cost(3 if quick else 5))
    return rows


def run_cost(reps: int = 5) -> dict:
    """``millflow run``'s work on the closed circuit (parse, solve, stream properties, grid
    check, summary; no files) with class averages and with upper edges (the scheme before),
    interleaved, medians of ``reps``: the cost of the second-order discretisation."""
    from millflow.flowsheet.gridcheck import grid_check
    from millflow.flowsheet.results import summary

    doc = document("closed_circuit_ball_mill")
    times = {"class_average": [], "upper_edge": []}
    for _ in range(reps):
        for scheme in times:
            d = copy.deepcopy(doc)
            d["grid"]["scheme"] = scheme
            t0 = time.perf_counter()
            sol = solve(from_dict(d))
            props = stream_properties(sol)
            summary(sol, props, grid_check=grid_check(sol, props))
            times[scheme].append(time.perf_counter() - t0)
    new, old = statistics.median(times["class_average"]), statistics.median(times["upper_edge"])
    return {"case": "closed circuit run (solve + grid check)", "method": "run cost",
            "circuit": "closed_circuit_ball_mill", "scheme": "class_average / upper_edge", "runtime_s": new,
            "runtime_upper_edge_s": old, "ratio": new / old}


def format_table(rows: list[dict]) -> str:
    lines = [f"{'circuit':30s} {'scheme':14s} {'ratio':>9s} {'N':>5s} {'time ms':>9s} {'P80 error':>10s}  stream",
             "-" * 96]
    for r in rows:
        if r.get("method") == "run cost":
            lines.append(f"{r['case']}: class averages {1e3 * r['runtime_s']:.1f} ms, upper edges "
                         f"{1e3 * r['runtime_upper_edge_s']:.1f} ms (medians, interleaved): ratio {r['ratio']:.2f}")
            continue
        lines.append(f"{r['circuit']:30s} {r['scheme']:14s} {r['ratio']:9.5f} {r['classes']:5d} "
                     f"{1e3 * r['runtime_s']:9.2f} {100 * r['p80_rel_error']:9.4f}%  {r['worst_stream']}")
    return "\n".join(lines)


def figure(rows: list[dict], path) -> None:
    """Draw the rows as docs/img/grid_convergence.png does: per circuit, P80 error [%]
    against solve time, class averages solid, upper edges dashed (matplotlib, PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 5.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    rows = [r for r in rows if r.get("method") != "run cost"]
    circuits = sorted({r["circuit"] for r in rows})
    for k, c in enumerate(circuits):
        for scheme, ls, mk in (("upper_edge", "--", "s"), ("class_average", "-", "o")):
            pts = sorted((r["classes"], r["runtime_s"], r["p80_rel_error"]) for r in rows
                         if r["circuit"] == c and r["scheme"] == scheme)
            ax.loglog([p[1] for p in pts], [100 * p[2] for p in pts], ls, marker=mk, color=f"C{k}", ms=4,
                      label=f"{c.replace('_', ' ')}: {scheme.replace('_', ' ')}")
    ax.axhline(0.5, color="k", lw=0.8, ls=":")
    ax.set_xlabel("solve time [s] (median; ratio 2^(1/2) ... 2^(1/32) along each line)")
    ax.set_ylabel("largest relative P80 error over the streams [%]")
    ax.set_title("millflow bench grid: P80 error against run time, class averages (solid) vs upper edges "
                 "(dashed); dotted: 0.5 %", fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=5.5, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":  # python -m millflow.bench.grid rows.json out.png (rows from --json)
    import json
    import sys

    figure(json.loads(open(sys.argv[1]).read()), sys.argv[2])
