"""Scale-up with malformed fit results and circuits without a steady state: one-line
errors naming what is wrong, never a foreign exception."""
import copy

import numpy as np
import pytest

from millflow.synthetic import synthetic_lab_fit
from millflow.errors import InputError, SolverError
from millflow.grid import SizeGrid
from millflow.scaleup import Circuit, MillDesign, ScaleUp, fit_from_dict
from tests.millflow.scaleup.test_scaleup import CYCLONE, FEED, LAB, PLANT, make_fit

GRID = SizeGrid.geometric(4e-3, 2 ** 0.5, 14)


@pytest.fixture(scope="module")
def fit_dict():
    theta = {"ln_A0": np.log(1 / 200), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}
    d, _ = synthetic_lab_fit(theta, GRID, 0.005, np.random.default_rng(3), as_dict=True)
    return d


def _edit(d, path, value):
    d = copy.deepcopy(d)
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return d


@pytest.mark.parametrize("path, value, match", [
    (("covariance",), [[1.0, 0.0], [0.0, 1.0]], "covariance: expected a table"),
    (("covariance", "names"), ["foo", "bar", "baz", "qux", "quux"], "covariance.names"),
    (("covariance", "matrix"), "identity", "covariance: expected a table"),
    (("covariance", "matrix"), [["a"]], "covariance.matrix"),
    (("params", "phi", "value"), 1.3, r"phi = 1.3.*outside"),
    (("params", "phi", "value"), "0.4", r"params.phi.value = '0.4'"),
    (("model_spec", "param_names"), "ln_A0", "model_spec.param_names"),
])
def test_malformed_fit_results_are_named(fit_dict, path, value, match):
    fit_dict["covariance"]["matrix"]  # the fixture is a valid fit
    fit_from_dict(fit_dict, "fit.json")
    with pytest.raises(InputError, match=match):
        fit_from_dict(_edit(fit_dict, path, value), "fit.json")


@pytest.mark.parametrize("plant, clf", [
    (MillDesign(4.0, 1e-9, 0.35, 0.75, 50.0, name="plant"), CYCLONE),  # a mill of no length: T = I
    (PLANT, {**CYCLONE, "d50c": 1e-12, "bypass": 0.0}),  # the classifier returns everything
])
def test_circuits_without_a_steady_state_are_solver_errors(plant, clf):
    su = ScaleUp(make_fit(), LAB, {}, Circuit(plant, "tis", {"n": 3}, clf), FEED, 100.0)
    with pytest.raises(SolverError, match="can never leave the loop .*classifier"):
        su.operate(su.fit.theta)


def test_a_target_finer_than_the_finest_sieve_is_said(fit_dict):
    # the lab sieves reach 4 mm / 2^5.5 = 88 um; a 20 um target extrapolates the fitted forms
    from millflow.scaleup import predict_plant

    fit = fit_from_dict(fit_dict, "fit.json")
    lo, hi = fit.spec["measured_size_range_m"]
    assert lo == pytest.approx(4e-3 * 2 ** -5.5, rel=1e-9) and hi == pytest.approx(4e-3, rel=1e-9)
    fine = SizeGrid.geometric(4e-3, 2 ** 0.5, 24)  # the prediction grid reaches 10 um
    feed = np.r_[np.full(3, 1 / 3), np.zeros(21)]
    su = ScaleUp(fit, LAB, {}, Circuit(PLANT, "tis", {"n": 3}, CYCLONE), feed, 100.0, x=fine.x)
    with pytest.warns(UserWarning, match=r"target P80 60 um is finer than the finest sieve .*88.39"):
        res = predict_plant(su, 60e-6, methods=("delta",))
    assert any("target P80" in n for n in res.summary["extrapolation"])
