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
    rtd_cli.add_arguments(p)
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder for fit.json and fit.png (default <csv stem>-rtd/)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an output folder that holds files millflow did not write")
    p.set_defaults(func=run)


def run(args) -> int:
    """Fit, print, write; return the exit code (0). rtd's errors become InputError
    (their messages name the file and the column)."""
    from millflow.commands.output import check_target, staged_folder

    out = Path(args.out) if args.out else (None if args.no_plots else Path.cwd() / f"{Path(args.csv).stem}-rtd")
    if out is not None:
        check_target(out, overwrite=args.overwrite, input_path=args.csv)
    try:
        path, curve = rtd_cli.load_curve(args.csv, args.kind, args.baseline)
        result = rtd_cli.fit_curve(path, curve, args.model, args.cells)
    except rtd.RTDError as err:
        raise InputError(str(err)) from None
    plot = None if (out is None or args.no_plots) else out / "fit.png"
    js = rtd_cli.to_json(result, args.model, curve.time_unit, plot)
    if args.json:
        print(json.dumps(js), flush=True)
        if js["lack_of_fit"]["flag"]:  # also said where a person reads it
            import sys
            print(f"millflow fit-rtd: warning: lack of fit ({'; '.join(js['lack_of_fit']['reasons'])})",
                  file=sys.stderr)
    elif not args.quiet:
        print(rtd_cli.text(path, result, args.model, curve.time_unit), flush=True)
    if out is not None:
        with staged_folder(out, overwrite=args.overwrite, input_path=path, command="fit-rtd") as tmp:
            (tmp / "fit.json").write_text(json.dumps(js, indent=1) + "\n", encoding="utf-8")
            if plot is not None:
                rtd_cli.write_plot(result, tmp / "fit.png", curve.time_unit, args.model)
        if not args.quiet and not args.json:
            print(f"wrote {out}/ (fit.json{', fit.png' if plot is not None else ''})")
    return 0

