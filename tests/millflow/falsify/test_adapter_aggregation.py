"""The adapter slot for non-linear truths (CallableTruth), exercised with an exact,
self-contained aggregation truth: pure constant-kernel aggregation of monomers.

Smoluchowski's equation with constant kernel K and N0 monomers at t = 0 has the exact
solution n_k(t) = N0 tau^(k-1) / (1 + tau)^(k+1), tau = K N0 t / 2 (Smoluchowski 1917;
e.g. Friedlander, Smoke, Dust and Haze, 2nd ed., ch. 7). The mass fraction of k-mers is
k tau^(k-1) / (1 + tau)^(k+1). Independent reference: the mass-weighted mean volume (the
ratio of the second to the first moment, in monomer volumes) obeys dM2/dt = K M1^2, so it
is exactly 1 + 2 tau.
"""
import numpy as np

from millflow.falsify import CallableTruth, GaussianNoise, batch_design, study
from millflow.fitting import ModelSpec


def _kmer_mass(tau, kmax):
    k = np.arange(1, kmax + 1, dtype=float)
    # in logs: tau^(k-1)/(1+tau)^(k+1) underflows gracefully for large k
    return k, np.exp(np.log(k) + (k - 1) * np.log(tau) - (k + 1) * np.log1p(tau))


def aggregation_truth(grid, K_N0_per_s, d1_m, kmax=200000):
    """A callable (times_s) -> (T, N) mass fractions of k-mers (size d1 k^(1/3)) on ``grid``;
    everything coarser than x_2 is class 1 (the top class lumps the oversize)."""
    x = grid.x
    N = x.size

    def f(times_s):
        out = np.zeros((len(times_s), N))
        for r, t in enumerate(times_s):
            tau = 0.5 * K_N0_per_s * t
            k, m = _kmer_mass(tau, kmax)
            size = d1_m * np.cbrt(k)
            # class i (0-based) holds x[i+1] < size <= x[i]; the sink holds size <= x[N-1]
            cls = np.searchsorted(-x, -size, side="right") - 1  # last class whose upper edge is >= size
            cls = np.clip(cls, 0, N - 1)
            np.add.at(out[r], cls, m)
            out[r, 0] += 1.0 - m.sum()  # k-mers beyond kmax (tail < 1e-12 here): top class
        return out

    return f


def test_constant_kernel_truth_through_the_adapter():
    design = batch_design([30.0, 60.0, 120.0, 240.0], n_sieves=10)
    grid = design.grid
    d1 = float(grid.x[-3])  # monomers two classes above the sink
    f = aggregation_truth(grid, K_N0_per_s=0.05, d1_m=d1)
    tr = CallableTruth(f, {}, name="aggregation_constant")
    M = tr.mass_fractions(design)  # the adapter checks shape, sign and mass balance
    assert M.shape == (4, grid.n)
    # aggregation only coarsens: mass in the finest occupied class falls with time
    assert np.all(np.diff(M[:, -3]) < 0)
    # the closed-form k-mer masses against the moment equation: mass-weighted mean volume
    # = 1 + 2 tau exactly; truncation at kmax leaves a tail below 1e-12 of the mass
    for t in design.times_s:
        tau = 0.5 * 0.05 * t
        k, m = _kmer_mass(tau, 200000)
        assert abs(np.sum(k * m) - (1 + 2 * tau)) <= 1e-9 * (1 + 2 * tau)


def test_a_study_runs_on_a_callable_truth():
    design = batch_design([30.0, 60.0, 120.0, 240.0], n_sieves=8)
    f = aggregation_truth(design.grid, K_N0_per_s=0.002, d1_m=float(design.grid.x[2]))
    # a mill charge that aggregates fitted as first-order breakage: the plumbing runs end to
    # end; failed fits, if any, are counted (n_failed), never dropped
    truth = CallableTruth(f, {}, name="aggregation_constant", strength=0.002)
    res = study(truth, ModelSpec(mode="batch", breakage="single"), design, noise=GaussianNoise(0.01),
                replicates=2, drift_replicates=0)
    ds = res.dataset
    assert ds.attrs["truth"] == "aggregation_constant"
    assert int(ds.n_failed.values[0]) + int(np.isfinite(ds.replicate_r2.values).sum()) == 2
    assert np.all(np.isnan(ds.truth.values))  # the truth shares no breakage parameter
