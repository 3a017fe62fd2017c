"""`millflow run FILE.toml [--out DIR] [--json] [--no-plots] [--overwrite] [--quiet]
[--tear-method M]`: solve a flowsheet.

Prints a compact table (stream, t/h, P80, P50, % passing the named sizes), the
circulating loads, mass balance, specific energy and run time, and writes results.nc,
CSV tables, summary.json, PNG plots, report.html (one self-contained page: flowsheet,
tables, plots, input file) and, whenever openpyxl is installed (extra ``report``),
results.xlsx to the output folder (default ``<file stem>-results/`` in the current
directory). With ``--json`` one JSON object
(the summary) is printed instead of the table.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from millflow.commands.output import add_output_flags, deprecated_alias


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("run", help="solve a flowsheet file (TOML) and write its results",
                              description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("file", help="flowsheet file (TOML), e.g. flowsheets/closed_circuit_ball_mill.toml")
    add_output_flags(p, out="output folder (default: <file stem>-results)",
                     json="print one JSON object instead of the table",
                     plots="do not write the PNG plots")
    p.add_argument("--no-grid-check", action="store_true",
                   help="skip the second solve on a refined size grid (Principle IV)")
    p.add_argument("--tear-method", default="wegstein", dest="tear_method",
                   help="tear method for nonlinear units (wegstein, newton, substitution)")
    deprecated_alias(p, "--method", "--tear-method", "tear_method")
    p.set_defaults(func=run)


def _f(v, fmt="{:.4g}") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def format_summary(s: dict, out_dir: str | None, written: list[str] | None = None) -> str:
    """The terminal summary as text."""
    streams = s["streams"]
    sizes = list(next(iter(streams.values()))["passing_pct"]) if streams else []
    wet = any("water_tph" in st for st in streams.values())
    head = ["stream", "from -> to", "t/h"] + (["water t/h", "% solids"] if wet else []) + ["P80 um", "P50 um"] \
        + [f"%-{x}um" for x in sizes]
    rows = []
    for name, st in streams.items():
        slurry = [_f(st.get("water_tph"), "{:.1f}"), _f(st.get("solids_content_pct"), "{:.1f}")] if wet else []
        rows.append([name, f"{st['from']} -> {st['to']}", _f(st["solids_tph"], "{:.1f}")] + slurry
                    + [_f(st["p80_um"], "{:.0f}"), _f(st["p50_um"], "{:.0f}")]
                    + [_f(st["passing_pct"][x], "{:.1f}") for x in sizes])
    width = [max(len(str(r[k])) for r in [head] + rows) for k in range(len(head))]
    lines = [s["title"] or s["source_file"], ""]
    for r in [head] + rows:
        lines.append("  ".join(str(c).ljust(w) if k < 2 else str(c).rjust(w) for k, (c, w) in enumerate(zip(r, width))))
        if r is head:
            lines.append("  ".join("-" * w for w in width))
    lines.append("")
    cl = s["circulating_load"]
    if cl:
        lines.append("circulating load (recycle / new feed): " + ", ".join(
            f"{u} {_f(100 * v, '{:.1f}')} %" for u, v in cl.items()))
    for u, r in s["units"].items():
        if r.get("specific_energy_kWh_per_t") is not None:
            role = " (drives breakage)" if str(r.get("power_role", "")).startswith("drives") else ""
            tau = f", tau {r['tau_s'] / 60:.4g} min ({r['tau_from'].split(' (')[0]})" if r.get("tau_from") else ""
            lines.append(f"{u}: {r['power_kW']:.4g} kW{role}, {r['specific_energy_kWh_per_t']:.3g} kWh/t of mill "
                         f"feed{tau}")
    for note in s.get("notes") or []:
        lines.append(f"note: {note}")
    if s["specific_energy_kWh_per_t"] is not None:
        lines.append(f"circuit specific energy: {s['specific_energy_kWh_per_t']:.3g} kWh/t of product")
    worst = max(s["unit_mass_balance_error"].values())
    lines.append(f"mass balance error: overall {_f(s['mass_balance_error'], '{:.1e}')}, worst unit {worst:.1e}")
    if wet:
        w_worst = max((r.get("water_balance_error", 0.0) or 0.0) for r in s["units"].values())
        lines.append(f"water balance error: overall {_f(s.get('water_balance_error'), '{:.1e}')}, "
                     f"worst unit {w_worst:.1e}")
    g = s.get("grid_check")
    if g and g.get("status") in ("ok", "grid too coarse"):
        line = (f"grid error (Richardson, order {g.get('order', '?')}, vs {g['refined_classes']} classes): P80, P50 "
                f"and circulating loads within {100 * g['worst']:.2g} % of the converged values ({g['worst_at']})")
        if g["status"] == "ok":
            lines.append(line + f": within {100 * g['threshold']:.3g} %")
        else:
            lines.append(line + f": the grid is too coarse for {100 * g['threshold']:.3g} % "
                                "(refine grid.ratio or grid.n)")
    elif g and g.get("status") == "not available":
        lines.append(f"grid error: not estimated: {g.get('reason', '')}")
    tear = s["solver"].get("tear")
    how = s["solver"]["structure"]
    if tear:
        how += f" ({tear['method']}, {tear['iterations']} iterations, last change {tear['residual_history'][-1]:.1e})"
    lines.append(f"solved in {1e3 * s['runtime_s']:.1f} ms: {how}; kernel {s.get('kernel', '?')}")
    if out_dir:
        names = written if written is not None else ["results.nc", "streams.csv", "units.csv", "psd.csv",
                                                      "summary.json", "psd.png", "classifiers.png", "flowsheet.png"]
        lines.append(f"results written to {out_dir}/ ({', '.join(names)})")
    return "\n".join(lines)


#: N x N float64 matrices a linear flowsheet run holds at its peak, per grid, calibrated
#: against the peak resident memory of `millflow run` (N = 200..5000 classes; docs/reliability.md):
#: about 7 for the solve itself (b, B, the sparse system on the streams and its LU factors,
#: the results) and 7-8 per mill (its transfer matrix, the cells' or the eigenbasis'
#: workspace), 1 per other unit; measured 14.8 (one mill, five units), 21.9 (two mills, six
#: units), and 12 per (N^2 + N'^2) with the grid check. Counted with margin: 8 + 8 per
#: mill + 1 per other unit.
RUN_MATRICES_BASE = 8
RUN_MATRICES_PER_MILL = 8


def run_matrices(fs) -> int:
    """N x N matrices counted for a run of ``fs`` (see :data:`RUN_MATRICES_BASE`)."""
    mills = sum(1 for u in fs.units.values() if u.type == "mill")
    return RUN_MATRICES_BASE + RUN_MATRICES_PER_MILL * mills + (len(fs.units) - mills)


def _check_memory(fs, grid_check: bool) -> None:
    """What the run will allocate, before it does: its N x N matrices (:func:`run_matrices`)
    and the grid check's as many on 2N - 1 classes (the refined solve runs while the first
    solution is kept), within the budget (on top of what the process holds already)."""
    from millflow.grid import check_run_memory

    n = fs.grid.n
    check_run_memory(n, run_matrices(fs), 2 * n - 1 if grid_check else None,
                     f"{getattr(fs, 'source_file', '') or 'the flowsheet'}")


def run(args) -> int:
    from millflow.commands.output import check_target, relocate, staged_folder, write_extras
    from millflow.flowsheet import load, save, solve, summary
    from millflow.flowsheet.results import stream_properties

    path = Path(args.file)
    out = Path(args.out) if args.out else Path.cwd() / f"{path.stem}-results"
    check_target(out, overwrite=args.overwrite, input_path=path)  # before the work, not after
    from millflow.progress import stages

    names = ["solve"] + ([] if args.no_grid_check else ["grid check"]) + ["write"]
    with stages("millflow run", names, enabled=not args.quiet) as stage:
        stage("solve")
        fs = load(path)
        _check_memory(fs, grid_check=not args.no_grid_check)
        sol = solve(fs, method=args.tear_method)
        props = stream_properties(sol)  # once, for the grid check, the summary and the files
        check = None
        if not args.no_grid_check:
            import warnings

            from millflow.errors import ModelRangeWarning
            from millflow.flowsheet.gridcheck import grid_check

            stage("grid check")
            with warnings.catch_warnings():  # the refined solve repeats the range warnings the run has given
                warnings.simplefilter("ignore", ModelRangeWarning)
                check = grid_check(sol, props)
        s = summary(sol, props, grid_check=check)
        stage("write")
        with staged_folder(out, overwrite=args.overwrite, input_path=path, command="run") as tmp:
            written = save(sol, tmp, plots=not args.no_plots, grid_check=check, props=props)
            written.update(write_extras(sol, s, tmp, input_path=path, command="millflow run"))
            files = relocate(written.values(), tmp, out)
    s["output_dir"] = str(out)
    s["files_written"] = [Path(f).name for f in files]
    if args.json:
        print(json.dumps(s))
    else:
        try:
            shown = str(out.relative_to(Path.cwd()))
        except ValueError:
            shown = str(out)
        print(format_summary(s, shown, s["files_written"]))
    return 0
