"""Issue 15 §1: standard errors under correlated residuals.

Synthetic batch data from a known truth (3 speeds x 3 times x 12 sieves) with noise that
is AR(1) along the sieves of each sample (rho 0.7, sigma 0.01: the knife mill's measured
lag-1 correlation is 0.68). The default intervals (eq. 9 raised to the sample-clustered
sandwich SE where larger, t with G - 1 dof) must cover the truth at least as often as eq. 9
alone, and at 0.85 or more in the long run.
"""
import numpy as np
import pandas as pd
import pytest
from scipy import stats

from millflow.fitting.data import psd_data_from_frames
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
from millflow.fitting.statistics import cluster_robust_covariance
from millflow.grid import SizeGrid

SIEVES_MM = 4.0 * 2 ** (-0.5 * np.arange(12))
TIMES_MIN = [1.0, 3.0, 9.0]
SPEEDS = {"c1": 0.6, "c2": 0.75, "c3": 0.9}
TRUTH = dict(ln_A0=np.log(1 / 3), a_speed=1.5, alpha=1.0, phi=0.4, gamma=0.8, beta=3.5)
SPEC = ModelSpec(mode="batch", breakage="normalized", rate_process=("speed",))
GRID = SizeGrid.between(4e-3, 4e-3 / 2 ** 5.5, 2 ** 0.25)
PROCESS = pd.DataFrame({"condition": list(SPEEDS), "speed": list(SPEEDS.values())})


def _model(values=None):
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "time_min": 0.0, "size_mm": SIEVES_MM[:2],
                          "passing": [1.0, 0.0]})]
    k = 0
    for c in SPEEDS:
        for t in TIMES_MIN:
            p = np.linspace(1, 0, 12) if values is None else values[k:k + 12]
            k += 12
            rows.append(pd.DataFrame({"condition": c, "location": "mill", "time_min": t, "size_mm": SIEVES_MM,
                                      "passing": p}))
    return ForwardModel(SPEC, psd_data_from_frames(pd.concat(rows), PROCESS, strict=False), GRID)


def coverage(replicates: int, seed: int = 1, rho: float = 0.7, sigma: float = 0.01):
    m0 = _model()
    y0 = m0.predict(np.array([TRUTH[n] for n in m0.param_names]))
    rng = np.random.default_rng(seed)
    hits = {n: 0 for n in TRUTH}
    hits9 = {n: 0 for n in TRUTH}
    for _ in range(replicates):
        z = rng.standard_normal((9, 12))
        e = np.empty_like(z)
        e[:, 0] = z[:, 0]
        for k in range(1, 12):
            e[:, k] = rho * e[:, k - 1] + np.sqrt(1 - rho ** 2) * z[:, k]
        m = _model(y0 + sigma * e.ravel())
        res = fit(m, default_parameters(SPEC, {n: {"value": v} for n, v in TRUTH.items()}),
                  global_search=False, starts=1, grid_check=False)
        st = res.stats
        t9 = stats.t.ppf(0.975, st["dof"])
        for n, truth in TRUTH.items():
            s = st["params"][n]
            lo, hi = s["ci95"]
            hits[n] += lo <= truth <= hi
            hits9[n] += abs(s["value"] - truth) <= t9 * s["se_eq9"]
    return {n: hits[n] / replicates for n in TRUTH}, {n: hits9[n] / replicates for n in TRUTH}


def test_cluster_robust_covariance_of_independent_clusters_matches_eq9_in_expectation():
    """With independent residuals the sandwich estimates the same covariance as eq. 9:
    for J = 1 (a mean) it is the CR1 variance of the mean, sum over clusters of (sum r)^2."""
    rng = np.random.default_rng(0)
    r = rng.standard_normal(400)
    ids = np.repeat(np.arange(100), 4)
    C, G = cluster_robust_covariance(np.ones((400, 1)), r, ids, 1)
    by_cluster = np.bincount(ids, r)
    expected = (100 / 99) * (399 / 399) * float(by_cluster @ by_cluster) / 400 ** 2
    assert G == 100 and C[0, 0] == pytest.approx(expected, rel=1e-12)


def test_default_intervals_cover_at_least_as_often_as_eq9():
    cov, cov9 = coverage(40)
    assert all(cov[n] >= cov9[n] for n in TRUTH)  # the default interval contains eq. 9's
    # expected ~0.93 each (measured 0.925-1.0); 0.8 is > 3 binomial SDs below at 40 replicates
    assert min(cov.values()) >= 0.8, cov


@pytest.mark.slow
def test_default_interval_coverage_under_ar1_is_at_least_085():
    cov, cov9 = coverage(200, seed=7)
    assert min(cov.values()) >= 0.85, (cov, cov9)


def test_robust_flag_needs_enough_samples_and_a_ratio_above_one():
    """The flag fires on a ratio > 1.5 from >= 10 samples only: fewer samples cannot support
    it, and a ratio below 1 is no evidence of correlation. The message names the count."""
    from millflow.fitting.statistics import ROBUST_MIN_CLUSTERS, parameter_statistics

    rng = np.random.default_rng(3)

    def stats_for(G, rho):
        n_per = 12
        J = rng.standard_normal((G * n_per, 2))
        r = np.empty((G, n_per))
        z = rng.standard_normal((G, n_per))
        r[:, 0] = z[:, 0]
        for k in range(1, n_per):
            r[:, k] = rho * r[:, k - 1] + np.sqrt(1 - rho ** 2) * z[:, k]
        # the scores J_g^T r_g grow with the within-sample correlation of J and r: give J
        # the same smooth structure so that rho > 0 really inflates the sandwich
        J = J + 3.0 * np.repeat(rng.standard_normal((G, 1, 2)), n_per, axis=1).reshape(-1, 2)
        r = r + 3.0 * rho * rng.standard_normal((G, 1))
        return parameter_statistics(["a", "b"], np.array([1.0, 2.0]), J, float((r ** 2).sum()), r.size,
                                    residuals=r.ravel(), clusters=np.repeat(np.arange(G), n_per))

    few = stats_for(ROBUST_MIN_CLUSTERS - 4, 0.9)
    assert not few["se_ratio_flag"] and not any(few["params"][n]["flags"] for n in "ab")
    many = stats_for(60, 0.9)
    assert many["se_ratio_max"] > 1.5  # strongly correlated within samples: the sandwich is wider
    assert many["se_ratio_flag"]
    assert any("from 60 samples" in f for n in "ab" for f in many["params"][n]["flags"])
    indep = stats_for(60, 0.0)  # independent residuals: ratio ~ 1 (never flagged below 1)
    assert not any("cluster-robust" in f for n in "ab" for f in indep["params"][n]["flags"]
                   if indep["params"][n]["se_cluster"] / indep["params"][n]["se_eq9"] < 1)
