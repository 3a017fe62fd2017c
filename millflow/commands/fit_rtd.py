"""`millflow fit-rtd`: fit a residence time distribution model to a tracer CSV.

Reads the CSV with :func:`rtd.read_tracer_csv` (``time_<unit>``, ``concentration`` or
``F``, optional ``inlet``), prints the curve's moments (mean, variance, N from the
variance), fits each ``--model`` (repeatable) with :func:`rtd.fit` (least squares,
standard errors from eq. 9), prints the estimates, a comparison table (SSR, AIC, BIC)
when several models are fitted, and a warning for every parameter that ended on a
bound; with ``--json`` one JSON object (the lowest-AIC fit, ``moments``, and ``models``
with every fit). Writes ``fit.json`` and a plot of data, best fit and residuals (``fit.png``) into the folder ``--out``
(default ``<csv stem>-rtd/`` in the current folder; with ``--no-plots`` and no ``--out``
nothing is written).
tau is reported in the file's time unit. Errors in the file become InputError naming
the file and the column.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import rtd
from rtd import cli as rtd_cli
from millflow.errors import InputError


def add_parser(subparsers) -> None:
    """Register the ``fit-rtd`` sub-command (the arguments of ``python -m rtd fit``)."""
    p = subparsers.add_parser(
        "fit-rtd", help="fit an RTD model to tracer data",
        description="Fit a residence time distribution model to a tracer CSV "
                    "(columns time_<unit>, concentration or F, optional inlet).",
        epilog="example: millflow fit-rtd docs/examples/tracer_tis.csv --model tis --out tis-fit")
    rtd_cli.add_arguments(p, several_models=True)
    from millflow.commands.output import QUIET_HELP

    for action in p._actions:  # --quiet means what it means in every millflow command
        if "--quiet" in action.option_strings:
            action.help = QUIET_HELP
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder for fit.json and fit.png (default <csv stem>-rtd/)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an output folder that holds files millflow did not write")
    p.set_defaults(func=run)


def tracer_moments(curve) -> dict:
    """Mean [time], variance [time^2] and the tanks-in-series number from the variance,
    N = mean^2 / variance (Levenspiel, Chemical Reaction Engineering, 3rd ed., eq. 11.17
    and ch. 14), of a pulse (E) or step (F) response, by trapezoids (:func:`rtd.tracer.moments`)."""
    from rtd.tracer import moments, step_moments

    m = moments(curve.t, curve.c) if curve.kind == "pulse" else step_moments(curve.t, curve.c)
    n = m.mean ** 2 / m.variance if m.variance > 0 else float("inf")
    return {"mean": m.mean, "variance": m.variance, "n_from_variance": n, "note": m.note}


def params_at_bounds(result, mean: float) -> list[str]:
    """Parameters of a fit that ended on a bound of :data:`rtd.fit.BOUNDS` (tau's scale
    with the data's mean): there the standard error and the model ranking mean little
    (the model collapses to a simpler one, e.g. recirculating cells with r -> 0)."""
    from rtd.fit import BOUNDS

    out = []
    for k, v in zip(result.names, result.values):
        if k not in BOUNDS:
            continue
        lo, hi, logs = BOUNDS[k]
        if k == "tau":
            lo, hi = lo * mean, hi * mean
        for edge, side in ((lo, "lower"), (hi, "upper")):
            # fitted in logs: a relative distance; linear: a tiny fraction of the range
            near = (abs(math.log(v / edge)) < 1e-6 if logs and v > 0 and edge > 0
                    else abs(v - edge) <= 1e-9 * (hi - lo))
            if near:
                out.append(f"{k} = {v:.3g} at its {side} bound {edge:g}")
    return out


def comparison_table(fits: dict, time_unit: str) -> str:
    """Models side by side: parameters, SSR, AIC, BIC and AIC difference to the best."""
    best = min(r.aic for r, _ in fits.values())
    rows = []
    for name, (r, bounds) in sorted(fits.items(), key=lambda kv: kv[1][0].aic):
        par = ", ".join(f"{k} {v:.4g}" + ("" if not math.isfinite(se) else f" ± {se:.2g}")
                        for k, v, se in zip(r.names, r.values, r.se))
        rows.append([name, str(r.n_params), f"{r.ssr:.4g}", f"{r.aic:.2f}", f"{r.bic:.2f}",
                     f"{r.aic - best:.2f}", par + (" (at a bound)" if bounds else "")])
    head = ["model", "params", "SSR", "AIC", "BIC", "dAIC", f"parameters (tau in {time_unit})"]
    width = [max(len(x[k]) for x in [head] + rows) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(head, width)).rstrip(),
             "  ".join("-" * w for w in width)]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, width)).rstrip() for r in rows]
    lines.append("lowest AIC first; dAIC > 2: less support, > 10: essentially none (Burnham and Anderson 2002)")
    return "\n".join(lines)


def run(args) -> int:
    """Fit, print, write; return the exit code (0). rtd's errors become InputError
    (their messages name the file and the column)."""
    import sys

    from millflow.commands.output import check_target, staged_folder

    models = list(dict.fromkeys(args.model or ["tis"]))
    out = Path(args.out) if args.out else (None if args.no_plots else Path.cwd() / f"{Path(args.csv).stem}-rtd")
    if out is not None:
        check_target(out, overwrite=args.overwrite, input_path=args.csv)
    fits = {}
    from millflow.progress import progress

    try:
        path, curve = rtd_cli.load_curve(args.csv, args.kind, args.baseline)
        mom = tracer_moments(curve)
        from millflow.mill.transport import is_network

        if args.cells is not None and not any(is_network(m) for m in models):
            raise rtd.RTDError(f"--cells {args.cells}: applies to --model recirculating_cells (or cells) only")
        with progress("millflow fit-rtd", [f"fit {m}" for m in models], enabled=not args.quiet) as stage:
            for name in models:  # --cells belongs to the recirculating-cells model among several
                stage(f"fit {name}")
                cells = args.cells if is_network(name) else None
                result = rtd_cli.fit_curve(path, curve, name, cells)
                fits[name] = (result, params_at_bounds(result, mom["mean"]))
    except rtd.RTDError as err:
        raise InputError(str(err)) from None
    unit = curve.time_unit or "time unit"
    best = min(fits, key=lambda m: fits[m][0].aic)
    plot = None if (out is None or args.no_plots) else out / "fit.png"
    docs = {}
    for name, (result, bounds) in fits.items():
        js = rtd_cli.to_json(result, name, curve.time_unit, plot if name == best else None)
        js["at_bounds"] = bounds
        docs[name] = js
    js = dict(docs[best])
    js["moments"] = {"mean": mom["mean"], "variance": mom["variance"], "n_from_variance": mom["n_from_variance"],
                     "time_unit": curve.time_unit, "note": mom["note"]}
    if len(fits) > 1:
        js["best_model"] = best
        js["models"] = docs
    if args.json:
        print(json.dumps(js), flush=True)
        for name, d in docs.items():  # also said where a person reads it
            if d["lack_of_fit"]["flag"]:
                print(f"millflow fit-rtd: warning: {name}: lack of fit ({'; '.join(d['lack_of_fit']['reasons'])})",
                      file=sys.stderr)
            for b in d["at_bounds"]:
                print(f"millflow fit-rtd: warning: {name}: {b}", file=sys.stderr)
    else:
        print(f"{path}: moments of the {'pulse' if curve.kind == 'pulse' else 'step'} response: "
              f"mean {mom['mean']:.4g} {unit}, variance {mom['variance']:.4g} {unit}^2, "
              f"N from the variance (mean^2/variance) {mom['n_from_variance']:.3g}"
              + (f" ({mom['note']})" if mom["note"] else ""))
        for name, (result, bounds) in fits.items():
            print(rtd_cli.text(path, result, name, curve.time_unit), flush=True)
            for b in bounds:
                print(f"warning: {name}: {b}: its standard error means little and the model reduces to a "
                      "simpler one")
        if len(fits) > 1:
            print("model comparison:")
            print(comparison_table(fits, unit))
    if out is not None:
        with staged_folder(out, overwrite=args.overwrite, input_path=path, command="fit-rtd") as tmp:
            (tmp / "fit.json").write_text(json.dumps(js, indent=1) + "\n", encoding="utf-8")
            if plot is not None:
                rtd_cli.write_plot(fits[best][0], tmp / "fit.png", curve.time_unit, best)
        if not args.json:
            print(f"wrote {out}/ (fit.json{', fit.png' if plot is not None else ''})")
    return 0
