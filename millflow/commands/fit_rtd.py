"""`millflow fit-rtd`: fit a residence time distribution model to a tracer CSV.

Reads the CSV with :func:`rtd.read_tracer_csv` (``time_<unit>``, ``concentration`` or
``F``, optional ``inlet``), fits one model with :func:`rtd.fit` (least squares, standard
errors from eq. 9), prints the estimates (or one JSON object with ``--json``) and writes
``fit.json`` and a plot of data, fit and residuals (``fit.png``) into the folder ``--out``
(default ``<csv stem>-rtd/`` in the current folder; with ``--no-plots`` and no ``--out``
nothing is written).
tau is reported in the file's time unit. Errors in the file become InputError naming
the file and the column.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

import rtd
from millflow.errors import InputError


def add_parser(subparsers) -> None:
    """Register the ``fit-rtd`` sub-command."""
    p = subparsers.add_parser(
        "fit-rtd", help="fit an RTD model to tracer data",
        description="Fit a residence time distribution model to a tracer CSV "
                    "(columns time_<unit>, concentration or F, optional inlet).",
        epilog="example: millflow fit-rtd docs/examples/tracer_tis.csv --model tis --out tis-fit")
    p.add_argument("csv", metavar="TRACER.csv", help="tracer data file")
    p.add_argument("--model", choices=sorted(rtd.MODELS), default="tis",
                   help="model to fit (default: tis)")
    p.add_argument("--cells", type=int, default=3, metavar="N",
                   help="number of cells for --model cells (default 3)")
    p.add_argument("--kind", choices=["pulse", "step"], default=None,
                   help="pulse (E) or step (F) response; default from the columns")
    p.add_argument("--baseline", default=None, metavar="head|tail|VALUE",
                   help="subtract a baseline: median of the first/last 5 points or a value")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder for fit.json and fit.png (default <csv stem>-rtd/)")
    p.add_argument("--no-plots", "--no-plot", dest="no_plots", action="store_true",
                   help="do not write the plot")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an output folder that holds files millflow did not write")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors (and --json output)")
    p.set_defaults(func=run)


def _load(args):
    path = Path(args.csv)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        curve = rtd.read_tracer_csv(path, kind=args.kind)
        if args.baseline is not None:
            base = args.baseline
            try:
                base = float(base)
            except ValueError:
                pass
            curve = rtd.subtract_baseline(curve, base)
    except rtd.TracerError as err:  # its message names the file and the column
        raise InputError(str(err)) from None
    return path, curve


def run(args) -> int:
    """Fit, print, plot; return the exit code (0)."""
    path, curve = _load(args)
    fixed = {"n": args.cells} if args.model == "cells" else {}
    try:
        result = rtd.fit(args.model, curve, **fixed)
    except rtd.TracerError as err:
        col = f", column {err.column!r}" if err.column else ""
        raise InputError(f"{path}{col}: {err}") from None
    except rtd.RTDError as err:
        raise InputError(f"{path}: {err}") from None
    out = Path(args.out) if args.out else (None if args.no_plots else Path.cwd() / f"{path.stem}-rtd")
    plot = None if (out is None or args.no_plots) else out / "fit.png"
    js = to_json(result, args.model, curve.time_unit, plot)
    if args.json:
        print(json.dumps(js), flush=True)
    elif not args.quiet:
        print(f"{path}: {args.model} fit, times in {curve.time_unit}")
        print(result.summary(), flush=True)
    if out is not None:
        from millflow.commands.output import staged_folder

        with staged_folder(out, overwrite=args.overwrite, input_path=path, command="fit-rtd") as tmp:
            (tmp / "fit.json").write_text(json.dumps(js, indent=1) + "\n", encoding="utf-8")
            if plot is not None:
                write_plot(result, tmp / "fit.png", curve.time_unit, args.model)
        if not args.quiet and not args.json:
            print(f"wrote {out}/ (fit.json{', fit.png' if plot is not None else ''})")
    return 0


def to_json(result, name: str, time_unit: str, plot) -> dict:
    """{"model", "params": {name: {"value", "se"}}, "ssr", "ser", "aic", "bic", ...}."""
    d = result.to_dict()
    return {"model": name, "repr": d["model"], "time_unit": time_unit, "params": d["params"],
            "scale": d["scale"], "ssr": d["ssr"], "ser": d["ser"], "r2": d["r2"],
            "aic": d["aic"], "bic": d["bic"], "n_data": d["n_data"], "notes": d["notes"],
            "plot": None if plot is None else str(plot)}


def write_plot(result, path: Path, time_unit: str, name: str) -> None:
    """Data, fitted curve and residuals (model - data) in two panels."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bot) = plt.subplots(2, 1, figsize=(7, 6), sharex=True,
                                   gridspec_kw={"height_ratios": [3, 1]})
    top.plot(result.t, result.data, "o", ms=3, label="data")
    fine = result.t if result.inlet is not None else np.linspace(result.t[0], result.t[-1], 400)
    top.plot(fine, result.curve(fine), "-", label=f"{name}: {_label(result)}")
    top.set_ylabel("concentration" if result.kind == "pulse" else "F")
    top.legend(fontsize=8)
    bot.axhline(0.0, color="0.5", lw=0.8)
    bot.plot(result.t, result.residuals, ".", ms=4)
    bot.set_ylabel("model - data")
    bot.set_xlabel(f"time [{time_unit}]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _label(result) -> str:
    parts = []
    for key, (value, se) in result.params.items():
        if se is None:
            continue
        err = "" if se is None or not math.isfinite(se) else f"±{se:.2g}"
        parts.append(f"{key}={value:.4g}{err}")
    return ", ".join(parts) or repr(result.model)
