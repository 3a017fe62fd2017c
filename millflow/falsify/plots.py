"""Plots of a falsification study: bias (in SE and percent) and coverage against strength."""
from __future__ import annotations

import numpy as np

from millflow.plotting import figure, save

__all__ = ["plot_sweep"]


def plot_sweep(ds, path, title: str | None = None):
    """Three panels against the strength of the model error: bias in reported SE, bias in
    percent, coverage of the reported 95 % intervals (nominal 0.95 dashed). Parameters the
    truth does not have are left out."""
    fig, axes = figure(1, 3, figsize=(12, 3.8))
    s = ds.strength.values
    for p in ds.parameter.values:
        if not np.isfinite(ds.truth.sel(parameter=p).values).any():
            continue
        for ax, var in zip(axes, ("bias_se", "bias_pct", "coverage")):
            ax.plot(s, ds[var].sel(parameter=p).values, "o-", ms=4, label=str(p))
    axes[0].set_ylabel("bias / reported SE")
    axes[1].set_ylabel("bias [%] (of X for ln_X)")
    axes[2].set_ylabel("coverage of 95 % intervals")
    axes[2].axhline(0.95, color="k", ls="--", lw=0.8)
    axes[2].set_ylim(-0.02, 1.02)
    for ax in axes:
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xlabel(f"strength ({ds.attrs.get('truth', '')})")
    axes[0].legend(fontsize=8)
    fig.suptitle(title or f"truth {ds.attrs.get('truth')} fitted as {ds.attrs.get('assumed')}", fontsize=10)
    return save(fig, path, dpi=80)
