"""The ``results.xlsx`` workbook: the mass balance as a plant engineer exports it.

``results.xlsx``: the mass balance as a plant engineer exports it from JKSimMet or
Moly-Cop Tools, from the summary (the dict of ``summary.json``).

Sheets:

- ``Streams``: one row per stream: from, to, solids t/h, water t/h, % solids, P80 um,
  P50 um, % passing the named sizes.
- ``Size tph`` (when the class flows are given): the size-by-stream mass balance, one row
  per size class (upper edge in um, the sink last), one column per stream, solids t/h in
  the class, and a total row equal to the stream's solids t/h.
- ``Size % passing``: cumulative % passing the upper edge of each class, per stream.
- ``Units``: each unit's report (type, t/h in, power, kWh/t, tau, cyclone pressure and
  d50c, balance errors, error estimate, method).
- ``About``: title, input file, its SHA-256, millflow version, mass and water balance errors.

Numbers are written at full precision (Excel shows them as formatted: 0.0 for t/h and %,
0 for um); openpyxl is an optional dependency (``pip install millflow[report]``).
"""
from __future__ import annotations

import sys
from pathlib import Path

from millflow.errors import InputError

__all__ = ["excel_available", "write_workbook", "write_balance_workbook", "class_flows_tph"]


def excel_available() -> bool:
    """True when openpyxl can be imported."""
    try:
        _openpyxl()
    except ImportError:
        return False
    return True


def _openpyxl():
    """Import openpyxl without Pillow.

    openpyxl imports Pillow, when installed, only to embed images in a sheet, which these
    workbooks never hold; Pillow's import is ~50 ms of a run's start-up. It stays
    importable for everything else (the run's PNGs).
    """
    if sys.modules.get("openpyxl") is not None:
        return sys.modules["openpyxl"]
    hide = "PIL" not in sys.modules
    if hide:
        sys.modules["PIL"] = None  # ImportError inside openpyxl's optional import
    try:
        import openpyxl
    finally:
        if hide and sys.modules.get("PIL", 0) is None:
            del sys.modules["PIL"]
    return openpyxl


def class_flows_tph(sol) -> dict:
    """Stream name -> solids t/h in each size class of a solved flowsheet."""
    fs = sol.flowsheet
    return {n: [float(v) * 3.6 for v in sol.flows[k]] for k, n in enumerate(fs.stream_names)}


def _num(v):
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def write_workbook(path, summary: dict, class_tph: dict | None = None) -> Path:
    """Write the workbook (see the module docstring) to ``path``; returns the path."""
    try:
        _openpyxl()
        from openpyxl import Workbook
        from openpyxl.styles import Font
    except ImportError:
        raise InputError("results.xlsx needs openpyxl: pip install 'millflow[report]'") from None
    from millflow.report.flowsheet import UNIT_COLUMNS
    from millflow.report.html import method_text

    wb = Workbook()
    bold = Font(bold=True)
    streams = summary["streams"]
    names = list(streams)
    wet = any(s.get("water_tph") is not None for s in streams.values())
    sizes = list(next(iter(streams.values())).get("passing_pct", {})) if streams else []

    ws = wb.active
    ws.title = "Streams"
    head = ["stream", "from", "to", "solids t/h"] + (["water t/h", "% solids"] if wet else []) + \
        ["P80 um", "P50 um"] + [f"% passing {x} um" for x in sizes]
    ws.append(head)
    for n, s in streams.items():
        row = [n, s["from"], s["to"], _num(s.get("solids_tph"))]
        if wet:
            row += [_num(s.get("water_tph")), _num(s.get("solids_content_pct"))]
        row += [_num(s.get("p80_um")), _num(s.get("p50_um"))] + [_num(s.get("passing_pct", {}).get(x))
                                                                  for x in sizes]
        ws.append(row)
    _style(ws, bold, {h: ("0" if h.endswith(" um") else "0.0") for h in head[3:]})

    size_um = next(iter(streams.values())).get("size_um", []) if streams else []
    if class_tph is not None:
        ws = wb.create_sheet("Size tph")
        ws.append(["size um (upper edge)"] + names)
        for k, x in enumerate(size_um):
            ws.append([x] + [_num(class_tph[n][k]) for n in names])
        ws.append(["total"] + [_num(streams[n].get("solids_tph")) for n in names])
        _style(ws, bold, {n: "0.000" for n in names})
    ws = wb.create_sheet("Size % passing")
    ws.append(["size um (upper edge)"] + names)
    for k, x in enumerate(size_um):
        ws.append([x] + [None if streams[n]["cum_passing"][k] is None else 100 * streams[n]["cum_passing"][k]
                         for n in names])
    _style(ws, bold, {n: "0.00" for n in names})

    ws = wb.create_sheet("Units")
    cols = [c for c in UNIT_COLUMNS if any(r.get(c[1]) is not None for r in summary["units"].values())]
    ws.append(["unit", "type"] + [c[0] for c in cols] + ["method"])
    for u, r in summary["units"].items():
        ws.append([u, r.get("type")] + [None if _num(r.get(k)) is None else r[k] * scale for _, k, scale in cols]
                  + [method_text(r.get("method"))])
    _style(ws, bold, {})

    ws = wb.create_sheet("About")
    for key, val in (("title", summary.get("title")), ("input file", summary.get("source_file")),
                     ("input SHA-256", summary.get("input_sha256")),
                     ("millflow version", summary.get("millflow_version")),
                     ("mass balance error", summary.get("mass_balance_error")),
                     ("water balance error", summary.get("water_balance_error")),
                     ("conventions", "class 1 coarsest, the last class the sink; size = upper class edge; "
                                     "t/h = metric tonnes per hour")):
        ws.append([key, val])
    _style(ws, bold, {})
    path = Path(path)
    wb.save(path)
    return path


def write_balance_workbook(path, summary: dict) -> Path:
    """The workbook of a reconciled survey (``millflow balance``), from its summary.json dict.

    Sheets: ``Streams`` (per stream: solids, water and % solids measured, adjusted and SD,
    P80 and P50 of the adjusted analysis), ``Size tph`` (adjusted solids t/h per sieve class
    and stream, a total row equal to the stream's adjusted solids), ``Size % passing``
    (adjusted cumulative passing at each sieve), ``Measurements`` (every measured value:
    measured, SD, adjusted, its SD, the adjustment in SDs, the normalised adjustment) and
    ``About`` (input, SHA-256, version, chi-square test, circulating loads).
    """
    try:
        _openpyxl()
        from openpyxl import Workbook
        from openpyxl.styles import Font
    except ImportError:
        raise InputError("results.xlsx needs openpyxl: pip install 'millflow[report]'") from None
    wb = Workbook()
    bold = Font(bold=True)
    streams = summary["streams"]
    names = list(streams)
    wet = any("water_tph" in s for s in streams.values())

    ws = wb.active
    ws.title = "Streams"
    cols = [("solids measured t/h", "solids_measured_tph"), ("solids adjusted t/h", "solids_tph"),
            ("solids SD t/h", "solids_sd_tph")]
    if wet:
        cols += [("water measured t/h", "water_measured_tph"), ("water adjusted t/h", "water_tph"),
                 ("water SD t/h", "water_sd_tph"), ("% solids measured", "solids_content_measured_pct"),
                 ("% solids adjusted", "solids_content_pct")]
    cols += [("P80 adjusted um", "p80_um"), ("P50 adjusted um", "p50_um")]
    head = ["stream", "from", "to"] + [c[0] for c in cols]
    ws.append(head)
    for n, s in streams.items():
        ws.append([n, s.get("from"), s.get("to")] + [_num(s.get(k)) for _, k in cols])
    _style(ws, bold, {h: ("0" if h.endswith(" um") else "0.00") for h in head[3:]})

    ws = wb.create_sheet("Size tph")
    ws.append(["size class"] + names)
    for k, lab in enumerate(summary.get("classes") or []):
        ws.append([lab] + [_num((streams[n].get("class_tph") or [None] * (k + 1))[k]) for n in names])
    ws.append(["total"] + [_num(streams[n].get("solids_tph")) for n in names])
    _style(ws, bold, {n: "0.000" for n in names})

    ws = wb.create_sheet("Size % passing")
    ws.append(["sieve um"] + names)
    for k, x in enumerate(summary.get("sieves_um") or []):
        ws.append([x] + [_num(streams[n]["passing_adjusted_pct"][k]) for n in names])
    _style(ws, bold, {n: "0.00" for n in names})

    ws = wb.create_sheet("Measurements")
    mcols = ["key", "class", "unit", "measured", "sd", "adjusted", "adjusted_sd", "adjustment_in_sd",
             "normalised_adjustment", "redundant"]
    ws.append(mcols)
    for m in summary.get("measurements") or []:
        ws.append([m.get(c) if c in ("key", "class", "unit", "redundant") else _num(m.get(c)) for c in mcols])
    _style(ws, bold, {c: "0.000" for c in mcols[3:9]})

    ws = wb.create_sheet("About")
    chi = summary.get("chi_square") or {}
    rows = [("title", summary.get("title")), ("input file", summary.get("source_file")),
            ("input SHA-256", summary.get("input_sha256")), ("millflow version", summary.get("millflow_version")),
            ("chi-square SSR", _num(chi.get("ssr"))), ("degrees of freedom", _num(chi.get("dof"))),
            ("chi-square 95 % point", _num(chi.get("critical_95"))), ("p-value", _num(chi.get("p_value"))),
            ("verdict", summary.get("chi_square_verdict")),
            ("gross-error candidates", ", ".join(c["measurement"] for c in summary.get("gross_error_candidates")
                                                 or []) or "none")]
    for n, c in (summary.get("circulating_load") or {}).items():
        rows += [(f"circulating load {n} %", _num(c.get("value_pct"))), (f"circulating load {n} SD %",
                                                                          _num(c.get("sd_pct")))]
    rows.append(("conventions", "adjusted = reconciled values; t/h = metric tonnes per hour; sizes in um"))
    for key, val in rows:
        ws.append([key, val])
    _style(ws, bold, {})
    path = Path(path)
    wb.save(path)
    return path


def _style(ws, bold, formats: dict) -> None:
    """Bold header, frozen first row and column, number formats by header, column widths."""
    head = [c.value for c in ws[1]]
    for c in ws[1]:
        c.font = bold
    ws.freeze_panes = "B2"
    for j, h in enumerate(head, start=1):
        fmt = formats.get(h)
        letter = ws.cell(row=1, column=j).column_letter
        if fmt:
            for row in ws.iter_rows(min_row=2, min_col=j, max_col=j):
                row[0].number_format = fmt
        width = max(len(str(c.value)) if c.value is not None and not isinstance(c.value, float) else 8
                    for c in ws[letter])
        ws.column_dimensions[letter].width = min(max(10, width + 2), 60)
