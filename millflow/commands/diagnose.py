"""``millflow diagnose CONFIG.toml [--json]``: which model do the data support?

Fits the candidate set of a fit config (linear, slowing-down, fines cushioning,
aggregation; for continuous data alternative RTDs: tanks in series, recirculating cells
with r fitted, axial dispersion with Pe fitted; and a classification), ranks them by BIC,
AICc and leave-one-condition-out prediction error, reports the drift test and residual
structure of each, how far the design separates the close candidates, and a verdict per
parameter of the config's model (:mod:`millflow.fitting.diagnose`). Writes table.csv, results.nc and fits.png into the
output folder (default ``<config stem>-diagnose/`` in the current folder).
"""
from __future__ import annotations

import json
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("diagnose", help="rank candidate kinetics (linear, slowing-down, cushioning, "
                              "aggregation, RTDs) on a fit config's data", description=__doc__.splitlines()[0])
    p.add_argument("config", help="TOML fit configuration (see docs/fitting.md)")
    add_output_flags(p, out="output folder (default <config stem>-diagnose in the current folder)",
                     json="print one JSON object instead of the table", plots="do not write the plot")
    p.add_argument("--no-loco", action="store_true", help="skip the leave-one-condition-out refits")
    p.add_argument("--no-drift", action="store_true", help="skip the drift refits (short and long half)")
    p.add_argument("--no-separation", action="store_true",
                   help="skip the noise-free refits that say how far the design separates the close candidates")
    p.add_argument("--candidates", metavar="LABELS", default=None,
                   help="comma-separated candidates to fit, e.g. linear,tanks_2 (default: the whole set; "
                        "linear and the config's model are always fitted)")
    p.set_defaults(func=run)


def _dataset(diag):
    import numpy as np
    import xarray as xr

    rows = diag.table
    labels = [r["model"] for r in rows]
    num = lambda key: np.array([np.nan if r.get(key) is None else float(r[key]) for r in rows])  # noqa: E731
    ds = xr.Dataset(
        {"ssr": ("candidate", num("ssr"), {"long_name": "weighted sum of squared residuals", "units": "1"}),
         "n_params": ("candidate", num("n_params")),
         "bic": ("candidate", num("bic")), "aicc": ("candidate", num("aicc")),
         "delta_bic": ("candidate", num("delta_bic")),
         "loco_rmse": ("candidate", num("loco_rmse"), {"long_name": "leave-one-condition-out RMSE of passing",
                                                       "units": "1"}),
         "drift_pct": ("candidate", num("drift_pct"), {"long_name": "A(long half) / A(short half) - 1",
                                                       "units": "%"}),
         "drift_se": ("candidate", num("drift_se"), {"units": "SE"}),
         "lag1": ("candidate", num("lag1")), "runs_reject": ("candidate", num("runs_reject")),
         "separation_lambda": ("candidate", num("separation_lambda"),
                               {"long_name": "non-centrality of the best model against this candidate on this design "
                                             "(noise-free refit SSR / sigma^2; NaN: not computed)", "units": "1"}),
         "repeat_choice": ("candidate", num("repeat_choice"),
                           {"long_name": "probability that a repeat of the experiment prefers the best model by BIC "
                                         "(approximate; NaN: not computed)", "units": "1"})},
        coords={"candidate": labels},
        attrs={"best": diag.best, "user_model": diag.user, "verdicts": json.dumps(diag.verdicts),
               "notes": "; ".join(diag.notes)})
    return ds


def _plot(diag, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax, axr) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    first = next(iter(diag.fits.values()))
    y = first.model.y
    ax.plot(np.arange(y.size), y, "k.", ms=3, label="data")
    for label, r in diag.fits.items():
        pred = r.predicted()
        ax.plot(np.arange(y.size), pred, "-", lw=0.8, label=label)
        axr.plot(np.arange(y.size), pred - y, "-", lw=0.8, label=label)
    ax.set_ylabel("cumulative passing [-]")
    axr.set_ylabel("residual (model - data) [-]")
    axr.set_xlabel("measured value (samples in order, sieves coarse to fine)")
    axr.axhline(0.0, color="k", lw=0.5)
    ax.legend(fontsize=7)
    ax.set_title(f"candidates' fits; best supported (BIC): {diag.best}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args) -> int:
    from millflow.commands.output import check_target, staged_folder
    from millflow.fitting.config import load_config
    from millflow.fitting.diagnose import diagnose

    from millflow.progress import note, progress

    cfg = load_config(args.config)
    out = Path(args.out) if args.out else Path.cwd() / f"{Path(args.config).stem}-diagnose"
    check_target(out, overwrite=args.overwrite, input_path=args.config)  # before the fits, not after
    only = None if args.candidates is None else [c.strip() for c in args.candidates.split(",") if c.strip()]
    with progress("millflow diagnose", ["candidate fits"], enabled=not args.quiet) as stage:
        stage("candidate fits")
        diag = diagnose(cfg, progress=note, quiet=False, loco=not args.no_loco, drift=not args.no_drift,
                        separation=not args.no_separation, candidates=only)
    summary = diag.to_dict()
    with staged_folder(out, overwrite=args.overwrite, input_path=args.config, command="diagnose") as tmp:
        ds = _dataset(diag)
        ds.to_netcdf(tmp / "results.nc")
        ds.to_dataframe().to_csv(tmp / "table.csv", float_format="%.6g")  # 6 significant digits (docs/cli.md)
        files = ["results.nc", "table.csv"]
        if not args.no_plots:
            _plot(diag, tmp / "fits.png")
            files.append("fits.png")
    if args.json:
        print(json.dumps({**summary, "out": str(out), "files": files}))
    else:
        print(diag.text())
        print(f"files: {', '.join(files)} in {out}")  # --quiet hides progress only
    return 0
