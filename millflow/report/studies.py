"""``report.html`` of the studies: a breakage fit (``millflow fit``) and a scale-up
(``millflow scaleup``), from the same dicts the commands print with ``--json``.

Pages are built with :mod:`millflow.report.html` (self-contained, numbers at 4
significant digits with ``data-key`` paths into the embedded JSON). A fit's PNG plots are
embedded as data URIs, so the page stays one file.
"""
from __future__ import annotations

import base64
import hashlib
from pathlib import Path

from millflow.report.html import esc, line_plot, page, table
from millflow.report.html import finite as _finite

__all__ = ["fit_report", "scaleup_report", "compare_report", "sweep_report", "write_page"]


def _meta(command: str, input_path, extra: list) -> tuple[list, str | None]:
    from millflow import __version__

    text = name = sha = None
    if input_path is not None:
        try:
            raw = Path(input_path).read_bytes()
            sha = hashlib.sha256(raw).hexdigest()
            text, name = raw.decode("utf-8"), Path(input_path).name
        except (OSError, UnicodeDecodeError):
            pass
    rows = [["input file", name or "-"], ["input SHA-256", sha or "-"], ["millflow version", __version__],
            ["command", command]] + extra
    return rows, (None if text is None else f"<pre>{esc(text)}</pre>")


def _png(path) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{esc(Path(path).stem)}" style="max-width:100%" src="data:image/png;base64,{data}">'


def fit_report(out: dict, *, input_path=None, images=()) -> str:
    """The page of a breakage fit: ``out`` is the dict ``millflow fit --json`` prints."""
    meta, src = _meta("millflow fit", input_path, [["model", out.get("model", "")],
                                                   ["covariance", out.get("covariance_kind", "")]])
    sections = [("", table(["", ""], meta, cls="meta"))]
    rows = []
    for name, p in out.get("params", {}).items():
        ci = p.get("ci95") or [None, None]
        rows.append([name, (p.get("value"), f"params.{name}.value"), (p.get("se"), f"params.{name}.se"),
                     (p.get("p_value"), f"params.{name}.p_value"), (ci[0], f"params.{name}.ci95.0"),
                     (ci[1], f"params.{name}.ci95.1"), "; ".join(p.get("flags") or []) or "ok"])
    sections.append(("Parameters", table(["parameter", "value", "SE", "p", "95 % low", "95 % high", "flags"], rows)))
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
    imgs = "".join(_png(p) for p in images if Path(p).is_file())
    if imgs:
        sections.append(("Plots", imgs))
    if src:
        sections.append(("Input file", src))
    return page(f"Fit: {out.get('model', '')}", sections, data=_finite(out))


def scaleup_report(s: dict, ds, *, input_path=None) -> str:
    """The page of a scale-up: ``s`` is the summary ``millflow scaleup --json`` prints and
    ``ds`` the scale-up Dataset (product passing with its bands)."""
    meta, src = _meta("millflow scaleup", input_path, [["lab fit", s.get("fit", "")],
                                                       ["scaling", s.get("scaling", "")],
                                                       ["power model", s.get("power_model", "")]])
    sections = [("", table(["", ""], meta, cls="meta"))]
    keys = [("fresh feed t/h", "feed_tph"), ("P80 um", "p80_um"), ("net power kW", "power_net_kW"),
            ("gross power kW", "power_gross_kW"), ("specific energy kWh/t", "specific_energy_kWh_t"),
            ("tau s", "tau_s"), ("hold-up kg", "holdup_kg"), ("A factor", "A_factor"),
            ("target P80 um", "target_p80_um"), ("throughput at target t/h", "throughput_tph"),
            ("specific energy at target kWh/t", "specific_energy_at_target_kWh_t"),
            ("mass balance error", "mass_balance")]
    rows = [[label, (s.get(k), k)] for label, k in keys if s.get(k) is not None]
    if s.get("circulating_load") is not None:
        rows.append(["circulating load %", (s["circulating_load"], "circulating_load", 4, 100.0)])
    sections.append(("Prediction", table(["quantity", "value"], rows)))
    band_rows = []
    for q, methods in (s.get("bands") or {}).items():
        for m, b in methods.items():
            band_rows.append([q, m, (b.get("lo"), f"bands.{q}.{m}.lo"), (b.get("hi"), f"bands.{q}.{m}.hi")])
    if band_rows:
        sections.append(("95 % bands", table(["quantity", "method", "low", "high"], band_rows)))
    x = list(ds.x.values * 1e6)
    series = [("fresh feed", x, list(100 * ds.feed_passing.values)),
              (f"plant product (P80 {s.get('p80_um', float('nan')):.4g} um)", x, list(100 * ds.passing.values))]
    for m in ds.estimator.values:
        series.append((f"95 % band low ({m})", x, list(100 * ds.passing_lo.sel(estimator=m).values)))
        series.append((f"95 % band high ({m})", x, list(100 * ds.passing_hi.sel(estimator=m).values)))
    sections.append(("Product size distribution", line_plot(series, xlabel="size [um]",
                                                           ylabel="cumulative passing [%]", ylim=(0, 100))))
    if src:
        sections.append(("Plant file", src))
    return page(f"Scale-up: {s.get('title', '')}", sections, data=_finite(s))


def write_page(path, html: str) -> Path:
    """Write a page; returns the path."""
    path = Path(path)
    path.write_text(html, encoding="utf-8")
    return path


def compare_report(result: dict, sa: dict, sb: dict) -> str:
    """The page of ``millflow compare``: ``result`` is the JSON it prints, ``sa`` and ``sb``
    the two flowsheets' summaries (each drawn with its stream labels)."""
    from millflow.report.flowsheet import flowsheet_layout_of, stream_label
    from millflow.report.html import flowsheet_svg

    meta, _ = _meta("millflow compare", None, [["A", result["a"]], ["B", result["b"]]])
    sections = [("", table(["", ""], meta[2:], cls="meta"))]
    rows = []
    for k, r in enumerate(result["streams"]):
        rows.append([r["stream"]] + [(r[c], f"streams.{k}.{c}") for c in
                                     ("tph_a", "tph_b", "p80_um_a", "p80_um_b", "d_p80_um", "p50_um_a", "p50_um_b",
                                      "d_p50_um")])
    sections.append(("Streams of the same name", table(
        ["stream", "t/h A", "t/h B", "P80 um A", "P80 um B", "P80 B - A", "P50 um A", "P50 um B", "P50 B - A"], rows)))
    other = []
    for side in ("a", "b"):
        for n in result["circulating_load"][side] or {}:
            other.append([f"circulating load of {n} % ({side.upper()})",
                          (result["circulating_load"][side][n], f"circulating_load.{side}.{n}", 4, 100.0)])
        other.append([f"specific energy kWh/t ({side.upper()})",
                      (result["specific_energy_kWh_per_t"][side], f"specific_energy_kWh_per_t.{side}")])
    sections.append(("Circuit", table(["quantity", "value"], other)))
    for side, s in (("A", sa), ("B", sb)):
        lay = flowsheet_layout_of(s)
        svg = flowsheet_svg(lay, {u: [esc(u), esc(r.get("type", ""))] for u, r in s["units"].items()},
                            {n: stream_label(n, st) for n, st in s["streams"].items()})
        sections.append((f"Flowsheet {side}: {s.get('title') or s.get('source_file')}", svg))
    series = []
    for r in result["streams"]:
        for side, s in (("A", sa), ("B", sb)):
            st = s["streams"][r["stream"]]
            series.append((f"{r['stream']} ({side})", st["size_um"], [None if v is None else 100 * v
                                                                        for v in st["cum_passing"]]))
    sections.append(("Size distributions", line_plot(series, xlabel="size [um]", ylabel="cumulative passing [%]",
                                                      ylim=(0, 100), height=420)))
    return page(f"Compare: {Path(result['a']).name} and {Path(result['b']).name}", sections, data=_finite(result))


#: Cases shown in a sweep's report table (all of them are in sweep.csv and sweep.nc).
SWEEP_ROWS = 500


def sweep_report(summary: dict, table_df, *, input_path=None) -> str:
    """The page of ``millflow sweep``: ``summary`` its JSON and ``table_df`` the case table
    (the rows of sweep.csv). The page embeds ``{"summary", "columns", "cases"}`` (the
    first :data:`SWEEP_ROWS` cases as rows) and every shown number points into it."""
    meta, src = _meta("millflow sweep", input_path, [["design", summary.get("design", "")],
                                                     ["varied", summary.get("varied", "")]])
    cols = list(table_df.columns)
    # rows as lists (column names hold dots: units.ball_mill.tau_min), keys cases.<row>.<column index>
    cases = _finite(table_df.head(SWEEP_ROWS).values.tolist())
    data = {"summary": summary, "columns": cols, "cases": cases}
    head = [["cases", (summary.get("cases"), "summary.cases")], ["failed", (summary.get("failed"), "summary.failed")]]
    sections = [("", table(["", ""], meta, cls="meta")), ("Sweep", table(["quantity", "value"], head))]
    rows = []
    for k, r in enumerate(cases):
        rows.append([(v, f"cases.{k}.{j}") if isinstance(v, (int, float)) or v is None else str(v)
                     for j, v in enumerate(r)])
    note = ("" if len(table_df) <= SWEEP_ROWS
            else f"<p>The first {SWEEP_ROWS} of {len(table_df)} cases; all are in sweep.csv.</p>")
    sections.append(("Cases", note + table(cols, rows)))
    if src:
        sections.append(("Flowsheet file", src))
    return page(f"Sweep: {Path(summary.get('file', '')).name}", sections, data=_finite(data))
