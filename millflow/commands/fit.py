"""``millflow fit CONFIG.toml [--json]``: estimate breakage parameters from PSD data.

A config with a ``[survey]`` table (or a survey file with a ``[fit]`` table) fits named
flowsheet parameters of a whole circuit to the reconciled survey instead (docs/survey.md).

Reads the TOML config (:mod:`millflow.fitting.config`), runs the global fit, ranks
candidate forms if any, predicts held-out conditions, writes the parameter table,
summary and plots into the output folder, and prints a summary (or, with --json, one
JSON object). Progress goes to stderr on a terminal (not with --quiet: millflow.progress).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("fit", help="fit breakage (and classification) parameters to PSD data, "
                                          "or a circuit to a survey",
                              description=__doc__.splitlines()[0])
    p.add_argument("config", help="TOML configuration (see docs/fitting.md)")
    add_output_flags(p, out="output folder (default: output.dir of the config, else <config stem>-fit)",
                     json="print one JSON object instead of the text summary",
                     plots="do not write plots")
    p.add_argument("--data-dir", default=None, help="SPRITE data folder (overrides data.sprite_folder)")
    p.set_defaults(func=run)


def ranking_table(table: list, fitted: str) -> str:
    """The AIC ranking of candidate models as aligned columns (as wide as the longest name),
    and, when the model fitted above (the config's [model], ``fitted``) is not the
    lowest-AIC one, a note saying so and why it is still the one reported."""
    names = [str(r["model"]) for r in table]
    w = max([len("model")] + [len(n) for n in names])
    lines = ["model ranking (AIC, lowest first):",
             f"  {'model':<{w}}  {'SSR':>10}  {'params':>6}  {'AIC':>10}  {'BIC':>10}  {'dAIC':>8}"]
    for r in table:
        lines.append(f"  {str(r['model']):<{w}}  {r['ssr']:>10.5g}  {r['n_params']:>6}  {r['aic']:>10.2f}  "
                     f"{r['bic']:>10.2f}  {r['delta_aic']:>8.2f}")
    best = min(table, key=lambda r: r["aic"]) if table else None
    if best is not None and str(best["model"]) != fitted:
        mine = next((r for r in table if str(r["model"]) == fitted), None)
        gap = f" (dAIC {mine['delta_aic']:.2f})" if mine else ""
        lines.append(f"  note: the estimates above are of the config's [model] {fitted!r}{gap}, as configured; "
                     f"the lowest-AIC candidate is {best['model']!r}: make it the [model] to report its estimates")
    return "\n".join(lines)


def data_files(config) -> list:
    """The data files a fit config reads (the existing files named in its [data] table,
    relative to the config), for the report's list of inputs and their SHA-256."""
    import tomllib

    try:
        data = tomllib.loads(Path(config).read_text(encoding="utf-8")).get("data") or {}
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return []
    out = []
    for v in data.values():
        if isinstance(v, str):
            p = Path(v) if Path(v).is_absolute() else Path(config).parent / v
            if p.is_file():
                out.append(p)
    return out


def run(args) -> int:
    from millflow.commands.output import check_target, relocate, staged_folder
    from millflow.fitting.config import load_config
    from millflow.fitting.estimate import compare_models, fit
    from millflow.fitting.report import write_report
    from millflow.fitting.validate import leave_out

    from millflow.survey.config import survey_fit_config

    sc = survey_fit_config(args.config)  # a [survey] table, or the survey file itself: the circuit fit
    if sc is not None:
        from millflow.commands.balance import balance_and_fit

        out_dir = Path(args.out or sc.out_dir or Path.cwd() / f"{Path(args.config).stem}-fit")
        check_target(out_dir, overwrite=args.overwrite, input_path=args.config)
        return balance_and_fit(args, sc.survey, Path(args.config), out_dir, sc.fit, command="fit",
                               plots=sc.plots, seed=sc.seed)
    from millflow.progress import note, progress

    cfg = load_config(args.config, data_dir=args.data_dir)
    out_dir = Path(args.out or cfg.out_dir)
    check_target(out_dir, overwrite=args.overwrite, input_path=args.config)  # before a long fit, not after
    model = cfg.model()
    names = ["fit"] + (["rank candidates"] if cfg.candidates else []) + (["predictive validation"]
                                                                         if cfg.hold_out else [])
    with progress("millflow fit", names, enabled=not args.quiet) as stage:
        stage("fit")
        note(str(model))
        result = fit(model, cfg.params, progress=note, **cfg.optimizer)
        out = result.to_dict()
        if len(set(model.data_kind)) > 1:  # several data kinds: how much each constrains each parameter
            from millflow.fitting.information import information_shares
            out["information_share"] = information_shares(result)
        if cfg.candidates:
            models = {cfg.label: model}
            params = {cfg.label: cfg.params}
            for label, spec, par in cfg.candidates:
                models[label] = cfg.model(spec, model.grid)
                params[label] = par
            stage("rank candidates")
            note(f"{len(models)} candidate models")
            cmp = compare_models(models, params, progress=note, **cfg.optimizer)
            out["discrimination"] = {"table": cmp["table"], "f_tests": cmp["f_tests"]}
        prediction = None
        if cfg.hold_out:
            stage("predictive validation")
            prediction = leave_out(model, cfg.params, cfg.hold_out, progress=note, **cfg.optimizer)
            out["prediction"] = {c: {"rmse": v} for c, v in prediction["rmse"].items()}
            out["prediction_mean_rmse"] = prediction["mean_rmse"]
    # print first: a failed write never loses a finished fit
    if args.json:
        print(json.dumps(out, default=float), flush=True)
    else:
        print(result.summary())
        if "discrimination" in out:
            print(ranking_table(out["discrimination"]["table"], cfg.label))
            for t in out["discrimination"]["f_tests"]:
                print(f"  F test {t['small']} -> {t['big']}: F {t['F']:.3g}, p {t['p_value']:.3g}")
        if prediction:
            print(f"prediction mean RMSE {prediction['mean_rmse']:.4f} "
                  f"over {len(prediction['rmse'])} held-out conditions")
        sys.stdout.flush()
    with staged_folder(out_dir, overwrite=args.overwrite, input_path=args.config, command="fit") as tmp:
        written = write_report(result, tmp, prediction, plots=cfg.plots and not args.no_plots)
        from millflow.report.html import finite
        from millflow.report.studies import fit_curves, fit_report, write_page

        js = finite(json.loads(json.dumps(out, default=float)))
        (Path(tmp) / "fit.json").write_text(json.dumps(js, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        written.append(str(Path(tmp) / "fit.json"))
        written.append(str(write_page(Path(tmp) / "report.html",
                                      fit_report(js, input_path=args.config, data_files=data_files(args.config),
                                                 curves=fit_curves(result)))))
        files = relocate(written, tmp, out_dir)
    print("wrote " + ", ".join(files), file=sys.stderr if args.json else sys.stdout)
    return 0
