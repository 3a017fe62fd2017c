"""``report.html`` of a reconciled plant survey (``millflow balance``), made from its
summary (the dict written to ``summary.json``), so every number on the page is one of
summary.json (table cells and drawing labels carry ``data-key`` paths into it).

The page: the input file, its SHA-256 and the version; the chi-square test of the
weighted sum of squares; the flowsheet drawn with each stream's adjusted solids t/h (and
SD), water t/h, % solids and P80; the streams measured vs adjusted with the adjustment in
SDs; the gross-error candidates; the circulating loads with their SDs; every measurement
with its adjustment; what the survey leaves undetermined; the adjusted size distributions.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

from millflow.report.flowsheet import drawing
from millflow.report.html import esc, fmt, line_plot, page, read_input, table
from millflow.report.textsize import Strong, name_lines

__all__ = ["balance_report", "write_balance_report"]


def _label(name: str, s: dict) -> list:
    k = f"streams.{name}."
    lines = [Strong(esc(t)) for t in name_lines(name)]
    if s.get("solids_observable", True):
        lines.append((f"{fmt(s.get('solids_tph'))} &#177; {fmt(s.get('solids_sd_tph'), 2)} t/h solids",
                      k + "solids_tph"))
    else:
        lines.append("solids unobservable")
    if "water_tph" in s:
        lines.append((f"{fmt(s.get('water_tph'))} t/h water, {fmt(s.get('solids_content_pct'))} % solids",
                      k + "water_tph"))
    lines.append((f"P80 {fmt(s.get('p80_um'))} um", k + "p80_um"))
    return lines


def _adj_in_sd(measured, adjusted, sd):
    if measured is None or adjusted is None or not sd:
        return None
    return (adjusted - measured) / sd


def _stream_rows(summary: dict, wet: bool) -> tuple[list, list]:
    head = ["stream", "from", "to", "solids measured t/h", "solids adjusted t/h", "SD t/h"]
    if wet:
        head += ["water measured t/h", "water adjusted t/h", "water SD t/h", "% solids measured",
                 "% solids adjusted"]
    head += ["P80 adjusted um", "P50 adjusted um"]
    rows = []
    for n, s in summary["streams"].items():
        k = f"streams.{n}."
        row = [n, s.get("from", ""), s.get("to", ""), (s.get("solids_measured_tph"), k + "solids_measured_tph"),
               (s.get("solids_tph") if s.get("solids_observable", True) else None, k + "solids_tph"),
               (s.get("solids_sd_tph"), k + "solids_sd_tph")]
        if wet:
            row += [(s.get("water_measured_tph"), k + "water_measured_tph"),
                    (s.get("water_tph") if s.get("water_observable", True) else None, k + "water_tph"),
                    (s.get("water_sd_tph"), k + "water_sd_tph"),
                    (s.get("solids_content_measured_pct"), k + "solids_content_measured_pct"),
                    (s.get("solids_content_pct"), k + "solids_content_pct")]
        row += [(s.get("p80_um"), k + "p80_um"), (s.get("p50_um"), k + "p50_um")]
        rows.append(row)
    return head, rows


def _measurement_rows(summary: dict, only=None) -> list:
    rows = []
    for i, m in enumerate(summary.get("measurements") or []):
        if only is not None and i not in only:
            continue
        k = f"measurements.{i}."
        rows.append([m.get("key", ""), m.get("class", ""), m.get("unit", ""), (m.get("measured"), k + "measured"),
                     (m.get("sd"), k + "sd"), (m.get("adjusted"), k + "adjusted"),
                     (m.get("adjusted_sd"), k + "adjusted_sd"), (m.get("adjustment_in_sd"), k + "adjustment_in_sd"),
                     (m.get("normalised_adjustment"), k + "normalised_adjustment"),
                     "yes" if m.get("redundant") else "no"])
    return rows


MEASUREMENT_HEAD = ["measurement", "class", "unit", "measured", "SD", "adjusted", "adjusted SD",
                    "adjustment in SDs", "normalised adjustment", "redundant"]


def _candidate_rows(summary: dict, which: str) -> list:
    rows = []
    for i, c in enumerate(summary.get(which) or []):
        rows.append([c.get("measurement", ""), (c.get("normalised_adjustment"), f"{which}.{i}.normalised_adjustment")])
    return rows


def balance_report(summary: dict, *, input_text: str | None = None, input_name: str | None = None,
                   command: str = "millflow balance") -> str:
    """The HTML page of a reconciled survey (see the module docstring)."""
    from millflow import __version__

    streams = summary["streams"]
    wet = any("water_tph" in s for s in streams.values())
    sha = summary.get("input_sha256")
    if input_text is not None and not sha:
        sha = hashlib.sha256(input_text.encode("utf-8")).hexdigest()
    meta = [["input file", input_name or summary.get("source_file", "")], ["input SHA-256", sha or "-"],
            ["millflow version", summary.get("millflow_version", __version__)], ["command", command],
            ["method", summary.get("method", "")]]
    sections = [("", table(["", ""], meta, cls="meta"))]

    chi = summary.get("chi_square") or {}
    if chi.get("dof", 0) > 0:
        verdict = ("consistent with the stated errors at 5 %" if chi.get("passed")
                   else "larger than the stated errors allow at 5 % (gross errors, or SDs too small)")
        chi_rows = [["weighted sum of squares (SSR)", (chi.get("ssr"), "chi_square.ssr")],
                    ["degrees of freedom", (chi.get("dof"), "chi_square.dof")],
                    ["measured values", (chi.get("n_measured"), "chi_square.n_measured")],
                    ["chi-square 95 % point", (chi.get("critical_95"), "chi_square.critical_95")],
                    ["p-value", (chi.get("p_value"), "chi_square.p_value")],
                    ["relative balance closure", (summary.get("balance_error"), "balance_error")]]
        line = (f'<p class="chi">Chi-square test: SSR {fmt(chi.get("ssr"))} on {chi.get("dof")} degrees of '
                f'freedom, 95 % point {fmt(chi.get("critical_95"))}, p = {fmt(chi.get("p_value"), 3)}: '
                f"<b>{esc(verdict)}</b>.</p>")
    else:
        chi_rows = [["relative balance closure", (summary.get("balance_error"), "balance_error")]]
        line = '<p class="chi">No redundancy (0 degrees of freedom): nothing to test; every value is as measured.</p>'
    sections.append(("Chi-square test", line + table(["quantity", "value"], chi_rows, cls="chi-square")))

    sections.append(("Flowsheet (adjusted values)", drawing(summary, {n: _label(n, s) for n, s in streams.items()})))
    head, rows = _stream_rows(summary, wet)
    sections.append(("Streams: measured and adjusted", table(head, rows, cls="streams")))

    thr = summary.get("gross_error_threshold")
    cand = _candidate_rows(summary, "gross_error_candidates")
    text = (f"<p>Candidates: |normalised adjustment| &gt; {fmt(thr)} "
            f"({esc(summary.get('gross_error_rule', ''))}).</p>")
    if cand:
        text += table(["measurement", "normalised adjustment"], cand, cls="gross-errors")
    else:
        text += "<p>None.</p>"
    largest = _candidate_rows(summary, "largest_normalised_adjustments")
    if largest:
        text += "<p>Largest normalised adjustments:</p>" + table(["measurement", "normalised adjustment"], largest,
                                                                 cls="largest")
    sections.append(("Gross-error candidates", text))

    cl_rows = []
    for n, c in (summary.get("circulating_load") or {}).items():
        cl_rows.append([n, (c.get("value_pct") if c.get("observable") else None, f"circulating_load.{n}.value_pct"),
                        (c.get("sd_pct"), f"circulating_load.{n}.sd_pct")])
    if cl_rows:
        sections.append(("Circulating load", table(["recycle stream", "circulating load %", "SD %"], cl_rows,
                                                   cls="circulating-load")))

    bad = (summary.get("observability") or {}).get("unobservable") or []
    bad = ", ".join((summary.get("observability") or {}).get("unobservable") or [])
    sections.append(("Not determined by the survey",
                     f"<p>{esc(bad) if bad else 'Nothing: every stream quantity is observable.'}</p>"))
    sections.append(("Measurements: measured, adjusted and the adjustment in SDs",
                     table(MEASUREMENT_HEAD, _measurement_rows(summary), cls="measurements")))

    sieves = summary.get("sieves_um") or []
    psd = [(f"{n} adjusted (P80 {fmt(s.get('p80_um'))} um)", sieves, s.get("passing_adjusted_pct") or [])
           for n, s in streams.items()]
    sections.append(("Adjusted size distributions", line_plot(
        psd, xlabel="sieve size [um]", ylabel="cumulative passing [%]", ylim=(0, 100))))
    if input_text is not None:
        sections.append((f"Input file {input_name or ''}", f"<pre>{esc(input_text)}</pre>"))
    return page(summary.get("title") or summary.get("source_file") or "survey balance", sections, data=summary,
                source="summary.json")


def write_balance_report(path, summary: dict, *, input_path=None, command: str = "millflow balance") -> Path:
    """Write :func:`balance_report` to ``path`` (with the survey file's text when
    ``input_path`` is given); returns the path."""
    text, name = read_input(input_path)
    path = Path(path)
    path.write_text(balance_report(summary, input_text=text, input_name=name, command=command), encoding="utf-8")
    return path
