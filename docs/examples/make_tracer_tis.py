"""Write docs/examples/tracer_tis.csv: a synthetic pulse tracer test of a mill.

Three tanks in series, tau = 12 min, tracer area 5.0 (mg/L) min, sampled every minute
from 0 to 60 min, additive Gaussian noise with standard deviation 2 % of the peak,
numpy seed 2024. Run from the repository root: python docs/examples/make_tracer_tis.py
"""
from pathlib import Path

import numpy as np

import rtd

TAU_MIN, N, AREA, SEED = 12.0, 3, 5.0, 2024

t = np.arange(0.0, 61.0, 1.0)
clean = AREA * rtd.TanksInSeries(TAU_MIN, N).pdf(t)
rng = np.random.default_rng(SEED)
c = clean + 0.02 * clean.max() * rng.standard_normal(t.size)
out = Path(__file__).with_name("tracer_tis.csv")
with out.open("w") as fh:
    fh.write(f"# synthetic: TanksInSeries(tau={TAU_MIN} min, n={N}), area {AREA}, "
             f"noise 2 % of peak, seed {SEED} (make_tracer_tis.py)\n")
    fh.write("time_min,concentration\n")
    for ti, ci in zip(t, c):
        fh.write(f"{ti:g},{ci:.6f}\n")
print(f"wrote {out}")
