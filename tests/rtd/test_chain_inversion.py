"""Long chains of cells (issue 10 §2: fit-rtd --cells 1000 took 131 s). A tridiagonal
network from 64 cells up is inverted from its exact transform (O(n) per frequency,
Fourier inversion on Re s = 0) when the eigen route is ill-conditioned, and from 160
cells always. References: the expm route of the same network, and scipy's
expm_multiply (Al-Mohy and Higham), an independent algorithm. Tolerances: the
inversion's aliasing is below e^-45 and its truncation below 1e-17 of the transform, so
1e-11 of the peak leaves room for the rounding of ~10^4 Fourier terms."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import expm_multiply

import rtd
from rtd.compartments import CompartmentNetwork

T = np.linspace(0.0, 40.0, 81)


def _expm_route(model):
    """A new network equal to the model's (networks are cached), held to the old route."""
    net = model.network()
    ref = CompartmentNetwork(net.volumes, net.flows, net.inlet, net.outlet, net.bypass)
    object.__setattr__(ref, "CHAIN_MIN_CELLS", 10 ** 9)  # this instance only
    return ref


@pytest.mark.parametrize("n, r, bypass", [(64, 0.5, 0.0), (100, 0.05, 0.1), (200, 0.3, 0.0)])
def test_chain_agrees_with_the_expm_route(n, r, bypass):
    m = rtd.RecirculatingCells(6.0, n, r, bypass=bypass)
    ref = _expm_route(m)
    assert m.network()._chain() and not ref._chain()
    e, e_ref = m.pdf(T), ref.pdf(T)
    np.testing.assert_allclose(e, e_ref, rtol=0, atol=1e-11 * e_ref.max())
    np.testing.assert_allclose(m.cdf(T), ref.cdf(T), rtol=0, atol=1e-11)


@pytest.mark.parametrize("r", [0.1, 0.5])
def test_thousand_cells_against_expm_multiply(r):
    net = rtd.RecirculatingCells(6.0, 1000, r).network()
    Y = expm_multiply(sp.csr_matrix(net.system_matrix()), net.inlet.astype(float), start=0.0, stop=40.0, num=81,
                      endpoint=True)
    e_ref = Y @ net._w()
    np.testing.assert_allclose(net.pdf(T), e_ref, rtol=0, atol=1e-11 * e_ref.max())


def test_chain_transform_is_the_dense_solve():
    net = rtd.RecirculatingCells(6.0, 80, 0.4).network()
    s = np.array([0.05, 0.3 + 2j, 5.0 - 1j])
    a = net.system_matrix()
    dense = [net._w() @ np.linalg.solve(x * np.eye(net.n) - a, net.inlet) for x in s]
    np.testing.assert_allclose(net.laplace(s), dense, rtol=1e-12)


def test_edge_is_the_largest_eigenvalue():
    """The chain's eigenvalues are real (A is similar to a symmetric tridiagonal matrix);
    numpy's dense eig of such a non-normal A (70 cells) was off by ~0.5 with imaginary parts
    ~4; the tridiagonal route agrees with a 30-digit eig (24 cells here: fast)."""
    import mpmath as mp

    net = rtd.RecirculatingCells(6.0, 24, 0.2).network()
    with mp.workdps(30):
        ev = mp.eig(mp.matrix(net.system_matrix().tolist()), left=False, right=False)
        ref = max(float(mp.re(e)) for e in ev)
    assert net.analytic_for_re_s_greater_than == pytest.approx(ref, rel=1e-12)


def test_non_chain_networks_keep_their_route():
    net = CompartmentNetwork.cells_in_series(np.full(3, 1.0), 1.5, 0.5)
    assert not net._chain()


def test_chain_with_a_side_outlet_uses_the_full_sweep():
    """Exits from two cells: the backward sweep of the Thomas algorithm is needed too."""
    n, B = 70, 0.2
    flows = np.zeros((n, n))
    F = np.where(np.arange(n - 1) < 34, 1.0 + B, 0.7)
    flows[np.arange(1, n), np.arange(n - 1)] = F
    flows[np.arange(n - 1), np.arange(1, n)] = B
    outlet = np.zeros(n)
    outlet[34], outlet[-1] = 0.5, 0.5
    net = CompartmentNetwork(np.full(n, 1.0 / n), flows, np.eye(n)[0], outlet)
    ref = CompartmentNetwork(net.volumes, net.flows, net.inlet, net.outlet)
    object.__setattr__(ref, "CHAIN_MIN_CELLS", 10 ** 9)
    object.__setattr__(net, "CHAIN_ALWAYS_CELLS", 64)  # this instance: the chain route whatever its modes
    assert net._chain() and not ref._chain()
    t = np.linspace(0.0, 4.0, 41)
    np.testing.assert_allclose(net.pdf(t), ref.pdf(t), rtol=0, atol=1e-11 * ref.pdf(t).max())
    s = np.array([0.5, 1.0 + 3j])
    dense = [net._w() @ np.linalg.solve(x * np.eye(n) - net.system_matrix(), net.inlet) for x in s]
    np.testing.assert_allclose(net._resolvent(s), dense, rtol=1e-12)
