"""Plots and tables of a fit: fitted vs measured cumulative passing (log size), parity plot,
parameter table. matplotlib (through millflow.plotting) is imported only inside the plotting function."""
from __future__ import annotations

import os

import numpy as np

__all__ = ["write_report", "parameter_table"]


def parameter_table(result) -> str:
    """The parameter table as CSV text (name, value, se, se_eq9, se_cluster, t, p_value,
    ci95_low, ci95_high, significant, flags); t and p are empty for ln_X parameters."""
    def g(v, fmt):
        return "" if v is None else format(v, fmt)
    lines = ["name,value,se,se_eq9,se_cluster,t,p_value,ci95_low,ci95_high,significant,flags"]
    for name, s in result.stats["params"].items():
        lines.append(f"{name},{s['value']:.8g},{s['se']:.4g},{g(s.get('se_eq9'), '.4g')},"
                     f"{g(s.get('se_cluster'), '.4g')},{g(s['t'], '.4g')},{g(s['p_value'], '.4g')},"
                     f"{s['ci95'][0]:.6g},{s['ci95'][1]:.6g},{s['significant']},"
                     f"\"{'; '.join(s.get('flags', s['reasons']))}\"")
    for name, par in result.params.items():
        if name not in result.stats["params"]:
            lines.append(f"{name},{par.value:.8g},,,,,,,,,fixed")
    return "\n".join(lines) + "\n"


def write_report(result, out_dir: str, prediction: dict | None = None, plots: bool = True) -> list[str]:
    """Write params.csv, summary.txt and (plots=True) fit_psd.png and parity.png into out_dir."""
    os.makedirs(out_dir, exist_ok=True)
    files = []
    p = os.path.join(out_dir, "params.csv")
    with open(p, "w") as fh:
        fh.write(parameter_table(result))
    files.append(p)
    p = os.path.join(out_dir, "summary.txt")
    with open(p, "w") as fh:
        fh.write(result.summary() + "\n")
        if prediction:
            fh.write(f"prediction (held-out conditions) mean RMSE {prediction['mean_rmse']:.4f}\n")
            for c, v in prediction["rmse"].items():
                fh.write(f"  {c}: {v:.4f}\n")
    files.append(p)
    if plots:
        files += _plots(result, out_dir)
    return files


def _plots(result, out_dir):
    from millflow.plotting import figure, save

    m = result.model
    theta = result.theta
    M = m.predict_grid(theta[None])[0]
    P = np.cumsum(M[:, ::-1], axis=1)[:, ::-1]
    n = len(m.groups)
    cols = min(4, n)
    rows = int(np.ceil(n / cols))
    fig, axes = figure(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False, sharey=True)
    for g, (c, loc, t) in enumerate(m.groups):
        ax = axes.flat[g]
        a, b = m.group_slices[g], m.group_slices[g + 1]
        s = m.sizes[g]
        pos = s > 0
        ax.semilogx(s[pos] * 1e3, m.y_cum[a:b][pos], "o", ms=3, label="measured")
        ax.semilogx(m.x * 1e3, P[g], "-", lw=1, label="model")
        title = m.conditions[c] + (f" t={t:g} s" if m.spec.mode == "batch" else f" {loc}")
        ax.set_title(title, fontsize=7)
        ax.set_xlabel("size [mm]", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].set_ylabel("cumulative passing [-]", fontsize=7)
    axes.flat[0].legend(fontsize=6)
    f1 = os.path.join(out_dir, "fit_psd.png")
    save(fig, f1, dpi=110)
    fig, ax = figure(figsize=(4, 4))
    ax.plot(m.y_cum, m.predict_cum(theta), ".", ms=3)
    ax.plot([0, 1], [0, 1], "k-", lw=0.8)
    ax.set_xlabel("measured cumulative passing [-]")
    ax.set_ylabel("model cumulative passing [-]")
    ax.set_title(f"parity, SER {result.ser:.3g}")
    f2 = os.path.join(out_dir, "parity.png")
    save(fig, f2, dpi=110)
    return [f1, f2]
