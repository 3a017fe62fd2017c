"""Worked example: one continuous knife mill fitted across the twelve SPRITE runs.

    python examples/knife_mill/run_example.py [DATA_DIR] [--config knife_mill.toml] [--quick]

DATA_DIR defaults to ``../shared/data/sprite-knife-mill`` relative to the repository
root. The data are not part of this repository: they are the measurements published with
the open-source SPRITE suite (Idaho National Laboratory, MIT licence) and described in Lu,
Xia, Bhattacharjee, Klinger and Li (2024), Powder Technology 441, 119830; put their folder
there or give its path. The data are read in place (millflow.fitting.data.read_sprite_folder builds the
long tables in memory); nothing is written into the repository except the output
folder named in the config.

It reports, in the README's metric (RMSE of cumulative passing at every row of each
product file, model curve linear in size):
- the in-sample RMSE of the shared model and its parameters with standard errors;
- the leave-one-run-out (LOO) prediction RMSE (each fold re-runs the global search);
- the trivial baseline (mean measured product of the other runs with the same screen);
- how SPRITE's per-run parameters (peer_fitted_params_JRS.csv) depend on the process
  parameters, next to the shared model's power laws.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np
import pandas as pd

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
DEFAULT_DATA = os.path.normpath(os.path.join(REPO, "..", "shared", "data", "sprite-knife-mill"))


def baseline_rmse(data) -> dict:
    """Trivial predictor: mean measured product of the other runs with the same screen."""
    proc, s = data.process, data.samples()
    out = {}
    for c in data.conditions:
        mine = s[s.condition == c]
        others = [o for o in data.conditions if o != c and proc.loc[o, "screen_mm"] == proc.loc[c, "screen_mm"]]
        curves = []
        for o in others:
            r = s[s.condition == o]
            curves.append(np.interp(mine.size_m, r.size_m[::-1], r.passing[::-1]))
        out[c] = float(np.sqrt(np.mean((np.mean(curves, axis=0) - mine.passing.to_numpy()) ** 2)))
    return out


def peer_comparison(data_dir: str) -> list[dict]:
    """R^2 of a main-effects regression of each SPRITE per-run parameter on (speed,
    moisture, screen), and in how many of the 4 (moisture, screen) groups it is
    monotone in speed. A physically meaningful parameter would be smooth and monotone."""
    peer = pd.read_csv(os.path.join(data_dir, "peer_fitted_params_JRS.csv"))
    X = np.column_stack([np.ones(len(peer)), peer.speed, peer.moisture, peer.screen])
    rows = []
    for col in [c for c in peer.columns if c not in ("speed", "moisture", "screen")]:
        y = peer[col].to_numpy(float)
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r2 = 1 - np.sum((X @ coef - y) ** 2) / np.sum((y - y.mean()) ** 2)
        mono = 0
        for _, g in peer.groupby(["moisture", "screen"]):
            d = np.diff(g.sort_values("speed")[col].to_numpy(float))
            mono += bool(np.all(d > 0) or np.all(d < 0))
        rows.append({"parameter": col, "cv": float(y.std() / abs(y.mean())), "r2_main_effects": float(r2),
                     "monotone_in_speed_groups": f"{mono}/4"})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data_dir", nargs="?", default=DEFAULT_DATA, help="SPRITE knife-mill data folder")
    ap.add_argument("--config", default=os.path.join(HERE, "knife_mill.toml"))
    ap.add_argument("--quick", action="store_true", help="fewer starts (for a smoke test)")
    ap.add_argument("--no-loo", action="store_true", help="skip the leave-one-run-out prediction")
    ap.add_argument("--nested", action="store_true",
                    help="also nested leave-one-run-out: the structure (this config's model and its [[candidates]]) "
                         "is chosen by BIC inside each fold")
    ap.add_argument("--out", default=None, help="output folder (default: output.dir of the config)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.data_dir):
        print(f"run_example.py: error: the SPRITE knife-mill data folder {args.data_dir} does not exist; it is "
              "expected at ../shared/data/sprite-knife-mill beside the repository, or give its path as "
              "the first argument", file=sys.stderr)
        return 2
    sys.path.insert(0, REPO)
    from millflow.errors import MillflowError
    try:
        return _run(args)
    except MillflowError as err:
        print(f"run_example.py: error: {err}", file=sys.stderr)
        return 2


def _run(args) -> int:
    from millflow.fitting.config import load_config
    from millflow.fitting.estimate import fit
    from millflow.fitting.models import ForwardModel
    from millflow.fitting.report import write_report
    from millflow.fitting.validate import leave_out, nested_leave_out

    cfg = load_config(args.config, data_dir=args.data_dir)
    opt = dict(cfg.optimizer)
    if args.quick:
        opt.update(starts=3, popsize=6, maxiter=60)
    say = lambda m: print(f"[knife] {m}", file=sys.stderr, flush=True)  # noqa: E731
    model = ForwardModel(cfg.spec, cfg.data, cfg.grid)
    res = fit(model, cfg.params, progress=say, **opt)
    insample = res.rmse_by_condition()
    loo = None if args.no_loo else leave_out(model, cfg.params, "each", progress=say, **opt)
    nested = None
    if args.nested:
        cands = {cfg.label: model,
                 **{label: ForwardModel(spec, cfg.data, model.grid) for label, spec, _ in cfg.candidates}}
        cparams = {cfg.label: cfg.params, **{label: par for label, _, par in cfg.candidates}}
        nested = nested_leave_out(cands, cparams, "each", criterion="bic", progress=say, **opt)
    base = baseline_rmse(cfg.data)
    write_report(res, args.out or cfg.out_dir, loo, plots=cfg.plots)
    out = {
        "n_params": res.n_params, "n_data": res.n_data,
        "in_sample_mean_rmse": float(np.mean(list(insample.values()))),
        "loo_mean_rmse": None if loo is None else loo["mean_rmse"],
        "baseline_mean_rmse": float(np.mean(list(base.values()))),
        "bar": 0.025, "params": {n: {"value": s["value"], "se": s["se"], "p_value": s["p_value"],
                                     "significant": s["significant"]} for n, s in res.stats["params"].items()},
        "nested_loo_mean_rmse": None if nested is None else nested["mean_rmse"],
        "nested_chosen": None if nested is None else nested["chosen"],
        "spread": res.spread, "grid_check": res.grid_check, "peer": peer_comparison(args.data_dir),
        "per_run": {c: {"in_sample": insample[c], "loo": None if loo is None else loo["rmse"][c],
                        "baseline": base[c]} for c in model.conditions},
    }
    if args.json:
        print(json.dumps(out, default=float, indent=1))
        return 0
    print(res.summary())
    print(f"\n{'run':<28}{'in-sample':>10}{'LOO':>9}{'baseline':>10}")
    for c, r in out["per_run"].items():
        loo_s = "" if r["loo"] is None else f"{r['loo']:.4f}"
        print(f"{c:<28}{r['in_sample']:>10.4f}{loo_s:>9}{r['baseline']:>10.4f}")
    loo_m = "-" if loo is None else f"{out['loo_mean_rmse']:.4f}"
    print(f"{'mean':<28}{out['in_sample_mean_rmse']:>10.4f}{loo_m:>9}{out['baseline_mean_rmse']:>10.4f}"
          f"   (bar: LOO <= 0.025 with ~7-8 shared parameters)")
    if nested is not None:
        print(f"nested leave-one-run-out (structure chosen by BIC in each fold): mean RMSE {nested['mean_rmse']:.4f}; "
              f"chosen: " + ", ".join(f"{k} x{v}" for k, v in nested["chosen"].items()))
    print("\nSPRITE per-run parameters (5 per run, 60 in all) against the process parameters:")
    for r in out["peer"]:
        print(f"  {r['parameter']:<8} CV {r['cv']:.2f}  R^2 on (speed, moisture, screen) {r['r2_main_effects']:.2f}  "
              f"monotone in speed in {r['monotone_in_speed_groups']} groups")
    return 0


if __name__ == "__main__":
    sys.exit(main())
