"""``python -m rtd fit TRACER.csv``: fit a residence time distribution to a tracer curve.

Standalone (imports nothing from millflow); ``millflow fit-rtd`` uses the same
functions. The CSV has ``time_<unit>``, ``concentration`` (pulse) or ``F`` (step) and an
optional ``inlet`` column; tau is reported in the file's time unit. Prints the
estimates with standard errors (or one JSON object with ``--json``) and, with
``--out DIR``, writes ``fit.json`` and ``fit.png`` (data, fit, residuals) into DIR.
Exit status: 0 done, 2 bad input (one line naming the file and column), 1 failed fit.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from rtd.base import RTDError
from rtd.fit import MODELS, fit
from rtd.names import canonical_name
from rtd.tracer import TracerError, read_tracer_csv, subtract_baseline


def add_arguments(p: argparse.ArgumentParser, several_models: bool = False) -> None:
    """The arguments of the tracer fit (shared with ``millflow fit-rtd``, which takes
    ``--model`` repeatedly: ``several_models``)."""
    p.add_argument("csv", metavar="TRACER.csv", help="tracer data file")
    if several_models:  # repeated --model: each is fitted and the fits are compared
        p.add_argument("--model", choices=sorted(MODELS), action="append", default=None,
                       help="model to fit (default: tis); repeat to fit several and compare them")
    else:
        p.add_argument("--model", choices=sorted(MODELS), default="tis", help="model to fit (default: tis)")
    p.add_argument("--cells", type=int, default=None, metavar="N",
                   help="number of cells of --model recirculating_cells (or any of its aliases; default 3)")
    p.add_argument("--kind", choices=["pulse", "step"], default=None,
                   help="pulse (E) or step (F) response; default from the columns")
    p.add_argument("--baseline", default=None, metavar="head|tail|VALUE",
                   help="subtract a baseline: median of the first/last 5 points or a value")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-plots", "--no-plot", dest="no_plots", action="store_true", help="do not write the plot")
    p.add_argument("--quiet", action="store_true", help="no progress messages (results still print)")


def load_curve(csv, kind=None, baseline=None):
    """(path, TracerCurve); a TracerError's message names the file and the column."""
    path = Path(csv)
    if not path.is_file():
        raise TracerError(f"{path}: no such file")
    curve = read_tracer_csv(path, kind=kind)
    if baseline is not None:
        try:
            baseline = float(baseline)
        except ValueError:
            pass
        curve = subtract_baseline(curve, baseline)
    return path, curve


def fit_curve(path, curve, model: str, cells: int | None = None):
    """Fit ``model`` to the curve; errors name the file (and column).

    ``cells`` is the fixed number of cells of the recirculating-cells model (under any of
    its names; default 3) and is refused for a model without cells.
    """
    has_cells = canonical_name(model) == "recirculating_cells"
    if cells is not None and not has_cells:
        raise RTDError(f"--cells {cells}: model {model!r} has no cells; give --cells only with "
                       "--model recirculating_cells (or its alias cells)")
    if cells is not None and cells < 1:
        raise RTDError(f"--cells {cells}: expected a whole number >= 1")
    fixed = {"n": 3 if cells is None else cells} if has_cells else {}
    try:
        return fit(model, curve, **fixed)
    except TracerError as err:
        col = f", column {err.column!r}" if getattr(err, "column", None) else ""
        raise TracerError(f"{path}{col}: {err}") from None
    except RTDError as err:
        raise RTDError(f"{path}: {err}") from None


def to_json(result, name: str, time_unit: str, plot) -> dict:
    """{"model", "params": {name: {"value", "se"}}, "ssr", "ser", "aic", "bic", ...}."""
    d = result.to_dict()
    return {"model": name, "repr": d["model"], "time_unit": time_unit, "params": d["params"],
            "scale": d["scale"], "ssr": d["ssr"], "ser": d["ser"], "r2": d["r2"],
            "aic": d["aic"], "bic": d["bic"], "n_data": d["n_data"], "notes": d["notes"],
            "lack_of_fit": d["lack_of_fit"], "plot": None if plot is None else str(plot)}


def text(path, result, name: str, time_unit: str) -> str:
    return f"{path}: {name} fit, times in {time_unit}\n{result.summary()}"


def write_plot(result, path: Path, time_unit: str, name: str) -> None:
    """Data, fitted curve and residuals (model - data) in two panels (Agg canvas: no
    display and no global backend switch)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 6))
    FigureCanvasAgg(fig)
    top, bot = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
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


def _check_plotting() -> None:
    """Refuse before fitting when fit.png is asked for and matplotlib is absent (the
    standalone distribution has it as the optional extra ``plot``)."""
    import importlib.util

    if importlib.util.find_spec("matplotlib") is None:
        raise RTDError("--out: the plot fit.png needs matplotlib (python -m pip install 'millflow-rtd[plot]'); "
                       "or give --no-plots")


def _label(result) -> str:
    parts = []
    for key, (value, se) in result.params.items():
        if se is None:
            continue
        err = "" if not math.isfinite(se) else f"±{se:.2g}"
        parts.append(f"{key}={value:.4g}{err}")
    return ", ".join(parts) or repr(result.model)


def _write_folder(out: Path, js: dict, result, time_unit: str, name: str, plots: bool, overwrite: bool) -> None:
    """fit.json (+ fit.png) into ``out``, staged in a temporary folder beside it; a
    non-empty ``out`` holding other files is refused unless ``overwrite``."""
    ours = {"fit.json", "fit.png"}
    if out.exists() and (not out.is_dir() or (set(os.listdir(out)) - ours and not overwrite)):
        raise TracerError(f"--out {out}: exists and holds other files; choose another folder or give --overwrite")
    if not out.resolve().parent.is_dir():
        raise TracerError(f"--out {out}: the parent folder does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.rtd-", dir=out.resolve().parent))
    try:
        (tmp / "fit.json").write_text(json.dumps(js, indent=1) + "\n", encoding="utf-8")
        if plots:
            write_plot(result, tmp / "fit.png", time_unit, name)
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rtd", description="Residence time distributions.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    p = sub.add_parser("fit", help="fit an RTD model to a tracer CSV",
                       description="Fit a residence time distribution model to a tracer CSV "
                                   "(columns time_<unit>, concentration or F, optional inlet).",
                       epilog="example: python -m rtd fit tracer.csv --model tis --out tis-fit")
    add_arguments(p)
    p.add_argument("--out", default=None, metavar="DIR", help="folder for fit.json and fit.png (default: none)")
    p.add_argument("--overwrite", action="store_true", help="replace a folder that holds other files")
    args = parser.parse_args(argv)
    try:
        if args.out is not None and not args.no_plots:
            _check_plotting()
        path, curve = load_curve(args.csv, args.kind, args.baseline)
        result = fit_curve(path, curve, args.model, args.cells)
        out = None if args.out is None else Path(args.out)
        plot = None if (out is None or args.no_plots) else out / "fit.png"
        js = to_json(result, args.model, curve.time_unit, plot)
        if args.json:
            print(json.dumps(js), flush=True)
            if js["lack_of_fit"]["flag"]:
                print(f"python -m rtd fit: warning: lack of fit ({'; '.join(js['lack_of_fit']['reasons'])})",
                      file=sys.stderr)
        else:  # --quiet hides progress only: the results still print
            print(text(path, result, args.model, curve.time_unit), flush=True)
        if out is not None:
            _write_folder(out, js, result, curve.time_unit, args.model, not args.no_plots, args.overwrite)
    except (RTDError, OSError) as err:
        print(f"python -m rtd fit: error: {err}", file=sys.stderr)
        return 2 if isinstance(err, RTDError) else 1
    except KeyboardInterrupt:
        print("python -m rtd fit: interrupted", file=sys.stderr)
        return 130
    return 0
