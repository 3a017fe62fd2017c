"""``millflow sweep FILE.toml --vary KEY=START:STOP:N [--vary ...] [--samples N --seed S]``:
solve a flowsheet over a grid (or a Latin hypercube) of its inputs.

Every case is solved (in chunks, on a Dask LocalCluster of this machine's cores, on the
scheduler at ``--scheduler ADDRESS``, or ``--scheduler serial`` in this process). The
result is one xarray Dataset with a dimension per varied key (a ``case`` dimension for
Latin-hypercube samples), written with a tidy CSV and plots of P80, circulating load
and kWh/t against each key into ``--out`` (default ``<stem>-sweep/``). A case that fails
is NaN with its reason; it never aborts the sweep.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("sweep", help="solve a flowsheet over a grid or sample of its inputs (Dask)",
                              description=__doc__.split("\n\n")[0],
                              epilog="example: millflow sweep flowsheets/closed_circuit_ball_mill.toml "
                                     "--vary units.ball_mill.tau_min=2:6:5 "
                                     "--vary units.fresh_feed.solids_tph=150:300:4")
    p.add_argument("file", help="flowsheet file (TOML)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=START:STOP:N",
                   help="a numeric key of the file (dotted path) and its range; repeat for more keys")
    p.add_argument("--samples", type=int, default=None, help="Latin-hypercube cases instead of the full grid")
    p.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube (default 0)")
    p.add_argument("--scheduler", default="local",
                   help="'local' (a LocalCluster, default), 'serial', or a Dask scheduler address")
    p.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: all cores)")
    add_output_flags(p, out="output folder (default: <file stem>-sweep)",
                     json="print a JSON summary instead of the text one",
                     plots="do not write the plots")
    p.set_defaults(func=run)


def run(args) -> int:
    from millflow.commands.output import check_target, staged_folder
    from millflow.errors import InputError
    from millflow.sweep import parse_vary, run_sweep

    path = Path(args.file)
    axes = [parse_vary(v) for v in args.vary]
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}: expected a whole number >= 1")
    out = Path(args.out) if args.out else Path.cwd() / f"{path.stem}-sweep"
    check_target(out, overwrite=args.overwrite, input_path=path)
    from millflow.progress import shown

    # sweep's bar of cases, under the one rule of millflow.progress: on a terminal, not with --quiet
    ds = run_sweep(path, axes, samples=args.samples, seed=args.seed, scheduler=args.scheduler,
                   workers=args.workers, progress=shown(not args.quiet))
    summary = {"file": str(path), "cases": int(ds.attrs["n_cases"]), "failed": int(ds.attrs["n_failed"]),
               "design": ds.attrs["design"], "varied": ds.attrs["varied"], "out": str(out)}
    with staged_folder(out, overwrite=args.overwrite, input_path=path, command="sweep") as tmp:
        ds.to_netcdf(tmp / "sweep.nc")
        cases = ds.to_dataframe().reset_index()
        cases.to_csv(tmp / "sweep.csv", index=False, float_format="%.6g")
        from millflow.report.html import finite
        from millflow.report.studies import SWEEP_ROWS, sweep_report, write_page

        # summary.json: the summary, and the first rows of sweep.csv that report.html shows
        page_data = dict(summary, keys=[a.key for a in axes], columns=[str(c) for c in cases.columns],
                         rows=finite(cases.head(SWEEP_ROWS).values.tolist()), n_rows=len(cases))
        (tmp / "summary.json").write_text(json.dumps(page_data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        write_page(tmp / "report.html", sweep_report(page_data, ds, input_path=path))
        if not args.no_plots:
            _plots(ds, axes, tmp / "sweep.png")
    if args.json:
        print(json.dumps(summary))
    else:  # --quiet hides progress only
        print(f"{path}: {summary['cases']} cases ({summary['design']}; {summary['varied']}), "
              f"{summary['failed']} failed; written to {out}/")
    if summary["cases"] and summary["failed"] == summary["cases"]:
        reason = str(ds["reason"].values.ravel()[0])
        print(f"millflow sweep: error: every case failed (written to {out}/); the first: {reason}", file=sys.stderr)
        return 1
    if summary["failed"]:
        print(f"millflow sweep: warning: {summary['failed']} of {summary['cases']} cases failed; "
              "their reasons are in the 'reason' variable", file=sys.stderr)
    return 0


def _plots(ds, axes, path) -> None:
    """P80, circulating load and kWh/t against each varied key (others at their middle)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if "case" in ds.dims:
        flat = ds
    elif len(axes) == 1:
        flat = ds.rename({axes[0].key: "case"}).assign_coords({axes[0].key: ("case", ds[axes[0].key].values)})
    else:
        flat = ds.stack(case=[a.key for a in axes]).reset_index("case")
    fig = Figure(figsize=(4.0 * len(axes), 8.0))
    FigureCanvasAgg(fig)
    rows = [("p80_um", "P80 [um]"), ("circulating_load", "circulating load [-]"),
            ("specific_energy_kWh_per_t", "kWh/t")]
    axs = fig.subplots(len(rows), len(axes), squeeze=False)
    for j, a in enumerate(axes):
        x = flat[a.key].values
        for i, (var, label) in enumerate(rows):
            if var not in flat:  # e.g. no recycle stream in an open circuit
                axs[i, j].set_ylabel(label + " (none)", fontsize=7)
                continue
            y = flat[var]
            for extra in [d for d in y.dims if d != "case"]:
                for name in y[extra].values:
                    axs[i, j].plot(x, y.sel({extra: name}).values, ".", ms=3, label=str(name))
            if y.dims == ("case",):
                axs[i, j].plot(x, y.values, ".", ms=3)
            axs[i, j].set_xlabel(a.key, fontsize=7)
            axs[i, j].set_ylabel(label, fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
