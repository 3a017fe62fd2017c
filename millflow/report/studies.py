"""The ``report.html`` of the studies: fit, scale-up, compare and sweep.

``report.html`` of the studies: a breakage fit (``millflow fit``), a scale-up
(``millflow scaleup``), two flowsheets side by side (``millflow compare``) and a sweep
(``millflow sweep``).

Each page is built with :mod:`millflow.report.html` as the run report is: one
self-contained file, the input files with their SHA-256 and the version, tables whose
numbers carry ``data-key`` paths into the JSON file of the same folder that the page
embeds and names (``fit.json``, ``scaleup.json``, ``compare.json``, the sweep's
``summary.json``), and plots drawn as inline SVG.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

from millflow.report.html import details, esc, fmt, line_plot, page, table
from millflow.report.html import finite as _finite

__all__ = ["fit_report", "scaleup_report", "compare_report", "sweep_report", "write_page", "input_rows",
           "fit_curves", "SWEEP_ROWS"]


def input_rows(inputs: list, command: str, extra: list = ()) -> tuple[list, list]:
    """Rows of the page's header table and the sections showing the input files.

    Rows of the page's header table: each input file (``inputs``: (what, path) pairs)
    with its SHA-256, the version and the command; and the (heading, html) sections
    showing the input files' text (folded).
    """
    from millflow import __version__

    rows, sections = [], []
    for what, path in inputs:
        if path is None:
            continue
        try:
            raw = Path(path).read_bytes()
        except OSError:
            rows += [[what, str(path)], [f"{what} SHA-256", "- (not readable)"]]
            continue
        rows += [[what, Path(path).name], [f"{what} SHA-256", hashlib.sha256(raw).hexdigest()]]
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            continue
        sections.append((f"{what[:1].upper()}{what[1:]}: {Path(path).name}",
                         details(f"show {Path(path).name} ({len(raw)} bytes)", f"<pre>{esc(text)}</pre>")))
    rows += [["millflow version", __version__], ["command", command]] + list(extra)
    return rows, sections


def write_page(path, html: str) -> Path:
    """Write a page; returns the path."""
    path = Path(path)
    path.write_text(html, encoding="utf-8")
    return path


# ---------------------------------------------------------------------------------- fit
def fit_curves(result) -> dict:
    """The fit's plots as numbers.

    Per measured group (condition, and time or location) the measured cumulative passing at
    the sieves and the model's on the grid [%, um], and the parity pairs (measured, model)
    [%].
    """
    import numpy as np

    m = result.model
    theta = result.theta
    M = m.predict_grid(theta[None])[0]
    P = np.cumsum(M[:, ::-1], axis=1)[:, ::-1]
    groups = []
    for g, (c, loc, t) in enumerate(m.groups):
        a, b = m.group_slices[g], m.group_slices[g + 1]
        s = np.asarray(m.sizes[g])
        pos = s > 0
        groups.append({"condition": str(m.conditions[c]),
                       "label": f"t = {t / 60:g} min" if m.spec.mode == "batch" else str(loc),
                       "size_um": list(s[pos] * 1e6), "measured_pct": list(100 * np.asarray(m.y_cum[a:b])[pos]),
                       "model_size_um": list(np.asarray(m.x) * 1e6), "model_pct": list(100 * P[g])})
    return {"groups": groups, "parity": (list(100 * np.asarray(m.y_cum)), list(100 * m.predict_cum(theta)))}


def _fit_plots(curves: dict) -> str:
    by_condition: dict = {}
    for g in curves["groups"]:
        by_condition.setdefault(g["condition"], []).append(g)
    out = []
    for cond, groups in by_condition.items():
        series = []
        for k, g in enumerate(groups):
            series.append((f"{g['label']} model", g["model_size_um"], g["model_pct"], {"color": k}))
            series.append((f"{g['label']} measured", g["size_um"], g["measured_pct"], {"style": "points", "color": k}))
        out.append(line_plot(series, xlabel="size [um]", ylabel="cumulative passing [%]", ylim=(0, 100),
                             title=f"{cond}: measured (points) and fitted (lines)"))
    meas, model = curves["parity"]
    out.append(line_plot([("measured vs model", meas, model, "points"), ("y = x", [0, 100], [0, 100], "dashed")],
                         xlabel="measured cumulative passing [%]", ylabel="model cumulative passing [%]",
                         xlog=False, ylim=(0, 100), width=560, height=420, title="parity"))
    return "".join(out)


def fit_report(out: dict, *, input_path=None, data_files=(), curves: dict | None = None) -> str:
    """The page of a breakage fit.

    ``out`` is fit.json (the dict ``millflow fit --json`` prints), ``data_files`` the data
    files the config reads, ``curves`` the fit's plots as numbers (:func:`fit_curves`),
    drawn as SVG.
    """
    meta, inputs = input_rows([("config file", input_path)] + [("data file", p) for p in data_files],
                              "millflow fit", [["model", out.get("model", "")],
                                               ["covariance", out.get("covariance_kind", "")]])
    sections = [("", table(["", ""], meta, cls="meta"))]
    rows = []
    for name, p in out.get("params", {}).items():
        ci = p.get("ci95") or [None, None]
        rows.append([name, (p.get("value"), f"params.{name}.value"), (p.get("se"), f"params.{name}.se"),
                     (p.get("p_value"), f"params.{name}.p_value"), (ci[0], f"params.{name}.ci95.0"),
                     (ci[1], f"params.{name}.ci95.1"), "; ".join(p.get("flags") or []) or "ok"])
    sections.append(("Parameters", table(["parameter", "value", "SE", "p", "95 % low", "95 % high", "flags"], rows,
                                         cls="params")))
    stats = [["data points", (out.get("n_data"), "n_data")], ["parameters", (out.get("n_params"), "n_params")],
             ["SSR", (out.get("ssr"), "ssr")], ["SER", (out.get("ser"), "ser")],
             ["condition number", (out.get("condition_number"), "condition_number")],
             ["run time s", (out.get("runtime_s"), "runtime_s")]]
    if out.get("prediction_mean_rmse") is not None:
        stats.append(["held-out mean RMSE", (out["prediction_mean_rmse"], "prediction_mean_rmse")])
    sections.append(("Fit statistics", table(["quantity", "value"], stats)))
    disc = (out.get("discrimination") or {}).get("table")
    if disc:
        rk = [[r["model"], (r["ssr"], f"discrimination.table.{k}.ssr"), r["n_params"],
               (r["aic"], f"discrimination.table.{k}.aic"), (r["bic"], f"discrimination.table.{k}.bic"),
               (r["delta_aic"], f"discrimination.table.{k}.delta_aic")] for k, r in enumerate(disc)]
        sections.append(("Candidate models (AIC)", table(["model", "SSR", "params", "AIC", "BIC", "dAIC"], rk)))
    if curves:
        sections.append(("Measured and fitted size distributions", _fit_plots(curves)))
    sections += inputs
    return page(f"Fit: {out.get('model', '')}", sections, data=_finite(out), source="fit.json")


# ------------------------------------------------------------------------------ scaleup
def _contribution_rows(mf: dict) -> tuple[list, list]:
    unit = "t/h" if mf.get("quantity") == "throughput_tph" else "um"
    head = ["source", f"95 % half-width {unit}", "% of the value", "factor", "alternatives", "how"]
    rows = []
    for name, r in (mf.get("contributions") or {}).items():
        k = f"model_form.contributions.{name}."
        alts = ", ".join(f"{a} {fmt(v)}" for a, v in (r.get("alternatives") or {}).items())
        factor = math.exp(r["log_factor"]) if r.get("log_factor") is not None else None
        rows.append([name, (r.get("half_width"), k + "half_width"), (r.get("rel"), k + "rel", 4, 100.0),
                     f"{fmt(factor)}", alts, r.get("how", "")])
    t = mf.get("total") or {}
    if t:
        rows.append(["total", f"[{fmt(t.get('lo'))}, {fmt(t.get('hi'))}]", "-",
                     (t.get("factor"), "model_form.total.factor"), "", t.get("how", "")])
    return head, rows


def scaleup_report(s: dict, ds, *, input_path=None, fit_path=None) -> str:
    """The page of a scale-up.

    ``s`` is scaleup.json (the summary ``millflow scaleup --json`` prints; its ``circuit``
    the plant circuit's streams and units at the estimate) and ``ds`` the scale-up Dataset
    (product passing with its bands).
    """
    from millflow.report.flowsheet import drawing, stream_and_unit_sections

    meta, inputs = input_rows([("lab fit", fit_path), ("plant file", input_path)], "millflow scaleup",
                              [["scaling", s.get("scaling", "")], ["power model", s.get("power_model", "")]])
    sections = [("", table(["", ""], meta, cls="meta"))]
    keys = [("fresh feed t/h", "feed_tph"), ("P80 um", "p80_um"), ("net power kW", "power_net_kW"),
            ("gross power kW", "power_gross_kW"), ("specific energy kWh/t", "specific_energy_kWh_per_t"),
            ("tau s", "tau_s"), ("hold-up kg", "holdup_kg"), ("A factor", "A_factor"),
            ("target P80 um", "target_p80_um"), ("throughput at target t/h", "throughput_tph"),
            ("specific energy at target kWh/t", "specific_energy_at_target_kWh_per_t"),
            ("mass balance error", "mass_balance")]
    rows = [[label, (s.get(k), k)] for label, k in keys if s.get(k) is not None]
    if s.get("circulating_load") is not None:
        rows.append(["circulating load %", (s["circulating_load"], "circulating_load", 4, 100.0)])
    sections.append(("Prediction", table(["quantity", "value"], rows, cls="prediction")))
    band_rows = []
    for q, methods in (s.get("bands") or {}).items():
        for m, b in methods.items():
            band_rows.append([q, m, (b.get("lo"), f"bands.{q}.{m}.lo"), (b.get("hi"), f"bands.{q}.{m}.hi")])
    if band_rows:
        sections.append(("95 % bands from the fit's covariance", table(["quantity", "method", "low", "high"],
                                                                        band_rows, cls="bands")))
    mf = s.get("model_form")
    if mf:
        head, crow = _contribution_rows(mf)
        sections.append((f"Band contributions to {mf.get('quantity')} = {fmt(mf.get('value'))}",
                         table(head, crow, cls="contributions")))
    circuit = s.get("circuit")
    if circuit:
        sections.append(("Plant circuit at the estimate", drawing(circuit)))
        sections += stream_and_unit_sections(circuit, "circuit.", " of the plant circuit")
    x = list(ds.x.values * 1e6)
    series = [("fresh feed", x, list(100 * ds.feed_passing.values), "dashed"),
              (f"plant product (P80 {fmt(s.get('p80_um'))} um)", x, list(100 * ds.passing.values))]
    for k, m in enumerate(ds.estimator.values):
        series.append((f"95 % band ({m})", x, list(100 * ds.passing_lo.sel(estimator=m).values), {"color": 2 + k}))
        series.append((None, x, list(100 * ds.passing_hi.sel(estimator=m).values), {"color": 2 + k}))
    sections.append(("Product size distribution", line_plot(series, xlabel="size [um]",
                                                           ylabel="cumulative passing [%]", ylim=(0, 100))))
    sections += inputs
    return page(f"Scale-up: {s.get('title', '')}", sections, data=_finite(s), source="scaleup.json")


# ------------------------------------------------------------------------------ compare
#: compare.json's stream columns: (heading, key), A and B side by side.
COMPARE_COLUMNS = [("solids t/h", "solids_tph"), ("water t/h", "water_tph"), ("% solids", "solids_content_pct"),
                   ("P80 um", "p80_um"), ("P50 um", "p50_um")]


def compare_report(result: dict, *, inputs=None) -> str:
    """The page of ``millflow compare``.

    ``result`` is compare.json (the JSON it prints, with both flowsheets' summaries under
    ``summaries``); ``inputs``: the two files.
    """
    from millflow.report.flowsheet import drawing, stream_and_unit_sections

    sa, sb = result["summaries"]["a"], result["summaries"]["b"]
    paths = inputs or (result["a"], result["b"])
    meta, inputs_html = input_rows([("A", paths[0]), ("B", paths[1])], "millflow compare")
    sections = [("", table(["", ""], meta, cls="meta"))]
    wet = any(r.get("water_tph_a") is not None or r.get("water_tph_b") is not None for r in result["streams"])
    cols = [c for c in COMPARE_COLUMNS if wet or c[1] not in ("water_tph", "solids_content_pct")]
    head = ["stream"]
    for label, key in cols:
        head += [f"{label} A", f"{label} B"] + ([f"{label.split()[0]} B - A"] if key in ("p80_um", "p50_um") else [])
    rows = []
    for k, r in enumerate(result["streams"]):
        row = [r["stream"]]
        for _, key in cols:
            row += [(r.get(f"{key}_a"), f"streams.{k}.{key}_a"), (r.get(f"{key}_b"), f"streams.{k}.{key}_b")]
            if key in ("p80_um", "p50_um"):
                row.append((r.get(f"d_{key}"), f"streams.{k}.d_{key}"))
        rows.append(row)
    sections.append(("Streams of the same name", table(head, rows, cls="compare")))
    other = []
    for side in ("a", "b"):
        for n in result["circulating_load"][side] or {}:
            other.append([f"circulating load of {n} % ({side.upper()})",
                          (result["circulating_load"][side][n], f"circulating_load.{side}.{n}", 4, 100.0)])
        other.append([f"circuit specific energy kWh/t of product ({side.upper()})",
                      (result["specific_energy_kWh_per_t"][side], f"specific_energy_kWh_per_t.{side}")])
        other.append([f"mass balance error ({side.upper()})",
                      (result["summaries"][side].get("mass_balance_error"), f"summaries.{side}.mass_balance_error")])
    sections.append(("Circuits", table(["quantity", "value"], other, cls="circuits")))
    for side, s in (("A", sa), ("B", sb)):
        name = s.get("title") or Path(str(s.get("source_file", ""))).name
        sections.append((f"Flowsheet {side}: {name}", drawing(s)))
        sections += stream_and_unit_sections(s, f"summaries.{side.lower()}.", f" of {side}")
    series = []
    for k, r in enumerate(result["streams"]):
        for side, s, style in (("A", sa, "line"), ("B", sb, "dashed")):
            st = s["streams"][r["stream"]]
            series.append((f"{r['stream']} ({side})", st["size_um"],
                           [None if v is None else 100 * v for v in st["cum_passing"]], {"style": style, "color": k}))
    sections.append(("Size distributions (A solid, B dashed)", line_plot(
        series, xlabel="size [um]", ylabel="cumulative passing [%]", ylim=(0, 100), height=420)))
    sections += inputs_html
    return page(f"Compare: {Path(result['a']).name} and {Path(result['b']).name}", sections, data=_finite(result),
                source="compare.json")


# -------------------------------------------------------------------------------- sweep
#: Cases in a sweep's summary.json and its report table (all of them are in sweep.csv and sweep.nc).
SWEEP_ROWS = 500
#: Outputs drawn against each varied key: (variable of sweep.nc, axis label, scale).
SWEEP_OUTPUTS = [("p80_um", "P80 [um]", 1.0), ("p50_um", "P50 [um]", 1.0),
                 ("circulating_load", "circulating load [%]", 100.0),
                 ("specific_energy_kWh_per_t", "specific energy [kWh/t of product]", 1.0)]


def sweep_plots(ds, keys: list) -> str:
    """SVG plots of each output against each varied key.

    On a grid, one line per value of the other keys (at most 10; points beyond), in a Latin
    hypercube the cases as points.
    """
    import numpy as np

    out = []
    for key in keys:
        for var, label, scale in SWEEP_OUTPUTS:
            if var not in ds:
                continue
            da = ds[var] * scale
            extra = [d for d in da.dims if d not in (key, "case") and d not in keys]
            if len(extra) > 1:
                continue
            series = []
            for sel in ([{}] if not extra else [{extra[0]: v} for v in da[extra[0]].values]):
                d = da.sel(sel) if sel else da
                tag = f" {next(iter(sel.values()))}" if sel else ""
                if "case" in d.dims:
                    series.append((f"cases{tag}", list(ds[key].values), list(d.values), "points"))
                    continue
                others = [k for k in keys if k != key]
                d = d.transpose(key, *others)
                flat = d.values.reshape(d.sizes[key], -1)
                combos = list(np.ndindex(*[d.sizes[k] for k in others])) if others else [()]
                style = "line" if len(combos) <= 10 else "points"
                for j, combo in enumerate(combos):
                    lab = ", ".join(f"{k.rsplit('.', 1)[-1]} {fmt(float(d[k].values[i]))}"
                                    for k, i in zip(others, combo))
                    series.append(((lab or var) + tag if style == "line" else None, list(d[key].values),
                                   list(flat[:, j]), {"style": style, "color": j}))
            out.append(line_plot(series, xlabel=key, ylabel=label, xlog=False, width=620, height=340,
                                 title=f"{label.split(' [')[0]} against {key}"))
    return "".join(out)


def sweep_report(summary: dict, ds=None, *, input_path=None) -> str:
    """The page of ``millflow sweep``.

    ``summary`` is its summary.json (``cases`` the number of cases; ``columns`` and
    ``rows``: the first :data:`SWEEP_ROWS` rows of sweep.csv); ``ds`` the sweep's Dataset,
    drawn as SVG plots of each output against each varied key.
    """
    meta, inputs = input_rows([("flowsheet file", input_path)], "millflow sweep",
                              [["design", summary.get("design", "")], ["varied", summary.get("varied", "")]])
    cols, cases = summary.get("columns") or [], summary.get("rows") or []
    head = [["cases", (summary.get("cases"), "cases")], ["failed", (summary.get("failed"), "failed")]]
    sections = [("", table(["", ""], meta, cls="meta")), ("Sweep", table(["quantity", "value"], head))]
    if ds is not None:
        keys = [k for k in (summary.get("keys") or []) if k in ds.variables]
        sections.append(("Outputs against the varied keys", sweep_plots(ds, keys)))
    rows = []
    for k, r in enumerate(cases):
        rows.append([(v, f"rows.{k}.{j}") if isinstance(v, (int, float)) or v is None else str(v)
                     for j, v in enumerate(r)])
    n = summary.get("n_rows") or len(cases)
    note = "" if n <= len(cases) else f"<p>The first {len(cases)} of {n} rows; all are in sweep.csv.</p>"
    sections.append(("Cases (the rows of sweep.csv)", note + table(cols, rows, cls="cases")))
    sections += inputs
    return page(f"Sweep: {Path(summary.get('file', '')).name}", sections, data=_finite(summary),
                source="summary.json")
