"""The finite-volume operator of axial dispersion (millflow.mill.finite_volume): the fitted
fluxes are exact for convection-dispersion at any cell Peclet number, the node balances
conserve mass, the grids cover their domains, and the closed and open grids agree on the
mill."""
import numpy as np
import pytest

from millflow.mill import axial
from millflow.mill.finite_volume import bernoulli, closed_faces, node_losses, open_faces, tridiagonal

EPS = np.finfo(float).eps
V = np.array([1.0, 0.6, 1.3])  # relative velocities and dispersions of three classes
W = np.array([1.0, 1.4, 0.5])


def _grids(pe):
    yield closed_faces(pe, 8, V, W)
    yield open_faces(pe, 8, V, W, 0.5)  # uniform tails
    yield open_faces(pe, 8, V, W, 3.0)  # stretched tails: widths from 1/8 up to ~0.6


def _dense(lower, diag, upper):
    return np.diag(diag) + np.diag(lower, -1) + np.diag(upper, 1)


def test_bernoulli_identity_limits_and_no_overflow():
    x = np.r_[0.0, np.geomspace(1e-12, 1e3, 60)]
    # B(-x) = x + B(x): a few roundings of numbers of size max(B(-x), 1)
    gap = np.abs(bernoulli(-x) - bernoulli(x) - x)
    assert np.all(gap <= 8 * EPS * np.maximum(bernoulli(-x), 1.0))
    assert bernoulli(np.array([0.0]))[0] == 1.0
    assert np.all(np.isfinite(bernoulli(np.array([-800.0, 800.0, 1e300]))))
    assert axial._bernoulli is bernoulli  # the old name still imports


@pytest.mark.parametrize("pe", [0.1, 10.0, 1e4])
def test_fluxes_exact_for_convection_dispersion_at_any_cell_peclet(pe):
    # c = A + B exp(v (z - z_end) / D) solves (v c - D c')' = 0 with the flux v A everywhere;
    # the fitted flux must give v A on every face, whatever v h / D (here 5e-3 ... 2e4).
    for faces in _grids(pe):
        D = W / pe
        c = 2.0 + 3.0 * np.exp(V[:, None] * (faces.z[None, :] - faces.z[-1]) / D[:, None])
        F = faces.alpha * c[:, :-1] - faces.beta * c[:, 1:]
        terms = faces.alpha * np.abs(c[:, :-1]) + faces.beta * np.abs(c[:, 1:])
        # relative to the terms that cancel: B to a few roundings, exp(x) to |x| eps with
        # |x| up to ~700 where it does not underflow (~2e-13), so 1e-12
        assert np.all(np.abs(F - 2.0 * V[:, None]) <= 1e-12 * terms)
        # the node balances A c = 0 inside, the inflow v A at the first node, v c at the last
        lower, diag, upper = tridiagonal(faces, node_losses(faces, V))
        for i in range(V.size):
            r = _dense(lower[i], diag[i], upper[i]) @ c[i]
            expected = np.zeros_like(r)
            expected[0], expected[-1] = 2.0 * V[i], V[i] * (c[i, -1] - 2.0)
            scale = np.abs(_dense(lower[i], diag[i], upper[i])) @ np.abs(c[i])
            assert np.all(np.abs(r - expected) <= 1e-12 * scale)


@pytest.mark.parametrize("pe", [1e-6, 10.0, 1e6])
def test_column_sums_are_the_losses(pe):
    # mass conservation: the fluxes cancel between volumes, so column k of each class's
    # matrix sums to what leaves at node k (breakage tau S w_k, the outflow v at the end);
    # three or four terms of size <= max|A| summed: 8 eps max|A|
    rates = np.array([0.5, 2.0, 0.0])
    for faces in _grids(pe):
        loss = node_losses(faces, V, rates)
        expected = rates[:, None] * faces.weights[None, :]
        expected[:, -1] += V
        assert np.allclose(loss, expected, rtol=2 * EPS, atol=0.0)  # one product and one sum: 2 eps
        lower, diag, upper = tridiagonal(faces, loss)
        in_place = loss.copy()
        assert np.array_equal(tridiagonal(faces, in_place, overwrite_loss=True)[1], diag)
        assert np.array_equal(in_place, diag) and not np.array_equal(loss, diag)
        for i in range(V.size):
            A = _dense(lower[i], diag[i], upper[i])
            assert np.all(np.abs(A.sum(axis=0) - loss[i]) <= 8 * EPS * np.abs(A).max())
            assert np.all(np.diag(A, -1) < 0) and np.all(np.diag(A, 1) <= 0)  # an M-matrix's signs
        assert np.all(faces.alpha > 0) and np.all(faces.beta >= 0)


@pytest.mark.parametrize("tail", [0.3, 1.0, 40.0])
def test_grids_cover_their_domains(tail):
    # sums of n positive numbers: n eps relative
    closed = closed_faces(10.0, 16, V, W)
    assert abs(closed.weights.sum() - 1.0) <= 17 * EPS
    assert np.array_equal(closed.upstream, closed.weights)
    assert (closed.inlet, closed.outlet) == (0, 16)
    faces = open_faces(10.0, 16, V, W, tail)
    n = faces.z.size
    assert np.array_equal(faces.h, np.diff(faces.z)) and np.all(faces.h > 0)
    length = faces.z[-1] - faces.z[0]
    assert abs(faces.weights.sum() - length) <= n * EPS * length
    assert faces.z[faces.inlet] == 0.0 and faces.z[faces.outlet] == 1.0
    assert abs(faces.upstream.sum() - (1.0 - faces.z[0])) <= n * EPS * length  # (-tail, 1]
    assert np.all(faces.upstream[faces.outlet + 1:] == 0.0)
    assert np.all(np.diff(faces.h[faces.outlet:]) >= -4 * EPS)  # the tail widens away from the mill


@pytest.mark.parametrize("M", [16, 12])
@pytest.mark.parametrize("pe", [0.1, 10.0, 1e4])
def test_open_grid_in_the_mill_is_the_closed_grid(pe, M):
    closed = closed_faces(pe, M, V, W)
    opened = open_faces(pe, M, V, W, 2.0)
    mill = slice(opened.inlet, opened.outlet + 1)
    assert np.all(np.abs(opened.z[mill] - closed.z) <= 2 * EPS)  # the same nodes, two constructions: 2 eps
    faces = slice(opened.inlet, opened.outlet)
    # The open grid's widths are differences of the same nodes: 1/M to ~M eps relative
    # (exactly when M is a power of two), which moves the coefficients by (1 + P) times that;
    # plus a few eps for exp evaluated in arrays of different lengths (SIMD and scalar paths
    # of libm may differ by an ulp on other machines).
    P = closed.cell_peclet
    tol = (4 * EPS if M & (M - 1) == 0 else 4 * M * EPS) * (1 + P) + 4 * EPS
    for a, b in ((opened.alpha, closed.alpha), (opened.beta, closed.beta), (opened.cell_peclet, P)):
        assert np.all(np.abs(a[:, faces] - b) <= tol * np.abs(b))
    # the volumes (h_(k-1) + h_k) / 2 ~ 1/M, each h within ~M eps / M of 1/M: 4 eps absolute
    assert np.all(np.abs(opened.weights[mill][1:-1] - closed.weights[1:-1]) <= 4 * EPS)
