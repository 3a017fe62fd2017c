"""The ``report.html`` of a solved flowsheet, made from its summary.

``report.html`` of a solved flowsheet, made from its summary (the dict written to
``summary.json``), so every number on the page is one of summary.json.

:func:`flowsheet_report` needs only that dict (streams with ``from``/``to``, solids and
water t/h, % solids, P80, P50, size and cumulative passing; units with their reports),
optional partition curves and the input file: any command whose results have this shape
(``millflow run``, a survey balance) can write the same page with :func:`write_report`.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

from millflow.report.html import esc, flowsheet_svg, fmt, line_plot, method_text, page, read_input, table
from millflow.report.layout import LAYERS_PER_ROW, layout
from millflow.report.textsize import Strong, name_lines

__all__ = ["flowsheet_report", "write_report", "partition_curves", "flowsheet_layout_of", "drawing", "stream_label",
           "unit_lines"]


def _unit_of(port: str) -> str:
    return port.rsplit(".", 1)[0]


def unit_lines(name: str, kind: str) -> list:
    """The lines of a unit's box: its name (bold; a long one on two lines, shortened beyond) and its type."""
    return [Strong(esc(t)) for t in name_lines(name, 170.0)] + [esc(kind)]


def flowsheet_layout_of(summary: dict, label_text: dict | None = None, *, layers_per_row: int = LAYERS_PER_ROW):
    """The drawing's layout for a summary's units and streams.

    The drawing's layout for a summary's units and streams (see :mod:`millflow.report.layout`),
    each label box sized to its text (``label_text``: stream -> lines; default :func:`stream_label`).
    """
    units = {u: r.get("type", "") for u, r in summary["units"].items()}
    streams = {n: (_unit_of(s["from"]), s["to"]) for n, s in summary["streams"].items()}
    if label_text is None:
        label_text = {n: stream_label(n, s) for n, s in summary["streams"].items()}
    return layout(units, streams, label_text=label_text, unit_text={u: unit_lines(u, k) for u, k in units.items()},
                  layers_per_row=layers_per_row)


def drawing(summary: dict, label_text: dict | None = None, *, layers_per_row: int = LAYERS_PER_ROW,
            standalone: bool = False) -> str:
    """The flowsheet drawing (SVG) of a summary.

    Units, routes and each stream's label (``label_text``: stream -> lines; default
    :func:`stream_label`).
    """
    if label_text is None:
        label_text = {n: stream_label(n, s) for n, s in summary["streams"].items()}
    lay = flowsheet_layout_of(summary, label_text, layers_per_row=layers_per_row)
    unit_text = {u: unit_lines(u, r.get("type", "")) for u, r in summary["units"].items()}
    return flowsheet_svg(lay, unit_text, label_text, standalone=standalone,
                         title=f"flowsheet: {summary.get('title') or summary.get('source_file') or ''}")


def stream_label(name: str, s: dict) -> list[str]:
    """The lines of a stream's label.

    Name (a long one on two lines, shortened beyond,
    :func:`~millflow.report.textsize.name_lines`); solids t/h; water t/h and % solids (wet);
    P80.
    """
    lines = [Strong(esc(t)) for t in name_lines(name)] + [f"{fmt(s.get('solids_tph'))} t/h solids"]
    if s.get("water_tph") is not None:
        lines.append(f"{fmt(s.get('water_tph'))} t/h water, {fmt(s.get('solids_content_pct'))} % solids")
    lines.append(f"P80 {fmt(s.get('p80_um'))} um")
    return lines


def partition_curves(sol) -> dict:
    """Partition curves of a solved flowsheet's classifiers and mill screens.

    Partition curves of a :class:`~millflow.flowsheet.solve.FlowsheetSolution`: label ->
    (sizes [um], fraction to the coarse stream), for classifiers (the curve the solve used)
    and mill discharge screens.
    """
    fs = sol.flowsheet
    x = list(fs.grid.x * 1e6)
    out = {}
    for name, unit in fs.units.items():
        if unit.type in ("classifier", "hydrocyclone") and name in sol.unit_blocks:
            port = unit.ports[0]
            out[f"{name} to {port}"] = (x, [float(v) for v in sol.unit_blocks[name][port]])
        elif unit.type == "mill" and getattr(unit, "classification", None) is not None:
            out[f"{name} discharge, retained"] = (x, [float(v) for v in unit.discharge_efficiency(fs.grid)])
    return out


def _stream_rows(summary: dict, wet: bool, prefix: str = "") -> tuple[list, list]:
    """Head and rows of the stream table.

    ``prefix``: where the summary sits in the page's JSON (``summaries.a.`` in compare.json,
    ``circuit.`` in scaleup.json).
    """
    streams = summary["streams"]
    sizes = list(next(iter(streams.values())).get("passing_pct", {})) if streams else []
    head = ["stream", "from", "to", "solids t/h"] + (["water t/h", "% solids"] if wet else []) \
        + ["P80 um", "P50 um"] + [f"% passing {x} um" for x in sizes]
    rows = []
    for n, s in streams.items():
        k = f"{prefix}streams.{n}."
        row = [n, s["from"], s["to"], (s.get("solids_tph"), k + "solids_tph")]
        if wet:
            row += [(s.get("water_tph"), k + "water_tph"), (s.get("solids_content_pct"), k + "solids_content_pct")]
        row += [(s.get("p80_um"), k + "p80_um"), (s.get("p50_um"), k + "p50_um")]
        row += [(s.get("passing_pct", {}).get(x), f"{k}passing_pct.{x}") for x in sizes]
        rows.append(row)
    return head, rows


#: Unit table columns: (heading, key in the unit's summary, scale to the shown unit).
UNIT_COLUMNS = [("solids in t/h", "solids_in_tph", 1.0), ("water in t/h", "water_in_tph", 1.0),
                ("power kW", "power_kW", 1.0), ("kWh/t", "specific_energy_kWh_per_t", 1.0),
                ("tau min", "tau_s", 1 / 60), ("hold-up t", "holdup_kg", 1e-3),
                ("pressure kPa", "pressure_Pa", 1e-3), ("d50c um", "d50c_m", 1e6),
                ("water split", "water_split", 1.0), ("mass balance error", "mass_balance_error", 1.0),
                ("water balance error", "water_balance_error", 1.0), ("error estimate", "error_estimate", 1.0)]


def _unit_rows(summary: dict, prefix: str = "") -> tuple[list, list]:
    """Head and rows of the unit table (the method with its numbers at 4 digits)."""
    units = summary["units"]
    cols = [c for c in UNIT_COLUMNS if any(r.get(c[1]) is not None for r in units.values())]
    head = ["unit", "type"] + [c[0] for c in cols] + ["method"]
    rows = []
    for u, r in units.items():
        rows.append([u, r.get("type", "")] + [(r.get(key), f"{prefix}units.{u}.{key}", 4, scale)
                                              for _, key, scale in cols] + [method_text(r.get("method", ""))])
    return head, rows


def stream_and_unit_sections(summary: dict, prefix: str = "", title: str = "") -> list:
    """The (heading, html) sections of a flowsheet's streams and units, keys under ``prefix``."""
    wet = any(s.get("water_tph") is not None for s in summary["streams"].values())
    head, rows = _stream_rows(summary, wet, prefix)
    uhead, urows = _unit_rows(summary, prefix)
    return [(f"Streams{title}", table(head, rows, cls="streams")), (f"Units{title}", table(uhead, urows, cls="units"))]


def _solver_rows(summary: dict) -> list:
    rows = [["mass balance error (products vs feeds)", ("mass_balance_error",)]]
    if summary.get("water_balance_error") is not None:
        rows.append(["water balance error", ("water_balance_error",)])
    if summary.get("specific_energy_kWh_per_t") is not None:
        rows.append(["circuit specific energy kWh/t of product", ("specific_energy_kWh_per_t",)])
    for n in summary.get("circulating_load") or {}:
        rows.append([f"circulating load of {n} %", (f"circulating_load.{n}", 100.0)])
    solver = summary.get("solver") or {}
    if solver.get("relative_residual") is not None:
        rows.append(["linear solve relative residual", ("solver.relative_residual",)])
    tear = solver.get("tear")
    if tear:
        rows.append([f"tear iterations ({tear.get('method')})", ("solver.tear.iterations",)])
        if tear.get("residual_history"):
            last = len(tear["residual_history"]) - 1
            rows.append(["tear: last relative change", (f"solver.tear.residual_history.{last}",)])
    g = summary.get("grid_check") or {}
    if g.get("worst") is not None:
        rows.append([f"grid check: largest move on {g.get('refined_classes')} classes "
                     f"({g.get('worst_at')}), %", ("grid_check.worst", 100.0)])
        rows.append(["grid check: tolerance %", ("grid_check.threshold", 100.0)])
    if summary.get("runtime_s") is not None:
        rows.append(["run time s", ("runtime_s",)])
    out = []
    for label, (key, *scale) in rows:
        out.append([label, (_get(summary, key), key, 4, scale[0] if scale else 1.0)])
    return out


def _get(d, key: str):
    for part in key.split("."):
        if isinstance(d, list):
            d = d[int(part)]
        elif isinstance(d, dict):
            d = d.get(part)
        else:
            return None
    return d


def flowsheet_report(summary: dict, *, partition: dict | None = None, input_text: str | None = None,
                     input_name: str | None = None, command: str = "millflow run") -> str:
    """The HTML page of a flowsheet's results (see the module docstring)."""
    from millflow import __version__

    streams = summary["streams"]
    svg = drawing(summary)
    sections = []
    sha = summary.get("input_sha256")
    if input_text is not None and not sha:
        sha = hashlib.sha256(input_text.encode("utf-8")).hexdigest()
    meta = [["input file", input_name or summary.get("source_file", "")], ["input SHA-256", sha or "-"],
            ["millflow version", summary.get("millflow_version", __version__)], ["command", command],
            ["solver", (summary.get("solver") or {}).get("structure", "")],
            ["kernel", summary.get("kernel", "")]]
    g = summary.get("grid_check") or {}
    if g.get("status"):
        meta.append(["grid check", g["status"]])
    sections.append(("", table(["", ""], meta, cls="meta")))
    sections.append(("Flowsheet", svg))
    sections += stream_and_unit_sections(summary)
    sections.append(("Balances, solver and grid errors", table(["quantity", "value"], _solver_rows(summary),
                                                              cls="solver")))
    psd = [(f"{n} (P80 {fmt(s.get('p80_um'))} um)", s.get("size_um", []), [None if v is None else 100 * v
                                                                            for v in s.get("cum_passing", [])])
           for n, s in streams.items()]
    sections.append(("Particle size distributions", line_plot(
        psd, xlabel="size [um] (upper class edge)", ylabel="cumulative passing [%]", ylim=(0, 100))))
    if partition:
        curves = [(lab, xs, ys) for lab, (xs, ys) in partition.items()]
        sections.append(("Partition curves", line_plot(curves, xlabel="size [um]",
                                                      ylabel="fraction to the coarse stream [-]", ylim=(0, 1))))
    if input_text is not None:
        sections.append((f"Input file {input_name or ''}", f"<pre>{esc(input_text)}</pre>"))
    return page(summary.get("title") or summary.get("source_file") or "millflow results", sections, data=summary,
                source="summary.json")


def write_report(path, summary: dict, *, input_path=None, partition: dict | None = None,
                 command: str = "millflow run") -> Path:
    """Write the flowsheet report to ``path``.

    Write :func:`flowsheet_report` to ``path`` (with the input file's text when
    ``input_path`` is given); returns the path.
    """
    text, name = read_input(input_path)
    path = Path(path)
    path.write_text(flowsheet_report(summary, partition=partition, input_text=text, input_name=name,
                                     command=command), encoding="utf-8")
    return path
