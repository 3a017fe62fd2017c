"""Run the two non-linear worked studies of docs/model-error.md and write their plots and
summaries (docs/images/falsify_aggregation.png, falsify_population.png; the summaries as
JSON beside this script), and the micromixing figure docs/images/micromixing.png.

    python examples/model_error/make_studies.py [--quick] [aggregation] [population] [micromixing]

With no names, all three. --quick runs 5 replicates per strength (a smoke run; the docs
quote the full 50) and writes into --out DIR (default ``make_studies-quick/`` in the
current folder), never over the committed figures and summaries; --out DIR sends a full
run elsewhere too.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(REPO))

from millflow.falsify.config import load_config  # noqa: E402
from millflow.falsify.plots import plot_sweep  # noqa: E402


def studies(quick: bool, names, images: Path, summaries: Path):
    for name in names:
        cfg = load_config(REPO / "docs" / "examples" / "falsify" / f"{name}.toml")
        if quick:
            cfg.replicates, cfg.drift_replicates = 5, 2
        res = cfg.run(progress=lambda m, name=name: print(f"[{name}] {m}", file=sys.stderr, flush=True))
        plot_sweep(res.dataset, images / f"falsify_{name}.png")
        (summaries / f"{name}_summary.json").write_text(json.dumps(res.summary(), indent=2) + "\n", encoding="utf-8")
        print(res.text())


def micromixing(images: Path):
    """Product of a mill with aggregation + cushioning, 3 tanks RTD: the two micromixing
    limits against the perfectly mixed and linear answers."""
    import rtd
    from millflow.breakage import b_from_B, normalized_B, power_law_rates
    from millflow.grid import SizeGrid
    from millflow.mill import nonlinear as nl
    from millflow.nonlinear import Aggregation, constant_kernel, kinetics
    from millflow.plotting import figure, save
    from millflow.psd import cum_passing

    n, tau = 60, 600.0
    grid = SizeGrid.geometric(4e-3, 2 ** 0.25, n)
    S = power_law_rates(grid.x, 1 / 60, 1.0, 1e-3)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.5))
    feed = np.zeros(n)
    feed[:4] = [0.1, 0.3, 0.4, 0.2]
    w = np.zeros((n, n))
    w[:, grid.x <= 2.5e-4] = 1.0
    kin = kinetics(S, b, w=w, lam=-2.0, aggregation=Aggregation(constant_kernel(3e-4), grid.x[-1]), grid=grid)
    lin = kinetics(S, b)
    model = rtd.TanksInSeries(tau, 3)
    mm = nl.micromixing_limits(kin, feed, model)
    ml = nl.micromixing_limits(lin, feed, model)
    fig, ax = figure(1, 1, figsize=(6, 4))
    x_um = grid.x * 1e6
    for p, lab, st in ((ml.segregated, "first order (limits coincide)", "k-"),
                       (mm.segregated, "non-linear, complete segregation", "C0-"),
                       (mm.max_mixedness, "non-linear, maximum mixedness", "C1--")):
        ax.semilogx(x_um, cum_passing(p), st, label=lab)
    ax.set_xlabel("size [um]")
    ax.set_ylabel("cumulative passing")
    ax.set_title(f"3 tanks, tau 10 min: micromixing spread {mm.spread:.3f}", fontsize=10)
    ax.legend(fontsize=8)
    save(fig, images / "micromixing.png", dpi=80)
    print(f"micromixing: spread {mm.spread:.4f}, error estimate {mm.error_estimate:.1e}, {mm.runtime_s:.2f} s")


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", choices=["aggregation", "population", "micromixing"], default=[])
    p.add_argument("--quick", action="store_true", help="5 replicates per strength (a smoke run)")
    p.add_argument("--out", default=None, help="folder for figures and summaries (default: the committed "
                                               "ones for a full run, make_studies-quick/ for --quick)")
    args = p.parse_args(argv)
    out = args.out or ("make_studies-quick" if args.quick else None)
    if out is None:  # a full run refreshes the committed figures and summaries
        images, summaries = REPO / "docs" / "images", HERE
    else:  # a smoke run never overwrites tracked files
        images = summaries = Path(out).resolve()
        images.mkdir(parents=True, exist_ok=True)
    chosen = args.names or ["micromixing", "aggregation", "population"]
    if "micromixing" in chosen:
        micromixing(images)
    studies(args.quick, [n for n in chosen if n != "micromixing"], images, summaries)
    print(f"written to {images}" + ("" if summaries == images else f" and {summaries}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
