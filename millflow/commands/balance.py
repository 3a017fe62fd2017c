"""`millflow balance SURVEY.toml [--out DIR] [--json] [--no-plots] [--overwrite] [--quiet]`: mass-balance a survey.

Reads the survey (measurements per stream on a flowsheet's topology, docs/survey.md),
reconciles it by weighted least squares with the node balances held exactly, and
prints the adjusted stream flows with their SDs, the chi-square test of the weighted
sum of squares, the gross-error candidates, the circulating loads and what the survey
leaves undetermined. Writes results.nc, measurements.csv, streams.csv, passing.csv,
summary.json, report.html, results.xlsx (when openpyxl is installed) and one plot per
stream to the output folder (default ``<file stem>-balance/``), whole or not at all.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("balance", help="mass-balance (reconcile) a plant survey",
                              description=__doc__.split("\n\n")[1] if __doc__ else None)
    p.add_argument("file", help="survey file (TOML), e.g. examples/survey/survey.toml")
    add_output_flags(p, out="output folder (default: <file stem>-balance)",
                     json="print one JSON object (the summary) instead of the table",
                     plots="do not write the PNG plots")
    p.add_argument("--no-fit", action="store_true", help="skip the circuit fit of the survey's [fit] table")
    p.set_defaults(func=run)


def _f(v, fmt="{:.1f}") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def format_summary(s: dict) -> str:
    lines = [s["title"] or s["source_file"], ""]
    wet = any("water_tph" in v for v in s["streams"].values())
    head = ["stream", "measured t/h", "adjusted t/h", "SD t/h"] + (["% solids", "water t/h"] if wet else [])
    rows = []
    for n, v in s["streams"].items():
        adj = _f(v["solids_tph"]) if v["solids_observable"] else "unobservable"
        rows.append([n, _f(v["solids_measured_tph"]), adj, _f(v["solids_sd_tph"], "{:.2f}")]
                    + ([_f(v.get("solids_content_pct")), _f(v.get("water_tph"))] if wet else []))
    width = [max(len(str(r[k])) for r in [head] + rows) for k in range(len(head))]
    for r in [head] + rows:
        lines.append("  ".join(str(c).ljust(w) if k == 0 else str(c).rjust(w)
                               for k, (c, w) in enumerate(zip(r, width))))
        if r is head:
            lines.append("  ".join("-" * w for w in width))
    lines.append("")
    chi = s["chi_square"]
    if chi["dof"] > 0:
        lines.append(f"weighted SSR {chi['ssr']:.4g} on {chi['dof']} degrees of freedom ({chi['n_measured']} measured, "
                     f"rank {chi['rank']}): chi-square 95 % point {chi['critical_95']:.4g}, p = {chi['p_value']:.3g}: "
                     + ("consistent with the stated errors" if chi["passed"]
                        else "LARGER than the stated errors allow"))
    else:
        lines.append("no redundancy (0 degrees of freedom): nothing to test; every value is as measured")
    cand = s["gross_error_candidates"]
    lines.append(f"gross-error candidates (|normalised adjustment| > {s['gross_error_threshold']:.2f}): "
                 + (", ".join(f"{c['measurement']} ({c['normalised_adjustment']:+.1f}"
                              + (f"; the test cannot tell it from {', '.join(c['not_separable_from'][:2])}"
                                 if c.get("not_separable_from") else "") + ")" for c in cand) or "none"))
    if not cand and s["largest_normalised_adjustments"]:
        c = s["largest_normalised_adjustments"][0]
        lines.append(f"largest normalised adjustment: {c['measurement']} ({c['normalised_adjustment']:+.2f})")
    d = s.get("gross_error_detectability")
    if d and d["n_redundant"]:
        lines.append(f"a gross error of {d['k_sd']:g} SD would be detected with probability >= {d['power_level']:g} "
                     f"in {d['n_detected_at_power']} of {d['n_redundant']} redundant measurements "
                     f"({d['n_not_redundant']} not redundant: never); least detectable: " + ", ".join(
                         f"{c['measurement']} (redundancy {c['redundancy']:.2f}, p = {c['power']:.2f}, "
                         f"{c['detectable_sd']:.0f} SD for {d['power_level']:g})" for c in d["least_detectable"][:3]))
    for n, c in s["circulating_load"].items():
        lines.append(f"circulating load {n}: " + (f"{c['value_pct']:.1f} +- {c['sd_pct']:.1f} %"
                                                  if c["observable"] else "unobservable"))
    bad = s["observability"]["unobservable"]
    lines.append("unobservable (not determined by the survey; no value is given): " + (", ".join(bad) or "none"))
    for v in s.get("physical_range_violations") or []:
        lines.append(f"NOT PHYSICAL: {v}, beyond 3 SD, from every start: the gross-error candidates above are the "
                     "likely cause; correct them (or give them large SDs) and balance again")
    neg = s.get("outside_physical_range") or []
    if neg:
        lines.append(f"{len(neg)} reconciled values below 0 within their errors (not clipped; summary.json "
                     "outside_physical_range): " + ", ".join(
                         f"{v.get('stream', v.get('unit'))} {v['quantity']} "
                         + (f"{v['value_pct']:.3g} %" if "value_pct" in v else f"{v['value_tph']:.3g} t/h")
                         for v in neg[:3]) + (" ..." if len(neg) > 3 else ""))
    lines.append(f"balances close to {s['balance_error']:.1e} (relative); {s['iterations']} evaluations, "
                 f"{1e3 * s['runtime_s']:.0f} ms")
    return "\n".join(lines)


def format_fit(f: dict) -> str:
    lines = ["", f"circuit fit: SSR {f['ssr']:.4g} on {f['dof']} degrees of freedom (weights: {f['weights']}), "
                 f"{f['starts']} starts, spread {f['spread']:.2g}"]
    w = max(len(n) for n in f["parameters"])
    for n, p in f["parameters"].items():
        lo, hi = p["ci95"]
        lines.append(f"  {n:<{w}}  {p['value']:.5g} +- {p['se']:.3g}  95 % [{lo:.4g}, {hi:.4g}]  "
                     + ("; ".join(p["flags"]) or "ok"))
    if f.get("condition_number") is None or f.get("singular"):
        lines.append("the parameters are not separately determined by the survey (singular: condition number "
                     "infinite); fix one of each correlated set")
    else:
        lines.append(f"condition number {f['condition_number']:.3g}" + "".join(
            f"; {a} and {b} correlate {c:+.3f}" for a, b, c in f.get("correlated_pairs", [])))
    loo = f.get("leave_one_stream_out") or {}
    if loo:
        lines.append("leave-one-stream-out prediction (RMS whitened error; about 1 = within its errors): " + ", ".join(
            f"{n} {v['rms_normalised_error']:.2f}" if "rms_normalised_error" in v else f"{n} skipped"
            for n, v in loo.items()))
    lines.append("the fitted circuit is fitted_circuit.toml in the output folder: millflow run reproduces it")
    return "\n".join(lines)


def write_reports(folder: Path, s: dict, input_path) -> dict:
    """``report.html`` (always) and ``results.xlsx`` (when openpyxl is installed) of the
    balance, from its summary (``s``: the summary.json dict); returns name -> path."""
    from millflow.report.balance import write_balance_report
    from millflow.report.excel import excel_available, write_balance_workbook

    files = {"report_html": write_balance_report(folder / "report.html", s, input_path=input_path)}
    if excel_available():
        files["results_xlsx"] = write_balance_workbook(folder / "results.xlsx", s)
    else:
        from millflow.commands.output import excel_missing_note

        excel_missing_note()
    return files


def run(args) -> int:
    from millflow.commands.output import check_target
    from millflow.survey import read_survey

    path = Path(args.file)
    out = Path(args.out) if args.out else Path.cwd() / f"{path.stem}-balance"
    check_target(out, overwrite=args.overwrite, input_path=path)
    survey = read_survey(path)
    return balance_and_fit(args, survey, path, out, survey.fit if not args.no_fit else None, command="balance")


def balance_and_fit(args, survey, path: Path, out: Path, fit_spec: dict | None, *, command: str,
                    plots: bool = True, seed: int = 0) -> int:
    """Reconcile ``survey``, fit the circuit parameters of ``fit_spec`` (if any), write and print the
    results: the one route of ``millflow balance`` and of ``millflow fit`` on a survey config."""
    from millflow.commands.output import relocate, staged_folder
    from millflow.survey import reconcile
    from millflow.survey.results import save, summary

    from millflow.progress import progress

    names = ["reconcile"] + (["fit circuit"] if fit_spec else []) + ["write"]
    with progress(f"millflow {command}", names, enabled=not args.quiet) as stage:
        stage("reconcile")
        bal = reconcile(survey)
        s = summary(bal)
        cf = None
        if fit_spec:
            from millflow.survey.fit import fit_circuit

            f = fit_spec
            stage("fit circuit")
            cf = fit_circuit(bal, f["names"], f["bounds"], starts=f["starts"], global_search=f["global_search"],
                             leave_one_out=f["leave_one_out"], quiet=True, seed=seed)
            s["fit"] = cf.to_dict()
        stage("write")
        with staged_folder(out, overwrite=args.overwrite, input_path=path, command=command) as tmp:
            files = relocate(save(bal, tmp, plots=plots and not args.no_plots).values(), tmp, out)
            if cf is not None:
                from millflow.survey.fit import to_toml

                (tmp / "fitted_circuit.toml").write_text(
                    f"# {survey.flowsheet.title or 'circuit'}: parameters fitted to the survey "
                    f"{Path(survey.source).name} by millflow {command}\n" + to_toml(cf.document()), encoding="utf-8")
                (tmp / "fit.json").write_text(json.dumps(s["fit"], indent=2, default=float), encoding="utf-8")
                files += relocate([tmp / "fitted_circuit.toml", tmp / "fit.json"], tmp, out)
            files += relocate(write_reports(tmp, s, path).values(), tmp, out)
    s["output_dir"] = str(out)
    s["files_written"] = [Path(f).name for f in files]
    if args.json:
        print(json.dumps(s))
    else:
        print(format_summary(s))
        if cf is not None:
            print(format_fit(s["fit"]))
        print(f"results written to {out}/ ({', '.join(s['files_written'])})")
    return 0
