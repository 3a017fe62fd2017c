"""``millflow scaleup FIT.json --to PLANT.toml [--target-p80-um X] [--json] [--out DIR]``:
carry a lab breakage fit to a plant mill and circuit, with 95 % bands from the fit's
covariance (eq. 9).

Prints the predicted plant product P80 with its band (delta method and Monte Carlo),
the mill power and specific energy, and, with a target P80, the fresh-feed throughput
that meets it (a bracketed root through the whole circuit, with its residual and band).
Beside the parameter band, the band's model-form contributions (power model, scaling rule,
size grid; :mod:`millflow.scaleup.modelform`), each its own line, and the total band with
how it is formed. Writes scaleup.nc, scaleup_psd.csv, scaleup.json, scaleup_contributions.csv,
scaleup.png and scaleup_contributions.png into the output folder (default
``<plant stem>-scaleup``). On a terminal, progress goes to stderr (not with --quiet). Bad
input: exit 2; a failed solve: exit 1.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

from millflow.commands.output import add_output_flags, deprecated_alias


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("scaleup", help="predict a plant mill/circuit from a lab fit, with uncertainty",
                              description=__doc__.split("\n\n")[0],
                              epilog="example: millflow scaleup lab_fit.json --to examples/scaleup/plant.toml "
                                     "--target-p80-um 150")
    p.add_argument("fit", help="result of 'millflow fit --json' (JSON file)")
    p.add_argument("--to", required=True, dest="plant", help="plant file (TOML, see docs/scaleup.md)")
    p.add_argument("--target-p80-um", type=float, default=None, help="target product P80 [um]: solve for throughput")
    add_output_flags(p, out="output folder (default: <plant stem>-scaleup)",
                     json="print one JSON object instead of the text summary",
                     plots="do not write scaleup.png")
    p.add_argument("--draws", type=int, default=400,
                   help="Monte Carlo draws (default 400: the percentiles of a 95 %% band to about 1 %% of the "
                        "band; the model-form contributions are usually larger)")
    p.add_argument("--band-method", choices=["both", "delta", "mc"], default="both", dest="band_method",
                   help="method(s) of the 95 %% bands: delta method, Monte Carlo or both (default both)")
    deprecated_alias(p, "--method", "--band-method", "band_method")
    p.set_defaults(func=run)


def _band(b, unit, fmt="{:.4g}"):
    return ", ".join(f"{m} [{fmt.format(v['lo'])}, {fmt.format(v['hi'])}] {unit}" for m, v in b.items())


def format_summary(s: dict) -> str:
    lines = [f"{s['title']}: scale-up of {s['fit']} ({s['scaling']}, power model {s['power_model']})",
             f"plant mill: net power {s['power_net_kW']:.4g} kW"
             + (f", gross {s['power_gross_kW']:.4g} kW" if s.get("power_gross_kW") else "")
             + f", hold-up {s['holdup_kg']:.4g} kg, A factor {s['A_factor']:.4g}",
             f"at {s['feed_tph']:.4g} t/h: P80 {s['p80_um']:.4g} um (95 %: {_band(s['bands']['p80_um'], 'um')}), "
             f"specific energy {s['specific_energy_kWh_per_t']:.4g} kWh/t, tau {s['tau_s']:.4g} s, "
             f"circulating load {100 * s['circulating_load']:.1f} %"]
    if "throughput_tph" in s:
        lines.append(f"target P80 {s['target_p80_um']:.4g} um: throughput {s['throughput_tph']:.4g} t/h "
                     f"(95 %: {_band(s['bands']['throughput_tph'], 't/h')}; "
                     f"residual {s['throughput_residual_rel']:.1e}), "
                     f"specific energy {s['specific_energy_at_target_kWh_per_t']:.4g} kWh/t "
                     f"(95 %: {_band(s['bands']['specific_energy_kWh_per_t'], 'kWh/t', '{:.3g}')})")
    for q, d in s.get("disagreement", {}).items():
        if isinstance(d, dict) and d["nonlinear"]:
            lines.append(f"note: {q}: delta method and Monte Carlo disagree (band widths differ by "
                         f"{100 * d['width_rel_diff']:.0f} %, centre shift {100 * d['centre_shift']:.0f} % of the "
                         "half-width): the prediction is non-linear over the parameter spread; prefer Monte Carlo")
    pm = s.get("power_models") or {}
    if pm.get("mixed"):
        lines.append(f"note: mixed power models: lab {pm['lab']}, plant {pm['plant']} (a stated choice; the A factor "
                     "carries their ratio; the power-model contribution below shows what it is worth)")
    if "mc" in s:
        lines.append(f"Monte Carlo: {s['mc']['n']} draws ({s['mc']['rejected']} rejected as unphysical, "
                     f"{s['mc']['failed']} failed)")
    mf = s.get("model_form")
    if mf:
        unit = "t/h" if mf["quantity"] == "throughput_tph" else "um"
        lines.append(f"band contributions to {mf['quantity']} = {mf['value']:.4g} {unit} (95 % half-widths):")
        for name, r in mf["contributions"].items():
            alts = ", ".join(f"{k} {v:.4g}" for k, v in r["alternatives"].items())
            lines.append(f"  {name:<13} +-{r['half_width']:.3g} {unit} ({100 * r['rel']:.1f} %, factor "
                         f"{math.exp(r['log_factor']):.3g}): {r['how']} [{alts}]")
        t = mf["total"]
        lines.append(f"  total         [{t['lo']:.4g}, {t['hi']:.4g}] {unit} (factor {t['factor']:.3g}): {t['how']}")
    lines.append(f"mass balance {s['mass_balance']:.1e}; run time {s['runtime_s']:.2f} s")
    return "\n".join(lines)


def run(args) -> int:
    from millflow.commands.output import check_target
    from millflow.scaleup.api import predict_plant
    from millflow.scaleup.fitted import load_fit
    from millflow.scaleup.plantfile import load_plant

    out = Path(args.out) if args.out else Path.cwd() / f"{Path(args.plant).stem}-scaleup"
    check_target(out, overwrite=args.overwrite, input_path=args.plant)  # before the work, not after
    fit = load_fit(args.fit)
    su, notes = load_plant(args.plant, fit)
    target = None if args.target_p80_um is None else args.target_p80_um * 1e-6
    if args.draws < 10:
        from millflow.errors import InputError
        raise InputError(f"--draws {args.draws}: expected >= 10")
    methods = {"both": ("delta", "mc"), "delta": ("delta",), "mc": ("mc",)}[args.band_method]
    from millflow.progress import progress

    t0 = time.perf_counter()
    bands = (f"parameter bands ({', '.join(methods)}"
             + (f", Monte Carlo {args.draws} draws" if "mc" in methods else "") + ")")
    contrib = "model-form contributions (power models, scaling rule, halved grid)"
    with progress("millflow scaleup", [bands, contrib, "write"], enabled=not args.quiet) as stage:
        stage(bands)
        res = predict_plant(su, target, methods=methods, n_draws=args.draws)  # SolverError: exit 1 (cli.main)
        stage(contrib)
        model_form = _model_form(args, fit, su, target, res.summary)
        stage("write")
        s = _finish(args, res, model_form, notes, su, t0, out)
    if args.json:
        print(json.dumps(s, default=float))
    else:
        print(format_summary(s))
        print(f"wrote {out}/ ({', '.join(s['files_written'])})")
    return 0


def _finish(args, res, model_form, notes, su, t0, out):
    """The summary of the files (scaleup.json) and the files written."""
    from millflow.commands.output import staged_folder

    s = file_names(res.summary)
    s["model_form"] = model_form
    s["power_models"] = notes["power_models"]
    s["runtime_s"] = time.perf_counter() - t0
    sc = res.scale
    s.update(title=notes["title"], fit=Path(args.fit).name, scaling=su.scaling, power_model=sc["power_model"],
             power_gross_kW=sc["plant_gross_kW"], holdup_kg=sc["plant_holdup_kg"], A_factor=sc["A"],
             mu_factor=sc["mu"], transport=notes["transport"], transport_params=notes["transport_params"],
             transport_source=notes["transport_source"])
    s["plant_file"] = str(args.plant)
    s["circuit"] = circuit_summary(su, s)
    with staged_folder(out, overwrite=args.overwrite, input_path=args.plant, command="scaleup") as tmp:
        files = _write(res, s, tmp, plots=not args.no_plots, fit_path=args.fit)
        files += _write_contributions(s, tmp, plots=not args.no_plots)
    s["files_written"] = [f.name for f in files]
    return s


def _model_form(args, fit, su, target, summary):
    """Model-form contributions to the band (:func:`millflow.scaleup.modelform.contributions`)
    and the reported quantity's error split into solver and grid parts (``summary["error_estimate"]``)."""
    from millflow.errors import InputError
    from millflow.scaleup.modelform import contributions, error_estimate
    from millflow.scaleup.plantfile import load_plant

    key = "throughput_tph" if target is not None else "p80_um"
    bands = summary["bands"].get(key, {})
    band = bands.get("mc") or bands.get("delta")
    refined, _ = load_plant(args.plant, fit, refine=1)
    finer = None
    try:
        coarse, _ = load_plant(args.plant, fit, refine=-1)
    except InputError:  # the classes do not pair up: the third grid is the one refined twice
        coarse = None
        finer, _ = load_plant(args.plant, fit, refine=2)
    out = contributions(su, target, band, refined, coarse, finer)
    summary["error_estimate"] = error_estimate(su, target, out["contributions"].get("size_grid"))
    return out


#: Names of the scale-up's results in its files (scaleup.json, the CSVs, report.html) where
#: the Python summary (:func:`millflow.scaleup.api.predict_plant`) names them otherwise:
#: one name per quantity in every command's files (docs/cli.md).
FILE_NAMES = {"specific_energy_kWh_t": "specific_energy_kWh_per_t",
              "specific_energy_at_target_kWh_t": "specific_energy_at_target_kWh_per_t"}


def file_names(summary: dict) -> dict:
    """A copy of the scale-up summary with the names of :data:`FILE_NAMES` (also in its
    bands and in the delta-vs-Monte-Carlo comparison)."""
    def rename(d):
        return {FILE_NAMES.get(k, k): v for k, v in d.items()}

    s = rename(summary)
    for key in ("bands", "disagreement"):
        if isinstance(s.get(key), dict):
            s[key] = rename(s[key])
    return s


def circuit_summary(su, s: dict) -> dict:
    """The plant circuit at the estimate as a flowsheet summary (streams with solids t/h,
    P80, P50 and cumulative passing; units with power, kWh/t, tau and hold-up) for report.html:
    the plant flowsheet of the study (:class:`millflow.scaleup.study.PlantStudy`) solved at the
    estimate's fresh feed, its flows scaled to that feed."""
    import numpy as np

    from millflow.flowsheet.solve import solve_at
    from millflow.psd import percentile_size
    from millflow.scaleup.study import MILL

    theta = su.fit.theta
    state = su.operate(theta, feed_tph=s["feed_tph"])
    fs = su.flowsheet(theta)
    flows, _ = solve_at(fs, {MILL: {"throughput": state["mill_flow_kg_s"]}})
    names = fs.stream_names
    fresh = float(flows[names.index("fresh")].sum())
    scale = s["feed_tph"] / fresh  # t/h per flow unit of the solve
    x = np.asarray(su.grid.x if hasattr(su.grid, "x") else su.x, float)
    closed = su.study.closed
    # report names of the plant flowsheet's streams: (name, from, to)
    layout = ({"fresh": ("fresh_feed", "fresh_feed.out", "mixer"), "mill_feed": ("mill_feed", "mixer.out", "mill"),
               "mill_discharge": ("mill_discharge", "mill.out", "classifier"),
               "recycle": ("classifier_coarse", "classifier.coarse", "mixer"),
               "product": ("product", "classifier.fine", "product")} if closed else
              {"fresh": ("fresh_feed", "fresh_feed.out", "mill"), "product": ("product", "mill.out", "product")})
    streams = {}
    for stream, (name, src, tgt) in layout.items():
        f = np.asarray(flows[names.index(stream)], float)
        tot = float(f.sum())
        frac = f / tot if tot > 0 else f
        streams[name] = {"from": src, "to": tgt, "solids_tph": tot * scale,
                         "p80_um": percentile_size(x, frac, 80.0, validate=False) * 1e6,
                         "p50_um": percentile_size(x, frac, 50.0, validate=False) * 1e6,
                         "size_um": list(x * 1e6), "cum_passing": list(np.cumsum(frac[::-1])[::-1])}
    mill_tph = streams["mill_feed" if closed else "fresh_feed"]["solids_tph"]
    units = {"fresh_feed": {"type": "feed"}}
    if closed:
        units["mixer"] = {"type": "mixer"}
    c = su.circuit
    units["mill"] = {"type": "mill", "solids_in_tph": mill_tph, "power_kW": s.get("power_net_kW"),
                     "specific_energy_kWh_per_t": s.get("power_net_kW") / mill_tph, "tau_s": state["tau_s"],
                     "holdup_kg": s.get("holdup_kg"), "method": f"{c.transport} {c.transport_params}"}
    if closed:
        params = {k: v for k, v in c.classifier.items() if k != "curve"}
        units["classifier"] = {"type": "classifier", "solids_in_tph": streams["mill_discharge"]["solids_tph"],
                               "d50c_m": params.get("d50c"), "method": f"{c.classifier['curve']} curve"}
    units["product"] = {"type": "product"}
    return {"title": s.get("title"), "streams": streams, "units": units,
            "mass_balance_error": abs(streams["product"]["solids_tph"] - s["feed_tph"]) / s["feed_tph"]}


def _write_contributions(s, out: Path, plots: bool):
    """scaleup_contributions.csv (6 significant digits, values in the quantity's unit:
    ``_um`` for P80, ``_tph`` for a throughput) and scaleup_contributions.png."""
    import pandas as pd

    mf = s["model_form"]
    u = "tph" if mf["quantity"] == "throughput_tph" else "um"
    rows = [{"source": k, f"half_width_{u}": r["half_width"], "half_width_pct": 100 * r["rel"],
             "log_factor": r["log_factor"], f"low_{u}": None, f"high_{u}": None,
             **{f"at_{a}_{u}": v for a, v in r["alternatives"].items()}, "how": r["how"]}
            for k, r in mf["contributions"].items()]
    rows.append({"source": "total", "log_factor": mf["total"]["log_factor"], f"low_{u}": mf["total"]["lo"],
                 f"high_{u}": mf["total"]["hi"], "how": mf["total"]["how"]})
    files = [out / "scaleup_contributions.csv"]
    pd.DataFrame(rows).to_csv(files[0], index=False, float_format="%.6g")
    if plots:
        from millflow.plotting import figure

        fig, ax = figure(figsize=(6, 3))
        names = [r["source"] for r in rows]
        vals = [r["log_factor"] for r in rows]
        ax.barh(names[::-1], vals[::-1], color=["0.4"] + ["C0"] * (len(vals) - 1))
        ax.set_xlabel(f"log factor of the 95 % half-width ({mf['quantity']} = {mf['value']:.4g}; 0.69 = x2)")
        ax.set_title("scale-up band: contribution of each source (total added linearly)", fontsize=9)
        fig.tight_layout()
        p = out / "scaleup_contributions.png"
        fig.savefig(p, dpi=110)
        files.append(p)
    return files


def _write(res, s, out: Path, plots: bool, fit_path=None):
    import pandas as pd

    files = [out / "scaleup.nc", out / "scaleup_psd.csv", out / "scaleup.json"]
    ds = res.dataset
    ds.to_netcdf(files[0])
    # passing in % (every CSV: docs/cli.md) at 6 significant digits; a band edge beyond
    # [0, 100] % is a linearisation artefact of the delta method: shown at the bound and
    # counted in scaleup.json (band_edges_at_physical_bounds)
    import numpy as np

    cols = {"size_um": ds.x.values * 1e6, "passing_pct": 100 * ds.passing.values,
            "feed_passing_pct": 100 * ds.feed_passing.values}
    clipped = 0
    for m in ds.estimator.values:
        for side in ("lo", "hi"):
            v = 100 * ds[f"passing_{side}"].sel(estimator=m).values
            clipped += int(np.count_nonzero((v < 0) | (v > 100)))
            cols[f"passing_{side}_{m}_pct"] = np.clip(v, 0.0, 100.0)
    cols["passing_pct"] = np.clip(cols["passing_pct"], 0.0, 100.0)  # rounding above 100 % only
    s["band_edges_at_physical_bounds"] = clipped
    pd.DataFrame(cols).to_csv(files[1], index=False, float_format="%.6g")
    from millflow.report.html import finite

    files[2].write_text(json.dumps(finite(s), indent=1, default=float, allow_nan=False) + "\n", encoding="utf-8")
    from millflow.report.studies import scaleup_report, write_page

    files.append(write_page(out / "report.html", scaleup_report(json.loads(files[2].read_text(encoding="utf-8")), ds,
                                                                input_path=s.get("plant_file"), fit_path=fit_path)))
    if plots:
        from millflow.plotting import figure

        fig, ax = figure(figsize=(6, 4))  # a Figure of its own: no pyplot state, no backend switched
        x = ds.x.values * 1e6
        ax.semilogx(x, ds.feed_passing, "k:", lw=1, label="fresh feed")
        ax.semilogx(x, ds.passing, "C0-", lw=1.5, label=f"plant product, P80 {s['p80_um']:.0f} um")
        for k, m in enumerate(ds.estimator.values):
            ax.fill_between(x, ds.passing_lo.sel(estimator=m), ds.passing_hi.sel(estimator=m), alpha=0.25,
                            color=f"C{k + 1}", label=f"95 % band ({m})")
        ax.axhline(0.8, color="0.6", lw=0.6)
        ax.set_xlabel("size [um]")
        ax.set_ylabel("cumulative passing [-]")
        ax.set_title(s["title"], fontsize=9)
        ax.legend(fontsize=7)
        fig.tight_layout()
        p = out / "scaleup.png"
        fig.savefig(p, dpi=110)
        files.append(p)
    return files
