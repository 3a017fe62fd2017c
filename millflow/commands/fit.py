"""``millflow fit CONFIG.toml [--json]``: estimate breakage parameters from PSD data.

Reads the TOML config (:mod:`millflow.fitting.config`), runs the global fit, ranks
candidate forms if any, predicts held-out conditions, writes the parameter table,
summary and plots into the output folder, and prints a summary (or, with --json, one
JSON object). Progress goes to stderr.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("fit", help="fit breakage (and classification) parameters to PSD data",
                              description=__doc__.splitlines()[0])
    p.add_argument("config", help="TOML configuration (see docs/fitting.md)")
    add_output_flags(p, out="output folder (overrides output.dir of the config)",
                     json="print one JSON object instead of the text summary",
                     plots="do not write plots", quiet="no progress messages")
    p.add_argument("--data-dir", default=None, help="SPRITE data folder (overrides data.sprite_folder)")
    p.set_defaults(func=run)


def run(args) -> int:
    from millflow.commands.output import check_target, relocate, staged_folder
    from millflow.fitting.config import load_config
    from millflow.fitting.estimate import compare_models, fit
    from millflow.fitting.report import write_report
    from millflow.fitting.validate import leave_out

    say = (lambda msg: None) if args.quiet else (lambda msg: print(f"[fit] {msg}", file=sys.stderr, flush=True))
    cfg = load_config(args.config, data_dir=args.data_dir)
    out_dir = Path(args.out or cfg.out_dir)
    check_target(out_dir, overwrite=args.overwrite, input_path=args.config)  # before a long fit, not after
    model = cfg.model()
    say(f"{model}")
    result = fit(model, cfg.params, progress=say, **cfg.optimizer)
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
        say(f"ranking {len(models)} candidate models")
        cmp = compare_models(models, params, **cfg.optimizer)
        out["discrimination"] = {"table": cmp["table"], "f_tests": cmp["f_tests"]}
    prediction = None
    if cfg.hold_out:
        say("predictive validation")
        prediction = leave_out(model, cfg.params, cfg.hold_out, progress=say, **cfg.optimizer)
        out["prediction"] = {c: {"rmse": v} for c, v in prediction["rmse"].items()}
        out["prediction_mean_rmse"] = prediction["mean_rmse"]
    # print first: a failed write never loses a finished fit
    if args.json:
        print(json.dumps(out, default=float), flush=True)
    else:
        print(result.summary())
        if "discrimination" in out:
            print("model ranking (AIC):")
            for row in out["discrimination"]["table"]:
                print(f"  {row['model']:<50} SSR {row['ssr']:.5g}  p {row['n_params']}  AIC {row['aic']:.2f}  "
                      f"BIC {row['bic']:.2f}  dAIC {row['delta_aic']:.2f}")
            for t in out["discrimination"]["f_tests"]:
                print(f"  F test {t['small']} -> {t['big']}: F {t['F']:.3g}, p {t['p_value']:.3g}")
        if prediction:
            print(f"prediction mean RMSE {prediction['mean_rmse']:.4f} "
                  f"over {len(prediction['rmse'])} held-out conditions")
        sys.stdout.flush()
    with staged_folder(out_dir, overwrite=args.overwrite, input_path=args.config, command="fit") as tmp:
        files = relocate(write_report(result, tmp, prediction, plots=cfg.plots and not args.no_plots), tmp, out_dir)
    if not args.quiet:
        print("wrote " + ", ".join(files), file=sys.stderr if args.json else sys.stdout)
    return 0
