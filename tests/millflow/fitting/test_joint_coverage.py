"""Coverage of the 95 % intervals of a joint tracer + multi-location fit (an axial-dispersion
mill with a screen, sieve curves at the product, the hold-up and three axial positions, and a
tracer F(t)), over 40 noisy replicates of a known truth.

Two causes made the intervals of the transport parameters too narrow (coverage ln_tau 0.82,
ln_Pe 0.80; SD of their z-scores 1.55 and 5.2): one pooled SER in eq. 9 gave the tracer rows
(SD 0.01) the sieves' noise (SD 0.005), and a finite-difference step for exact solves stepped
across the axial finite volumes' grid switches (one replicate: SE(ln Pe) 0.0018 against ~0.03,
z = +31). The tracer and sieve rows are now weighted by their own variance
(:func:`millflow.fitting.estimate._variance_components`) and the Jacobian steps over the mill's
noise (:func:`millflow.fitting.estimate.prediction_noise`)."""
import math

import numpy as np
import pandas as pd
import pytest

from millflow.fitting.data import psd_data_from_frames
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
from millflow.grid import SizeGrid

TRUTH = {"ln_A0": math.log(4e-3), "alpha": 1.0, "phi": 0.5, "gamma": 0.9, "beta": 4.0,
         "ln_c50": math.log(0.6), "ln_sharp": math.log(4.0), "ln_tau": math.log(600.0), "ln_pe": math.log(5.0)}
START = {"ln_A0": math.log(3e-3), "alpha": 1.2, "phi": 0.4, "gamma": 1.1, "beta": 3.2,
         "ln_c50": math.log(0.8), "ln_sharp": math.log(3.0), "ln_tau": math.log(450.0), "ln_pe": math.log(3.0)}
BOUNDS = {"ln_A0": (-9.0, -2.0), "ln_c50": (-2.0, 1.0), "ln_sharp": (0.0, 3.0), "ln_tau": (5.0, 8.0),
          "ln_pe": (-2.0, 6.0), "beta": (2.2, 8.0), "gamma": (0.3, 2.0)}
LOCATIONS = ("product", "holdup", "z:0.25", "z:0.5", "z:0.75")


def _replicate(seed, psd_noise=0.005, tracer_noise=0.01):
    grid = SizeGrid.geometric(8e-3, 2 ** 0.5, 18)
    x = grid.x
    feed = pd.DataFrame({"condition": "run1", "location": "feed", "size_m": x,
                         "passing": np.clip((x / x[0]) ** 1.5, 0, 1)})
    process = pd.DataFrame({"condition": ["run1"], "screen_mm": [2.0]})
    times = np.linspace(0.0, 3000.0, 26)[1:]
    spec = ModelSpec(mode="mill", transport="axial_dispersion", transport_params={}, transport_fit=("tau", "pe"),
                     classification="screen")

    def build(values, F):
        rows = [feed] + [pd.DataFrame({"condition": "run1", "location": loc, "size_m": x, "passing": values[loc]})
                         for loc in LOCATIONS]
        return ForwardModel(spec, psd_data_from_frames(pd.concat(rows, ignore_index=True), process, strict=False),
                            grid, tracer=pd.DataFrame({"condition": "run1", "time_s": times, "F": F}))

    shape = build({loc: np.linspace(1, 0, x.size) for loc in LOCATIONS}, np.zeros(times.size))
    clean = shape.predict(np.array([TRUTH[n] for n in shape.param_names]))
    rng = np.random.default_rng(seed)
    noisy = clean + np.where(shape.data_kind == "tracer", tracer_noise, psd_noise) * rng.standard_normal(clean.size)
    s = shape.group_slices
    model = build({loc: noisy[s[g]:s[g + 1]] for g, (_, loc, _) in enumerate(shape.groups)},
                  noisy[shape.data_kind == "tracer"])
    over = {n: {"value": START[n], **({"min": BOUNDS[n][0], "max": BOUNDS[n][1]} if n in BOUNDS else {})}
            for n in model.param_names}
    return model, default_parameters(spec, over)


@pytest.mark.slow  # 40 fits of 9 parameters: ~80 s alone
def test_joint_tracer_and_profile_fit_intervals_cover():
    hits, z = {}, {}
    for seed in range(40):
        model, params = _replicate(seed)
        res = fit(model, params, global_search=False, starts=1, grid_check=False, quiet=True)
        for name, st in res.stats["params"].items():
            lo, hi = st["ci95"]
            hits.setdefault(name, []).append(lo <= TRUTH[name] <= hi)
            z.setdefault(name, []).append((st["value"] - TRUTH[name]) / st["se"])
        assert "variance_components" in res.stats
    coverage = {n: float(np.mean(v)) for n, v in hits.items()}
    # 95 % intervals over 40 replicates: the binomial SD of the coverage is 0.034, so 0.85 is
    # three SDs below nominal; measured (docs/reliability.md) ln_tau 0.97, ln_pe 1.00, all >= 0.93
    assert min(coverage.values()) >= 0.85, coverage
    for name in ("ln_tau", "ln_pe"):
        assert np.std(z[name], ddof=1) < 1.5, (name, np.std(z[name], ddof=1))  # was 1.55 and 5.2
