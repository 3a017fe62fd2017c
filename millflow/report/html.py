"""A self-contained HTML page: tables, SVG line plots, the flowsheet drawing.

No network: styles and the one small script are inline, plots are inline SVG. Every
number shown in a table cell carries ``data-key`` (its path in the summary the page was
made from, e.g. ``streams.overflow.p80_um``) so a reader or a test can map it back. The
page's script records JavaScript errors in ``#js-errors``; on the flowsheet drawing as
the browser lays it out it counts the pairs of boxes (a unit or label box with its text)
that overlap (``data-overlaps`` on ``<body>``) and the lines of text that spill out of
their box (``data-spills``); it marks the page ``data-rendered="ok"`` when every SVG has
a non-empty size and no script failed.

Numbers are shown to :data:`SIG` significant digits (integers above that keep all their
digits: 1287 um, not 1.287e+03).
"""
from __future__ import annotations

import html
import json
import math
import re

from millflow.report.layout import FlowsheetLayout
from millflow.report.textsize import LINE_H, Strong

__all__ = ["SIG", "fmt", "table", "line_plot", "flowsheet_svg", "page", "details", "method_text"]

#: Significant digits of the numbers in a report.
SIG = 4


def fmt(v, sig: int = SIG, *, pct: bool = False) -> str:
    """A number at ``sig`` significant digits ("-" for None or not finite); errors and
    other small numbers in exponent form."""
    if v is None or isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return "-" if not isinstance(v, str) else html.escape(v)
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 10 ** sig:
        return f"{v:.0f}"
    if a < 1e-3:
        return f"{v:.{sig - 1}e}" if sig > 2 else f"{v:.1e}"
    return f"{v:.{sig}g}"


_LONG_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+\.\d{5,}(?:[eE][-+]?\d+)?(?![\w.])"
                          r"|(?<![\w.])[-+]?\d+(?:\.\d+)?[eE][-+]?\d+")


def method_text(text, sig: int = SIG) -> str:
    """A method description with its long numbers at ``sig`` significant digits
    ("tau=393.49708243757686" -> "tau=393.5"); other text as it is."""
    if not isinstance(text, str):
        return "" if text is None else str(text)
    return _LONG_NUMBER.sub(lambda m: fmt(float(m.group(0)), sig), text)


def esc(s) -> str:
    return html.escape(str(s), quote=True)


def table(head: list, rows: list, *, cls: str = "") -> str:
    """An HTML table. ``rows``: lists of cells; a cell is text, a number, or
    ``(value, key[, sig[, scale]])`` for a number with its summary key (shown as
    value * scale, e.g. 1e-3 for Pa shown in kPa; ``data-scale`` says so)."""
    out = [f'<table class="{esc(cls)}"><thead><tr>' + "".join(f"<th>{esc(h)}</th>" for h in head)
           + "</tr></thead><tbody>"]
    for r in rows:
        cells = []
        for c in r:
            if isinstance(c, tuple):
                value, key = c[0], c[1]
                sig = c[2] if len(c) > 2 else SIG
                scale = c[3] if len(c) > 3 else 1.0
                shown = value * scale if isinstance(value, (int, float)) and value is not None else value
                attr = f' data-scale="{scale:g}"' if scale != 1.0 else ""
                cells.append(f'<td class="num" data-key="{esc(key)}"{attr}>{fmt(shown, sig)}</td>')
            elif isinstance(c, (int, float)) and not isinstance(c, bool):
                cells.append(f'<td class="num">{fmt(c)}</td>')
            else:
                cells.append(f"<td>{esc(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
          "#7f7f7f", "#bcbd22"]


def _ticks_log(lo: float, hi: float) -> list[float]:
    out = []
    for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1):
        for m in (1, 2, 5):
            v = m * 10.0 ** e
            if lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9):
                out.append(v)
    return out


def _ticks_lin(lo: float, hi: float, n: int = 5) -> list[float]:
    """Round ticks (1, 2 or 5 times a power of ten apart) covering [lo, hi], about ``n`` of them."""
    raw = (hi - lo) / n
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    first = math.ceil(lo / step - 1e-9)
    return [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def line_plot(series: list, *, xlabel: str, ylabel: str, ylim=None, xlog: bool = True,
              width: int = 760, height: int = 380, title: str = "") -> str:
    """An SVG line plot. ``series``: (label, xs, ys) or (label, xs, ys, style) with style
    ``"line"`` (default), ``"dashed"`` or ``"points"`` (markers only), or a dict with keys
    ``style`` and ``color`` (an index into :data:`COLORS`, to draw several series in one
    colour); a series labelled None has no legend entry. On a log axis (``xlog``) only
    finite positive xs are drawn."""
    items = []
    for item in series:
        lab, xs, ys = item[:3]
        style = item[3] if len(item) > 3 else "line"
        style = style if isinstance(style, dict) else {"style": style}
        p = [(x, y) for x, y in zip(xs, ys) if x is not None and y is not None and math.isfinite(x)
             and math.isfinite(y) and (x > 0 or not xlog)]
        if p:
            items.append((lab, p, style.get("style", "line"), style.get("color", len(items))))
    legend = [it for it in items if it[0] is not None]
    left, right, top, bottom = 64, 220 if legend else 24, 16 + (18 if title else 0), 48
    height = max(height, top + 18 * len(legend) + 8)
    pw, ph = width - left - right, height - top - bottom
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" class="plot" viewBox="0 0 {width} {height}" '
             f'width="{width}" height="{height}" role="img" aria-label="{esc(title or ylabel)}">']
    if title:
        parts.append(f'<text x="{left}" y="16" class="ttl">{esc(title)}</text>')
    if not items:
        parts.append(f'<text x="{width / 2}" y="{height / 2}" text-anchor="middle">no data</text></svg>')
        return "".join(parts)
    xs = [x for _, p, _, _ in items for x, _ in p]
    ys = [y for _, p, _, _ in items for _, y in p]
    x0, x1 = min(xs), max(xs)
    if x1 <= x0:
        x0, x1 = (x0 / 2, x0 * 2) if xlog else (x0 - 0.5 * (abs(x0) or 1), x0 + 0.5 * (abs(x0) or 1))
    if ylim:
        y0, y1 = ylim
    else:
        y0, y1 = min(ys), max(ys)
        pad = 0.05 * (y1 - y0) if y1 > y0 else 0.5 * (abs(y0) or 1)
        y0, y1 = y0 - pad, y1 + pad
        t = _ticks_lin(y0, y1)
        step = t[1] - t[0] if len(t) > 1 else (y1 - y0)
        y0, y1 = step * math.floor(y0 / step), step * math.ceil(y1 / step)  # the axis from tick to tick

    def X(x):
        f = (math.log10(x) - math.log10(x0)) / (math.log10(x1) - math.log10(x0)) if xlog else (x - x0) / (x1 - x0)
        return left + f * pw

    def Y(y):
        return top + (1 - (y - y0) / (y1 - y0)) * ph

    parts.append(f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" class="frame"/>')
    for t in (_ticks_log(x0, x1) if xlog else _ticks_lin(x0, x1)):
        parts.append(f'<line x1="{X(t):.1f}" x2="{X(t):.1f}" y1="{top}" y2="{top + ph}" class="grid"/>'
                     f'<text x="{X(t):.1f}" y="{top + ph + 16}" text-anchor="middle">{fmt(t, 3)}</text>')
    for t in _ticks_lin(y0, y1):
        parts.append(f'<line x1="{left}" x2="{left + pw}" y1="{Y(t):.1f}" y2="{Y(t):.1f}" class="grid"/>'
                     f'<text x="{left - 6}" y="{Y(t) + 4:.1f}" text-anchor="end">{fmt(t, 3)}</text>')
    parts.append(f'<text x="{left + pw / 2}" y="{height - 10}" text-anchor="middle">{esc(xlabel)}</text>'
                 f'<text transform="translate(16 {top + ph / 2}) rotate(-90)" text-anchor="middle">'
                 f'{esc(ylabel)}</text>')
    k_leg = 0
    for lab, p, style, ci in items:
        c = COLORS[ci % len(COLORS)]
        pts = [(X(x), Y(min(max(y, y0), y1))) for x, y in p]
        if style == "points":
            parts.append("".join(f'<circle cx="{a:.1f}" cy="{b:.1f}" r="2.6" fill="{c}"/>' for a, b in pts))
        else:
            dash = ' stroke-dasharray="6 4"' if style == "dashed" else ""
            d = " ".join(f"{a:.1f},{b:.1f}" for a, b in pts)
            parts.append(f'<polyline points="{d}" fill="none" stroke="{c}" stroke-width="1.8"{dash}/>')
        if lab is None:
            continue
        ly = top + 8 + 18 * k_leg
        k_leg += 1
        xl = left + pw + 12
        if style == "points":
            parts.append(f'<circle cx="{xl + 11}" cy="{ly}" r="3" fill="{c}"/>')
        else:
            dash = ' stroke-dasharray="6 4"' if style == "dashed" else ""
            parts.append(f'<line x1="{xl}" x2="{xl + 22}" y1="{ly}" y2="{ly}" stroke="{c}" stroke-width="2.5"{dash}/>')
        parts.append(f'<text x="{xl + 28}" y="{ly + 4}">{esc(lab)}</text>')
    parts.append("</svg>")
    return "".join(parts)


#: Style of the flowsheet drawing (in the page's CSS, and inside a standalone SVG file).
#: Its text asks for DejaVu Sans first: the face the boxes are sized for (:mod:`millflow.report.textsize`).
FLOWSHEET_CSS = (".flowsheet text{font-family:'DejaVu Sans',Verdana,system-ui,sans-serif;font-size:12px;fill:#222}"
                 ".flowsheet .b{font-weight:600}"
                 ".flowsheet .unit rect{fill:#e8f0fa;stroke:#3060a0;stroke-width:1.5}"
                 ".flowsheet .stream{fill:none;stroke:#303030;stroke-width:1.4}.flowsheet .recycle{stroke:#a03030}"
                 ".flowsheet .stream-label rect{fill:#fff;fill-opacity:.92;stroke:#bbb}")


def flowsheet_svg(lay: FlowsheetLayout, unit_text: dict, label_text: dict, *, standalone: bool = False,
                  title: str = "flowsheet") -> str:
    """The flowsheet drawing: unit boxes (``unit_text``: name -> lines), stream routes with
    arrow heads (recycles in red) and label boxes (``label_text``: name -> lines), each box
    with its whole name as a tooltip. ``standalone``: a file of its own (its style inside,
    white background)."""
    w, h = lay.width, lay.height
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" class="flowsheet" viewBox="0 0 {w:.0f} {h:.0f}" '
             f'width="{w:.0f}" height="{h:.0f}" role="img" aria-label="{esc(title)}">']
    if standalone:
        parts.append(f'<style>{FLOWSHEET_CSS}</style><rect width="100%" height="100%" fill="#fff"/>')
    parts.append('<defs><marker id="arr" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" markerHeight="7" '
                 'orient="auto-start-reverse"><path d="M0,0 L10,5 L0,10 z" fill="#303030"/></marker>'
                 '<marker id="arr-r" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" markerHeight="7" '
                 'orient="auto-start-reverse"><path d="M0,0 L10,5 L0,10 z" fill="#a03030"/></marker></defs>')
    for n, route in lay.routes.items():
        red = lay.recycle[n]
        d = " ".join(f"{x:.1f},{y:.1f}" for x, y in route)
        parts.append(f'<polyline class="stream{" recycle" if red else ""}" data-stream="{esc(n)}" points="{d}" '
                     f'marker-end="url(#{"arr-r" if red else "arr"})"/>')
    for u, b in lay.units.items():
        lines = unit_text.get(u, [esc(u)])
        parts.append(f'<g class="unit" data-unit="{esc(u)}"><title>{esc(u)}</title><rect x="{b.x - b.w / 2:.1f}" '
                     f'y="{b.y - b.h / 2:.1f}" width="{b.w:.1f}" height="{b.h:.1f}" rx="6"/>' + _lines(b, lines)
                     + "</g>")
    for n, b in lay.labels.items():
        parts.append(f'<g class="stream-label" data-stream="{esc(n)}"><title>{esc(n)}</title><rect '
                     f'x="{b.x - b.w / 2:.1f}" y="{b.y - b.h / 2:.1f}" width="{b.w:.1f}" height="{b.h:.1f}" rx="3"/>'
                     + _lines(b, label_text.get(n, [esc(n)])) + "</g>")
    parts.append("</svg>")
    return "".join(parts)


def _lines(b, lines) -> str:
    y0 = b.y - LINE_H / 2 * (len(lines) - 1) + 4
    out = []
    for k, line in enumerate(lines):
        text, key = (line if isinstance(line, tuple) else (line, None))
        attr = f' data-key="{esc(key)}"' if key else ""
        cls = ' class="b"' if k == 0 or isinstance(text, Strong) else ""
        out.append(f'<text x="{b.x:.1f}" y="{y0 + LINE_H * k:.1f}" text-anchor="middle"{cls}{attr}>{text}</text>')
    return "".join(out)


def finite(d):
    """A JSON-ready copy: non-finite floats as None (the page embeds strict JSON), numpy
    scalars as Python numbers."""
    if isinstance(d, dict):
        return {str(k): finite(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [finite(v) for v in d]
    if isinstance(d, float):
        return d if math.isfinite(d) else None
    if hasattr(d, "item") and not isinstance(d, (str, bytes)):
        try:
            return finite(d.item())
        except (ValueError, TypeError):
            return str(d)
    return d


CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:1.5em auto;max-width:1500px;
padding:0 1em;color:#222}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.15em;border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}th,td{border:1px solid #ccc;padding:2px 6px}
th{background:#eef2f7;text-align:left}td.num{text-align:right;font-variant-numeric:tabular-nums}
.meta td:first-child{font-weight:600}
svg{max-width:100%;height:auto;font-size:12px}svg text{fill:#222}svg .ttl{font-weight:600}
svg .b{font-weight:600}svg .frame{fill:none;stroke:#888}svg .grid{stroke:#e4e4e4}
""" + FLOWSHEET_CSS + """
pre{background:#f6f6f6;padding:.6em;overflow:auto;font-size:.8em}
.warn{color:#a03030}#js-errors:empty{display:none}
@media print{body{max-width:none}h2{page-break-after:avoid}}
"""

SCRIPT = """
(function(){
var errs=[];function rec(m){errs.push(m);var e=document.getElementById('js-errors');
if(e){e.textContent=errs.join('\\n');}}
window.addEventListener('error',function(ev){rec('error: '+ev.message);});
function hit(a,b){return a.x<b.x+b.width&&b.x<a.x+a.width&&a.y<b.y+b.height&&b.y<a.y+a.height;}
function inside(t,r){return t.x>=r.x-0.5&&t.y>=r.y-0.5&&t.x+t.width<=r.x+r.width+0.5&&t.y+t.height<=r.y+r.height+0.5;}
window.addEventListener('load',function(){
 var ok=true;document.querySelectorAll('svg').forEach(function(s){var r=s.getBoundingClientRect();
  if(!(r.width>0&&r.height>0)){ok=false;rec('empty svg');}});
 var n=0,spill=0;document.querySelectorAll('svg.flowsheet').forEach(function(svg){var gs=[];
  svg.querySelectorAll('g.unit, g.stream-label').forEach(function(g){var r=g.querySelector('rect').getBBox();
   var bs=[r];g.querySelectorAll('text').forEach(function(t){var b=t.getBBox();bs.push(b);
    if(!inside(b,r)){spill++;}});gs.push(bs);});
  for(var i=0;i<gs.length;i++){for(var j=i+1;j<gs.length;j++){var o=false;
   gs[i].forEach(function(a){gs[j].forEach(function(b){if(hit(a,b)){o=true;}});});if(o){n++;}}}});
 document.body.setAttribute('data-overlaps',String(n));
 document.body.setAttribute('data-spills',String(spill));
 document.body.setAttribute('data-rendered',ok&&errs.length===0?'ok':'failed');
});})();
"""


def page(title: str, sections: list, *, data: dict | None = None, source: str | None = None) -> str:
    """The whole page. ``sections``: (heading, html) pairs; ``data``: embedded as JSON in
    ``<script type="application/json" id="summary">`` (the numbers the page shows: every
    ``data-key`` is a path into it); ``source``: the file of the folder that ``data`` is
    (``summary.json``, ``compare.json`` ...), named on the page (``data-source``)."""
    body = [f"<h1>{esc(title)}</h1>", '<pre id="js-errors" class="warn"></pre>']
    if source:
        body.append(f'<p class="source">Every number on this page is one of <code>{esc(source)}</code> '
                    "(in this folder, and embedded at the end of the page), shown to 4 significant digits.</p>")
    for heading, content in sections:
        body.append(f"<h2>{esc(heading)}</h2>{content}" if heading else content)
    blob = ""
    if data is not None:
        text = json.dumps(finite(data), allow_nan=False).replace("</", "<\\/")
        src = f' data-source="{esc(source)}"' if source else ""
        blob = f'<script type="application/json" id="summary"{src}>{text}</script>'
    src = f' data-source="{esc(source)}"' if source else ""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{esc(title)}</title>"
            f"<style>{CSS}</style><script>{SCRIPT}</script></head><body{src}>" + "".join(body) + blob
            + "</body></html>\n")


def details(summary: str, content: str) -> str:
    """A section shown folded (an input file's text)."""
    return f"<details><summary>{esc(summary)}</summary>{content}</details>"


def read_input(input_path) -> tuple[str | None, str | None]:
    """(text, file name) of the input file a report shows, or (None, None) when there is
    none or it cannot be read as UTF-8 text (the report then says so instead of failing)."""
    if input_path is None:
        return None, None
    from pathlib import Path

    try:
        return Path(input_path).read_text(encoding="utf-8"), Path(input_path).name
    except (OSError, UnicodeDecodeError):
        return None, None
