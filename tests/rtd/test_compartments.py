"""Compartment networks and recirculating cells: conventions, validation and limits."""
import numpy as np
import pytest
from scipy import linalg

import rtd
from rtd.compartments import expm_batch


def test_system_matrix_convention():
    # cell 0 -> cell 1 at 2.0, back-mixing 1 -> 0 at 0.5, feed 1.5 into cell 0, exit from 1
    net = rtd.CompartmentNetwork(volumes=[1.0, 4.0], flows=[[0, 0.5], [2.0, 0]],
                                 inlet=[1, 0], outlet=[0, 1.5])
    a = net.system_matrix()
    np.testing.assert_allclose(a, [[-2.0, 0.5 / 4], [2.0, -(0.5 + 1.5) / 4]])
    # total tracer is conserved except through the outlet: 1^T A = -outlet/V
    np.testing.assert_allclose(a.sum(axis=0), -net.outlet / net.volumes)
    assert net.feed_flow == 1.5
    assert net.mean == pytest.approx(5.0 / 1.5, rel=1e-12)  # V/Q when every cell is flushed


def test_pdf_and_transform_from_matrix_exponential_and_solve():
    net = rtd.RecirculatingCells(3.0, 4, r=0.7).network()
    a, w, u = net.system_matrix(), net.outlet / net.volumes, net.inlet
    for t in (0.1, 1.0, 7.0):
        assert net.pdf(t) == pytest.approx(w @ linalg.expm(a * t) @ u, rel=1e-12)
    for s in (0.2, 3 + 4j, 1e8):
        ref = w @ np.linalg.solve(s * np.eye(4) - a, u)
        assert abs(net.laplace(s) - ref) <= 1e-13 * abs(ref)


def test_expm_batch_matches_scipy_for_defective_and_stiff_matrices():
    a = rtd.TanksInSeries(2.0, 5).network().system_matrix()  # one repeated eigenvalue
    b = rtd.RecirculatingCells(1.0, 6, r=50.0).network().system_matrix()  # stiff
    t = np.array([0.0, 1e-4, 0.3, 2.0, 40.0])
    for m in (a, b):
        got = expm_batch(m, t)
        for k, tk in enumerate(t):
            np.testing.assert_allclose(got[k], linalg.expm(m * tk), rtol=1e-10, atol=1e-14)


def test_cells_without_backmixing_are_tanks_in_series():
    t = np.linspace(0, 10, 21)
    for n in (1, 2, 5):
        cells, tis = rtd.RecirculatingCells(2.0, n), rtd.TanksInSeries(2.0, n)
        np.testing.assert_allclose(cells.pdf(t), tis.pdf(t), rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(cells.cdf(t), tis.cdf(t), rtol=1e-10, atol=1e-14)
        assert cells.variance == pytest.approx(tis.variance, rel=1e-12)


def test_backmixing_moves_cells_towards_one_mixer():
    variances = [rtd.RecirculatingCells(1.0, 5, r=r).variance for r in (0, 1, 10, 1e3)]
    assert variances[0] == pytest.approx(0.2) and np.all(np.diff(variances) > 0)
    assert variances[-1] == pytest.approx(1.0, abs=2e-3)


def test_many_cells_with_backmixing_approach_closed_axial_dispersion():
    # n cells with back-mixing r: 1/Pe ~ (1/(2n))(1 + 2r) for large n (variance matching);
    # compare whole curves to the closed dispersion model of the same variance
    t = np.linspace(0.2, 2.5, 12)
    errors = []
    for n in (15, 60):
        cells = rtd.RecirculatingCells(1.0, n, r=2.0)
        ad = rtd.AxialDispersion.from_moments(cells.mean, cells.variance)
        assert ad.pe == pytest.approx(2 * n / (1 + 2 * 2.0), rel=0.02)
        errors.append(np.max(np.abs(cells.pdf(t) - ad.pdf(t))) / ad.pdf(1.0))
    assert errors[1] < 0.01 and errors[1] < errors[0] / 2


def test_dead_volume_and_bypass(integrate_density):
    m = rtd.RecirculatingCells(4.0, 3, r=0.5, dead=0.25, bypass=0.2)
    assert m.mean == pytest.approx(3.0) and m.network().mean == pytest.approx(3.0, rel=1e-12)
    assert float(m.cdf(0.0)) == pytest.approx(0.2)
    assert m.laplace(1e8) == pytest.approx(0.2, abs=1e-7)
    assert integrate_density(m) == pytest.approx(1.0, abs=1e-10)
    net = m.network()
    assert net.bypass == 0.2 and net.volumes.sum() == pytest.approx(3.0)


def test_network_exposes_structure_read_only():
    net = rtd.TanksInSeries(3.0, 3).network()
    np.testing.assert_allclose(net.volumes, [1, 1, 1])
    np.testing.assert_allclose(net.flows, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(net.inlet, [1, 0, 0])
    np.testing.assert_allclose(net.outlet, [0, 0, 1])
    with pytest.raises(ValueError):
        net.volumes[0] = 2.0
    assert net.analytic_for_re_s_greater_than == pytest.approx(-1.0)
    with pytest.raises(rtd.ParameterError, match="integer"):
        rtd.TanksInSeries(3.0, 2.5).network()


@pytest.mark.parametrize("kwargs, match", [
    (dict(volumes=[1.0, -1.0]), "volumes"),
    (dict(flows=[[0, 1], [1, 0]]), "cell 0"),          # volume imbalance
    (dict(inlet=[0.5, 0.4]), "inlet"),
    (dict(outlet=[0.0, 0.0]), "outlet"),
    (dict(flows=[[1.0, 0], [1.0, 0]]), "diagonal"),
    (dict(bypass=1.0), "bypass"),
    (dict(flows=[[0, 0], [1, 0], [0, 0]]), "shapes"),
])
def test_network_validation(kwargs, match):
    base = dict(volumes=[1.0, 1.0], flows=[[0, 0], [1.0, 0]], inlet=[1, 0], outlet=[0, 1.0])
    with pytest.raises(rtd.ParameterError, match=match):
        rtd.CompartmentNetwork(**{**base, **kwargs})
