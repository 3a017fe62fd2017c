"""PNG plots of a solved flowsheet.

- ``psd.png``: cumulative passing of every stream on a log size axis [um].
- ``classifiers.png``: partition curves of every classifier and mill discharge screen
  (fraction of each size to the coarse stream).
- ``flowsheet.png``: the drawing of report.html (:mod:`millflow.report.layout`): units
  placed by distance from the feeds, streams labelled with solids and water t/h, % solids
  and P80, recycles routed below their row.

:func:`save_plots` writes them as report.html draws them (its SVG line plots and
flowsheet drawing, rasterised by :mod:`millflow.report.raster`: Pillow, a few
hundredths of a second), or with matplotlib where Pillow has no FreeType. The
``plot_*`` functions draw the same plots on a matplotlib axis, for a user's own figure.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from millflow.plotting import figure, save

__all__ = ["save_plots", "plot_psd", "plot_classifiers", "plot_flowsheet"]


def plot_psd(ds, ax):
    """Cumulative passing [%] of every stream against size [um] (log axis)."""
    x = ds["size"].values * 1e6
    for s in ds["stream"].values:
        y = ds["cum_passing"].sel(stream=s).values * 100
        if np.all(np.isnan(y)):
            continue
        ax.semilogx(x, y, marker=".", ms=3, label=f"{s} ({float(ds['solids'].sel(stream=s)) * 3.6:.4g} t/h)")
    ax.set_xlabel("size [um] (upper class edge)")
    ax.set_ylabel("cumulative passing [%]")
    ax.set_ylim(0, 100)
    _plain_log_ticks(ax)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8)


def _plain_log_ticks(ax) -> None:
    """Size ticks as plain numbers (10, 100, 1000) and no minor grid: mathtext labels
    (10^2) and a minor grid line per tick are most of a log plot's drawing time."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def plot_classifiers(sol, ax):
    """Partition curves (fraction to the coarse stream) of classifiers and mill discharge screens."""
    fs = sol.flowsheet
    x = fs.grid.x * 1e6
    n = 0
    for name, unit in fs.units.items():
        c = None
        if unit.type == "classifier":
            c = np.asarray(sol.unit_blocks[name][unit.ports[0]], float)  # the curve the solve used
            label = f"{name} ({unit.kind}, {unit.curve}) to {unit.ports[0]}"
        elif unit.type == "mill" and unit.classification is not None:
            c = unit.discharge_efficiency(fs.grid)
            label = f"{name} discharge ({unit.classification['curve']}), retained"
        if c is not None:
            ax.semilogx(x, c, label=label)
            n += 1
    if not n:
        ax.text(0.5, 0.5, "no classifiers in this flowsheet", ha="center", transform=ax.transAxes)
    ax.set_xlabel("size [um]")
    ax.set_ylabel("fraction to coarse stream [-]")
    ax.set_ylim(-0.02, 1.02)
    _plain_log_ticks(ax)
    ax.grid(True, which="major", alpha=0.3)
    if n:
        ax.legend(fontsize=8)


def _flowsheet_labels(sol, ds=None):
    """Stream label lines (solids t/h; water t/h and % solids when wet; P80 um), as
    report.html shows them; from ``ds`` (:func:`~millflow.flowsheet.results.to_dataset`)
    when given, else from the solution's flows."""
    from millflow.errors import GridError
    from millflow.psd import percentile_size
    from millflow.report.flowsheet import stream_label

    fs = sol.flowsheet
    wet = sol.water is not None and bool(np.any(sol.water.flows > 0))
    out = {}
    for k, n in enumerate(fs.stream_names):
        if ds is not None:
            s = {"solids_tph": float(ds["solids"].sel(stream=n)) * 3.6, "p80_um": float(ds["p80"].sel(stream=n)) * 1e6}
        else:
            f = np.maximum(np.asarray(sol.flows[k], float), 0.0)
            try:
                p80 = percentile_size(fs.grid, f / f.sum(), 80) * 1e6 if f.sum() > 0 else float("nan")
            except GridError:
                p80 = float("nan")
            s = {"solids_tph": float(sol.flows[k].sum()) * 3.6, "p80_um": p80}
        if wet:
            water = float(sol.water_flow(n)) * 3.6
            total = s["solids_tph"] + water
            s.update(water_tph=water, solids_content_pct=100 * s["solids_tph"] / total if total > 0 else float("nan"))
        out[n] = stream_label(n, s)
    return out


def flowsheet_drawing(sol, ds=None):
    """The layout (:mod:`millflow.report.layout`) and label lines of the flowsheet drawing."""
    from millflow.report.layout import layout

    fs = sol.flowsheet
    labels = _flowsheet_labels(sol, ds)
    lay = layout({u: x.type for u, x in fs.units.items()}, {n: (s.source, s.target) for n, s in fs.streams.items()},
                 label_text=labels)
    return lay, labels


#: Pixels of the layout per inch of flowsheet.png (labels then print at 8 pt on 15 px lines).
PX_PER_IN = 100.0


def plot_flowsheet(sol, ax, ds=None):
    """Boxes for units, arrows for streams (recycles in red, routed below their row) and one
    label per stream: solids t/h, water t/h and % solids (wet circuits), P80 [um]; the
    layout of report.html's drawing."""
    import html

    fs = sol.flowsheet
    lay, labels = flowsheet_drawing(sol, ds)
    for u, b in lay.units.items():
        unit = fs.units[u]
        ax.add_patch(_rect(b, fc="#e8f0fa", ec="#3060a0"))
        ax.text(b.x, b.y, f"{u}\n{getattr(unit, 'kind', unit.type)}", ha="center", va="center", fontsize=8,
                zorder=3)
    for n, route in lay.routes.items():
        color = "#a03030" if lay.recycle[n] else "#303030"
        xs, ys = zip(*route)
        ax.plot(xs, ys, color=color, lw=1.2, zorder=1)
        ax.annotate("", xy=route[-1], xytext=route[-2], zorder=2,
                    arrowprops=dict(arrowstyle="-|>", color=color, lw=1.2, shrinkA=0, shrinkB=0))
    for n, b in lay.labels.items():
        ax.add_patch(_rect(b, fc="white", ec="#bbbbbb", alpha=0.92, zorder=4))
        ax.text(b.x, b.y, "\n".join(html.unescape(t) for t in labels[n]), ha="center", va="center", fontsize=7.5,
                linespacing=1.25, zorder=5)
    ax.set_xlim(0, lay.width)
    ax.set_ylim(lay.height, 0)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(fs.title or "flowsheet", fontsize=10)


def _rect(b, **kw):
    from matplotlib.patches import FancyBboxPatch

    kw.setdefault("zorder", 2)
    return FancyBboxPatch((b.x - b.w / 2, b.y - b.h / 2), b.w, b.h, boxstyle="round,pad=0,rounding_size=5", **kw)


def flowsheet_figsize(sol, ds=None) -> tuple:
    """flowsheet.png's size [in]: the layout at :data:`PX_PER_IN`, plus room for the title."""
    lay, _ = flowsheet_drawing(sol, ds)
    return lay.width / PX_PER_IN, lay.height / PX_PER_IN + 0.4


#: Axes placement of the 8 x 5 in plots (fractions of the figure): room for the tick
#: labels and axis titles without measuring them (tight_layout would draw twice).
_MARGINS = {"left": 0.085, "right": 0.98, "bottom": 0.11, "top": 0.97}
#: The flowsheet drawing has no axes, only a title: the whole figure but a title band.
_DRAWING_MARGINS = {"left": 0.01, "right": 0.99, "bottom": 0.01, "top": 0.93}


def save_plots(sol, ds, out_dir) -> dict:
    """Write psd.png, classifiers.png (only when the circuit classifies) and flowsheet.png to
    ``out_dir``; returns name -> path."""
    from millflow.report import raster

    if raster.available():
        return _save_raster(sol, ds, Path(out_dir))
    return _save_matplotlib(sol, ds, Path(out_dir))


def _classifies(sol) -> bool:
    return any(u.type == "classifier" or (u.type == "mill" and u.classification is not None)
               for u in sol.flowsheet.units.values())


def _save_raster(sol, ds, out: Path) -> dict:
    """The plots as report.html's SVG drawings, rasterised."""
    import html

    from millflow.report.html import esc, flowsheet_svg, line_plot
    from millflow.report.raster import svg_to_png

    files = {}
    x = ds["size"].values * 1e6
    series = []
    for k, s in enumerate(ds["stream"].values):
        y = ds["cum_passing"].values[k] * 100
        if not np.all(np.isnan(y)):
            series.append((f"{s} ({float(ds['solids'].values[k]) * 3.6:.4g} t/h)", x.tolist(), y.tolist()))
    svg = line_plot(series, xlabel="size [um] (upper class edge)", ylabel="cumulative passing [%]", ylim=(0, 100))
    files["psd_png"] = out / "psd.png"
    svg_to_png(svg, files["psd_png"])
    if _classifies(sol):
        from millflow.report.flowsheet import partition_curves

        curves = [(label, xs, ys) for label, (xs, ys) in partition_curves(sol).items()]  # report.html's
        svg = line_plot(curves, xlabel="size [um]", ylabel="fraction to coarse stream [-]", ylim=(0, 1))
        files["classifiers_png"] = out / "classifiers.png"
        svg_to_png(svg, files["classifiers_png"])
    lay, labels = flowsheet_drawing(sol, ds)
    units = {u: [esc(u), esc(getattr(unit, "kind", unit.type))] for u, unit in sol.flowsheet.units.items()}
    svg = flowsheet_svg(lay, units, {n: [html.escape(html.unescape(t)) for t in lines] for n, lines in labels.items()})
    # a title band above the drawing, as flowsheet.png always had
    band = 26
    svg = svg.replace(f'viewBox="0 0 {lay.width:.0f} {lay.height:.0f}"',
                      f'viewBox="0 {-band} {lay.width:.0f} {lay.height + band:.0f}"', 1)
    svg = svg.replace("</defs>", f'</defs><text x="{lay.width / 2:.1f}" y="{-band / 2 + 4:.1f}" text-anchor="middle" '
                      f'class="ttl">{esc(sol.flowsheet.title or "flowsheet")}</text>', 1)
    files["flowsheet_png"] = out / "flowsheet.png"
    svg_to_png(svg, files["flowsheet_png"], scale=PX_PER_IN / 100.0 * 1.1)
    return files


def _save_matplotlib(sol, ds, out: Path) -> dict:
    """The plots with matplotlib (where Pillow has no FreeType)."""
    files = {}
    plots = [("psd_png", "psd.png", plot_psd, ds, (8, 5))]
    if _classifies(sol):
        plots.append(("classifiers_png", "classifiers.png", plot_classifiers, sol, (8, 5)))
    plots.append(("flowsheet_png", "flowsheet.png", lambda s, ax: plot_flowsheet(s, ax, ds), sol,
                  flowsheet_figsize(sol, ds)))
    for key, fname, fun, arg, size in plots:
        fig, ax = figure(figsize=size)
        fun(arg, ax)
        margins = _DRAWING_MARGINS if key == "flowsheet_png" else _MARGINS
        files[key] = save(fig, out / fname, dpi=110, margins=margins)
    return files
