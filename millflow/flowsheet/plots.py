"""PNG plots of a solved flowsheet (matplotlib through millflow.plotting).

- ``psd.png``: cumulative passing of every stream on a log size axis [um].
- ``classifiers.png``: partition curves of every classifier and mill discharge screen
  (fraction of each size to the coarse stream).
- ``flowsheet.png``: a simple drawing of units (boxes, placed by distance from the
  feeds) and streams (arrows, recycles curved) labelled with solids rates [t/h].
"""
from __future__ import annotations

from collections import deque
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


def _levels(fs) -> dict:
    adj = {u: [] for u in fs.units}
    for s in fs.streams.values():
        adj[s.source].append(s.target)
    level = {}
    q = deque()
    for u, unit in fs.units.items():
        if unit.type == "feed":
            level[u] = 0
            q.append(u)
    while q:
        u = q.popleft()
        for v in adj[u]:
            if v not in level:
                level[v] = level[u] + 1
                q.append(v)
    for u in fs.units:
        level.setdefault(u, 0)
    return level


#: Layers per row of the flowsheet drawing: longer circuits wrap onto further rows.
LAYERS_PER_ROW = 6
_DX, _DY = 3.6, 1.7  # spacing of layers and of units within a layer [data units]


def flowsheet_layout(fs) -> tuple[dict, dict, tuple]:
    """Positions of units (layers by distance from the feeds, wrapped after
    :data:`LAYERS_PER_ROW` layers, alternate rows running back), their layers, and the figure size [in] that keeps
    boxes and labels legible for circuits of 10-20 units."""
    level = _levels(fs)
    per_level = {}
    for u in fs.units:
        per_level.setdefault(level[u], []).append(u)
    depth = max(len(v) for v in per_level.values())
    n_levels = max(level.values()) + 1
    row_height = _DY * depth + 1.8
    pos = {}
    for lv, units in per_level.items():
        row, col = divmod(lv, LAYERS_PER_ROW)
        if row % 2:  # boustrophedon: the next row runs back, so a wrapped loop stays short
            col = LAYERS_PER_ROW - 1 - col
        for k, u in enumerate(units):
            pos[u] = (_DX * col, -row * row_height - _DY * k)
    rows = (n_levels - 1) // LAYERS_PER_ROW + 1
    cols = min(n_levels, LAYERS_PER_ROW)
    size = (max(6.0, 1.9 * cols + 1.5), max(3.5, 1.25 * rows * (depth + 1) + 1.0))
    return pos, level, size


def plot_flowsheet(sol, ax):
    """Boxes for units, arrows for streams with their solids rates [t/h] (recycles in red)."""
    fs = sol.flowsheet
    pos, level, _ = flowsheet_layout(fs)
    for u, (x, y) in pos.items():
        unit = fs.units[u]
        ax.text(x, y, f"{u}\n[{getattr(unit, 'kind', unit.type)}]", ha="center", va="center", fontsize=8,
                bbox=dict(boxstyle="round", fc="#e8f0fa", ec="#3060a0"), zorder=3)
    tot = {n: float(sol.flows[k].sum()) * 3.6 for k, n in enumerate(fs.stream_names)}
    for n, s in fs.streams.items():
        (x0, y0), (x1, y1) = pos[s.source], pos[s.target]
        back = level[s.target] <= level[s.source]
        dist = max(float(np.hypot(x1 - x0, y1 - y0)), 1e-9)
        rad = 0.45 * min(1.0, 2.0 * _DX / dist) if back else 0.0  # arcs about one layer high at most
        if back and (x0, y0) == (x1, y1):
            x1, y1 = x1 + 0.01, y1 - 0.01
        ax.annotate("", xy=(x1, y1), xytext=(x0, y0), zorder=2,
                    arrowprops=dict(arrowstyle="-|>", color="#a03030" if back else "#303030", shrinkA=34,
                                    shrinkB=34, connectionstyle=f"arc3,rad={rad}"))
        # label at the arc's apex (mid + rad/2 (dy, -dx)) or just above a straight arrow
        mx, my = (x0 + x1) / 2 + 0.5 * rad * (y1 - y0), (y0 + y1) / 2 - 0.5 * rad * (x1 - x0)
        my += 0.35 if not back else (0.3 if my >= (y0 + y1) / 2 else -0.3)
        ax.text(mx, my, f"{n}\n{tot[n]:.4g} t/h", ha="center", va="center", fontsize=7, color="#202020",
                bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.8), zorder=4)
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    ax.set_xlim(min(xs) - 1.8, max(xs) + 1.8)
    ax.set_ylim(min(ys) - 0.6 - 0.5 * _DX, max(ys) + 0.6 + 0.5 * _DX)
    ax.set_axis_off()
    ax.set_title(fs.title or "flowsheet", fontsize=10)


#: Axes placement of the 8 x 5 in plots (fractions of the figure): room for the tick
#: labels and axis titles without measuring them (tight_layout would draw twice).
_MARGINS = {"left": 0.085, "right": 0.98, "bottom": 0.11, "top": 0.97}
#: The flowsheet drawing has no axes, only a title: the whole figure but a title band.
_DRAWING_MARGINS = {"left": 0.01, "right": 0.99, "bottom": 0.01, "top": 0.93}


def save_plots(sol, ds, out_dir) -> dict:
    """Write psd.png, classifiers.png (only when the circuit classifies) and flowsheet.png to
    ``out_dir``; returns name -> path."""
    out = Path(out_dir)
    files = {}
    classifies = any(u.type == "classifier" or (u.type == "mill" and u.classification is not None)
                     for u in sol.flowsheet.units.values())
    plots = [("psd_png", "psd.png", plot_psd, ds, (8, 5))]
    if classifies:
        plots.append(("classifiers_png", "classifiers.png", plot_classifiers, sol, (8, 5)))
    plots.append(("flowsheet_png", "flowsheet.png", plot_flowsheet, sol, flowsheet_layout(sol.flowsheet)[2]))
    for key, fname, fun, arg, size in plots:
        fig, ax = figure(figsize=size)
        fun(arg, ax)
        margins = _DRAWING_MARGINS if fun is plot_flowsheet else _MARGINS
        files[key] = save(fig, out / fname, dpi=110, margins=margins)
    return files
