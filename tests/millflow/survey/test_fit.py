"""Fitting a circuit to a survey: exact recovery, the written flowsheet, coverage over replicates."""
import numpy as np
import pytest

from millflow.flowsheet import from_dict, load, solve
from millflow.flowsheet.io import loads
from millflow.psd import cum_passing_at
from millflow.survey import reconcile
from millflow.survey.fit import fit_circuit, to_toml
from millflow.survey.reader import ErrorModel
from millflow.survey.synthetic import grid_sieves, synthetic_survey
from tests import paths

CIRCUIT = paths.REPO / "examples" / "survey" / "circuit.toml"
ERRORS = ErrorModel(solids_rel=0.02, water_rel=0.05, solids_content_sd=0.01, psd_sd=0.01, psd_floor=0.001)
NAMES = ["materials.ore.rate.A_E_t_per_kWh", "units.cyclones.d50c_um", "units.cyclones.bypass",
         "units.cyclones.water_to_coarse"]
TRUTH = [0.675, 140.0, 0.30, 0.30]
BOUNDS = {NAMES[0]: (0.3, 2.0), NAMES[1]: (80.0, 300.0), NAMES[2]: (0.05, 0.6), NAMES[3]: (0.05, 0.6)}


class _Zero:
    def standard_normal(self, size=None):
        return 0.0 if size is None else np.zeros(size)


def _setup():
    sol = solve(load(CIRCUIT))
    return sol, grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)[1:]


def test_noise_free_survey_recovers_the_circuit_and_the_toml_reproduces_it(tmp_path):
    sol, sieves = _setup()
    survey, _ = synthetic_survey(sol, sieves, _Zero(), errors=ERRORS, additions=["sump"])
    cf = fit_circuit(reconcile(survey), NAMES, BOUNDS, starts=1, leave_one_out=False)
    # the data are the truth; the fitted circuit's feed is the survey's, known only at the sieves
    # (every second grid edge, PCHIP between them), which moves the estimate by ~4e-5: 1e-3 bounds it
    for n, t in zip(NAMES, TRUTH):
        assert cf.values[n] == pytest.approx(t, rel=1e-3), n
    text = to_toml(cf.document())
    fs = loads(text)
    again = solve(fs)
    direct = cf.model.solve([cf.values[n] for n in NAMES])
    np.testing.assert_allclose(again.flows, direct.flows, rtol=1e-12, atol=1e-12 * direct.flows.max())
    # and the fitted circuit is the true one: stream flows agree with the truth's
    np.testing.assert_allclose(direct.flows.sum(axis=1), sol.flows.sum(axis=1), rtol=1e-3)
    assert from_dict(cf.document()).units["cyclones"].type == "classifier"


@pytest.mark.slow
def test_coverage_and_second_operating_point():
    """Over replicates the 95 % intervals cover the true parameters in >= 85 % of cases, and the
    prediction at +15 % feed (overflow % passing 75 um) lies within its 95 % band as often."""
    sol, sieves = _setup()
    doc = load(CIRCUIT).meta["document"]
    import copy

    def more_feed(d):
        d["units"]["fresh_feed"]["solids_tph"] *= 1.15

    def passing_75(s):
        f = s.flow("overflow")
        return 100 * cum_passing_at(s.flowsheet.grid, f / f.sum(), [75e-6])[0]

    rng = np.random.default_rng(11)
    covered, predicted = [], []
    R = 25
    for _ in range(R):
        survey, truth = synthetic_survey(sol, sieves, rng, errors=ERRORS, additions=["sump"])
        cf = fit_circuit(reconcile(survey), NAMES, BOUNDS, starts=1, leave_one_out=False)
        d = cf.to_dict()["parameters"]
        for n, t in zip(NAMES, TRUTH):
            covered.append(d[n]["ci95"][0] <= t <= d[n]["ci95"][1])
        # the truth at the second operating point: the true circuit with the surveyed feed's change
        true_doc = copy.deepcopy(cf.model.doc)  # the reconciled feed, true parameters
        for n, t in zip(NAMES, TRUTH):
            node = true_doc
            *head, last = n.split(".")
            for part in head:
                node = node[part]
            node[last] = t
        more_feed(true_doc)
        true_value = passing_75(solve(from_dict(true_doc, base_dir=CIRCUIT.parent)))
        value, sd = cf.prediction_band(more_feed, passing_75)
        predicted.append(abs(value - true_value) <= 1.959964 * sd)
    assert doc  # the example circuit was read
    assert np.mean(covered) >= 0.85, np.mean(covered)
    assert np.mean(predicted) >= 0.85, np.mean(predicted)


@pytest.mark.slow
def test_wet_cyclone_circuit_plitt_calibration_and_water_split():
    """The wet circuit with Plitt-predicted cyclones: its calibration factors F1 (cut size) and
    F3 (water split) fitted to a survey of the circuit calibrated at F1 = 1.15, F3 = 0.85,
    starting from the uncalibrated model (1, 1). Noise-free: recovered to 1e-3 (the feed is known
    only at the sieves). With noise from the error model (one seed): the truth inside the 95 %
    intervals."""
    import copy
    import dataclasses

    base = load(paths.REPO / "flowsheets" / "closed_circuit_wet_cyclones.toml")
    doc = copy.deepcopy(base.meta["document"])
    doc["units"]["cyclones"].update(F1=1.0, F3=1.0)
    start = from_dict(copy.deepcopy(doc))
    doc["units"]["cyclones"].update(F1=1.15, F3=0.85)
    sol = solve(from_dict(doc))
    sieves = grid_sieves(sol.flowsheet.grid, 10, bottom=20e-6)
    names = ["units.cyclones.F1", "units.cyclones.F3"]
    bounds = {names[0]: (0.5, 2.0), names[1]: (0.5, 2.0)}
    truth = {names[0]: 1.15, names[1]: 0.85}
    water = ErrorModel(solids_rel=0.02, water_rel=0.05, solids_content_sd=0.01, psd_sd=0.01, psd_floor=0.001)
    for rng, exact in ((_Zero(), True), (np.random.default_rng(5), False)):
        survey, _ = synthetic_survey(sol, sieves, rng, errors=water, additions=["ball_mill", "sump"])
        survey = dataclasses.replace(survey, flowsheet=start)  # the fit starts from the uncalibrated model
        cf = fit_circuit(reconcile(survey), names, bounds, starts=1, leave_one_out=False)
        d = cf.to_dict()["parameters"]
        for n in names:
            if exact:
                assert d[n]["value"] == pytest.approx(truth[n], rel=1e-3), (n, d[n])
            else:
                lo, hi = d[n]["ci95"]
                assert lo <= truth[n] <= hi, (n, d[n])
                assert d[n]["se"] < 0.1 * truth[n]  # the survey determines both factors
