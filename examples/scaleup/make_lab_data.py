"""Make the SYNTHETIC lab data set of the scale-up example (not measurements).

A 0.2 m x 0.2 m lab ball mill, batch grinding of a 1.4-4 mm feed for 1, 3, 9 and 30 min,
at two speeds (0.65 and 0.80 of critical) so that eq. 10 (A ~ speed^a) is fitted.
The "truth" below is a plausible limestone-like parameter set; the passing values are
millflow's exact batch solution (eq. 4) of the continuous model (class averages on a
2^(1/16) grid: within ~1e-5 of the grid-converged passing) plus Gaussian noise of sd
0.005 on cumulative passing (seed 2026). Run from this folder:

    python make_lab_data.py        # writes lab_psd.csv and lab_process.csv
"""
import math

import numpy as np
import pandas as pd

from millflow.fitting.data import psd_data_from_frames
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.grid import SizeGrid

TRUTH = {"ln_A0": math.log(1 / 240), "a_speed": 1.5, "alpha": 1.1, "phi": 0.45, "gamma": 0.9, "beta": 3.8}
SIEVES_MM = 4.0 * 2 ** (-0.5 * np.arange(14))
SPEEDS = {"lab_065": 0.65, "lab_080": 0.80}
TIMES_MIN = (1.0, 3.0, 9.0, 30.0)
NOISE = 0.005


def tables(rng=None):
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "time_min": 0.0, "size_mm": SIEVES_MM[:4],
                          "passing": [1.0, 2 / 3, 1 / 3, 0.0]})]
    for c in SPEEDS:
        for t in TIMES_MIN:
            rows.append(pd.DataFrame({"condition": c, "location": "mill", "time_min": t, "size_mm": SIEVES_MM,
                                      "passing": np.linspace(1, 0, SIEVES_MM.size)}))
    proc = pd.DataFrame({"condition": list(SPEEDS), "speed": list(SPEEDS.values())})
    spec = ModelSpec(mode="batch", breakage="normalized", rate_process=("speed",))
    grid = SizeGrid.between(4e-3, 4e-3 / 2 ** 7.5, 2 ** (1 / 16))
    model = ForwardModel(spec, psd_data_from_frames(pd.concat(rows), proc), grid)
    y = model.predict(np.array([TRUTH[n] for n in model.param_names]))
    if rng is not None:
        y = y + rng.normal(0.0, NOISE, y.size)
    k = 0
    for r in rows[1:]:
        n = len(r)
        # clip to [0, 1] and keep non-increasing, as a sieve analysis reports
        r["passing"] = np.minimum.accumulate(np.clip(np.round(y[k:k + n], 4), 0.0, 1.0))
        k += n
    return pd.concat(rows), proc


if __name__ == "__main__":
    psd, proc = tables(np.random.default_rng(2026))
    psd.to_csv("lab_psd.csv", index=False)
    proc.to_csv("lab_process.csv", index=False)
    print("wrote lab_psd.csv, lab_process.csv (synthetic)")
