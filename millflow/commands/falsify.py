"""``millflow falsify CONFIG.toml [--json] [--out DIR]``: a falsification study.

Generates synthetic measurements from a truth with model error, fits the assumed model
over replicates and strengths, and writes results.nc, summary.json, summary.csv and
bias_coverage.png into DIR (default ``<config stem>-falsify/`` in the current folder). The files
are written into a temporary folder beside DIR and renamed when complete; an existing
non-empty DIR is refused unless --overwrite. See docs/model-error.md.
"""
from __future__ import annotations

import json
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("falsify", help="measure how model error falsifies fitted breakage kinetics",
                              description=__doc__.splitlines()[0])
    p.add_argument("config", help="TOML configuration (see docs/model-error.md)")
    add_output_flags(p, out="output folder (default: <config stem>-falsify)",
                     json="print one JSON object instead of the text summary",
                     plots="do not write plots")
    p.set_defaults(func=run)


def run(args) -> int:
    from millflow.commands.output import check_target, staged_folder
    from millflow.falsify.config import load_config
    from millflow.falsify.plots import plot_sweep

    from millflow.progress import note, progress

    cfg = load_config(args.config)
    out = Path(args.out) if args.out else Path.cwd() / f"{Path(args.config).stem}-falsify"
    check_target(out, overwrite=args.overwrite, input_path=args.config)  # before the study, not after
    with progress("millflow falsify", ["study"], enabled=not args.quiet) as stage:
        stage("study")
        res = cfg.run(progress=note)
    summary = res.summary()
    with staged_folder(out, overwrite=args.overwrite, input_path=args.config, command="falsify") as tmp:
        res.dataset.to_netcdf(tmp / "results.nc")
        (tmp / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        table = res.dataset[["truth", "mean_estimate", "bias", "bias_se", "bias_pct", "coverage", "se_ratio"]]
        table.to_dataframe().to_csv(tmp / "summary.csv", float_format="%.6g")  # 6 significant digits (docs/cli.md)
        files = ["results.nc", "summary.json", "summary.csv"]
        if not args.no_plots:
            plot_sweep(res.dataset, tmp / "bias_coverage.png")
            files.append("bias_coverage.png")
    if args.json:
        print(json.dumps({**summary, "out": str(out), "files": files}))
    else:  # --quiet hides progress only
        print(res.text())
        print(f"files: {', '.join(files)} in {out}")
    return 0
