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
    prediction at +15 % feed (overflow % passing 75 um) lies within its 95 % band as often.
    Measured (seed 11): 96.8 % of 400 intervals, 93 % of 100 predictions; with eq. 9's SEs alone
    (no input-error term) 88.7 % and 72 %. ~7 min wall on 2 shared cores (~100 s of CPU)."""
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
    # 100 replicates (4 parameters: 400 intervals): the binomial SE of a 95 % coverage is 1.1 %
    # (2.2 % for the 100 predictions), so >= 85 % is 9 (4.5) SEs below the nominal rate
    R = 100
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
    print(f"parameter intervals cover the truth in {np.mean(covered):.3f} of {len(covered)}, the prediction "
          f"band in {np.mean(predicted):.3f} of {len(predicted)}")
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


def _columns(model, theta, rel=1e-4):
    """Whitened central-difference Jacobian columns of a circuit model at ``theta``."""
    th = np.asarray(theta, float)
    cols = []
    for k in range(th.size):
        h = rel * abs(th[k])
        tp, tm = th.copy(), th.copy()
        tp[k] += h
        tm[k] -= h
        cols.append((model.predict(tp)[0] - model.predict(tm)[0]) / (2 * h))
    return np.array(cols)


def _per_time_circuit():
    """The survey example with rates per time and a fixed residence time (the per-time path)."""
    import copy

    doc = copy.deepcopy(load(CIRCUIT).meta["document"])
    doc["materials"]["ore"]["rate"] = {"form": "power", "A_per_min": 0.9, "alpha": 1.0, "x0_um": 1000}
    mill = doc["units"]["ball_mill"]
    del mill["holdup_t"]
    mill["tau_min"] = 3.5
    return doc


def test_residence_time_is_fitted_and_its_confounding_with_the_rate_is_reported(tmp_path):
    """Per-time rates with a fixed tau_min: a noise-free survey of the circuit at tau = 3.5 min,
    fitted from tau = 2.5 min with the rate known, recovers tau to 1e-3 (the feed is known only
    at the sieves). Rate and tau together are not separable: through tanks in series a class's
    product depends on S_i tau only, so the two Jacobian columns are parallel (|cos| > 1 - 1e-6),
    and the fit of both reports a condition number in fit.json's statistics above 1e8."""
    import copy

    truth_doc = _per_time_circuit()
    sol = solve(from_dict(copy.deepcopy(truth_doc), base_dir=CIRCUIT.parent))
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)[1:]
    start_doc = copy.deepcopy(truth_doc)
    start_doc["units"]["ball_mill"]["tau_min"] = 2.5
    start = from_dict(start_doc, base_dir=CIRCUIT.parent)
    import dataclasses

    survey, _ = synthetic_survey(sol, sieves, _Zero(), errors=ERRORS, additions=["sump"])
    bal = reconcile(dataclasses.replace(survey, flowsheet=start))
    name = "units.ball_mill.tau_min"
    cf = fit_circuit(bal, [name], {name: (1.0, 8.0)}, starts=1, leave_one_out=False)
    assert cf.values[name] == pytest.approx(3.5, rel=1e-3)
    one = cf.to_dict()
    assert one["input_errors"].startswith("propagated") and one["parameters"][name]["se_inputs"] >= 0
    assert one["parameters"][name]["se"] >= one["parameters"][name]["se_eq9"]
    names = ["materials.ore.rate.A_per_min", name]
    from millflow.survey.fit import CircuitModel

    J = _columns(CircuitModel(bal, names), [0.9, 3.5])
    cos = J[0] @ J[1] / np.linalg.norm(J[0]) / np.linalg.norm(J[1])
    assert abs(cos) > 1 - 1e-6, cos
    both = fit_circuit(bal, names, {names[0]: (0.3, 3.0), name: (1.0, 8.0)}, starts=1, leave_one_out=False)
    d = both.to_dict()
    assert d["singular"] or d["condition_number"] is None or d["condition_number"] > 1e8, d
    assert "not used" in d["cluster_robust"]
    assert d["correlation"]["names"] == names


@pytest.mark.slow
def test_plitt_sharpness_and_pressure_calibration():
    """Plitt's F4 (sharpness) with F1 (cut size), and F2 (pressure), fitted to noise-free surveys
    of the wet circuit calibrated at F1 = 1.15, F2 = 1.3, F3 = 0.85, F4 = 1.2, the factors not
    fitted held at their true values: recovered to 1e-3 (the feed is known only at the sieves).
    F2 and F3 together are not separable from a survey without a pressure gauge: F2 enters the
    split only through the head, S ~ F3 H^-0.24 with H ~ F2, so their Jacobian columns are
    parallel (|cos| > 1 - 1e-4). Measured: F1, F4 fit in ~35 s, F2 in ~80 s on this machine."""
    import copy
    import dataclasses

    from millflow.survey.fit import CircuitModel

    base = load(paths.REPO / "flowsheets" / "closed_circuit_wet_cyclones.toml")
    truth = {"F1": 1.15, "F2": 1.3, "F3": 0.85, "F4": 1.2}
    doc = copy.deepcopy(base.meta["document"])
    doc["units"]["cyclones"].update(truth)
    sol = solve(from_dict(copy.deepcopy(doc)))
    sieves = grid_sieves(sol.flowsheet.grid, 10, bottom=20e-6)
    survey, _ = synthetic_survey(sol, sieves, _Zero(), errors=ERRORS, additions=["ball_mill", "sump"])
    for fitted, start in ((("F1", "F4"), (1.0, 1.0)), (("F2",), (1.0,))):
        d = copy.deepcopy(doc)
        d["units"]["cyclones"].update(dict(zip(fitted, start)))
        bal = reconcile(dataclasses.replace(survey, flowsheet=from_dict(d)))
        names = [f"units.cyclones.{f}" for f in fitted]
        cf = fit_circuit(bal, names, {n: (0.5, 2.0) for n in names}, starts=1, leave_one_out=False)
        for f, n in zip(fitted, names):
            assert cf.values[n] == pytest.approx(truth[f], rel=1e-3), (n, cf.values[n])
    bal = reconcile(dataclasses.replace(survey, flowsheet=from_dict(copy.deepcopy(doc))))
    J = _columns(CircuitModel(bal, ["units.cyclones.F2", "units.cyclones.F3"]), [1.3, 0.85])
    cos = J[0] @ J[1] / np.linalg.norm(J[0]) / np.linalg.norm(J[1])
    assert abs(cos) > 1 - 1e-4, cos


def test_fit_takes_the_feed_at_the_sieves_the_survey_determines():
    """Analyses on different ranges of one series: the fresh feed's and the mill feed's stop at
    44 um, the other streams' go to 31 um. The fresh feed's 31 um passing is then not determined
    (in the chute, fresh + underflow = mill feed class by class, and neither the fresh feed's
    nor the mill feed's -44 um fraction is split), so the fitted circuit's feed takes only the
    sieves the balance determines for it, and the cut size is still recovered from a noise-free
    survey to 1e-2 (the feed below 44 um is extrapolated by the feed reader)."""
    import dataclasses

    from millflow.survey.fit import CircuitModel
    from millflow.survey.reader import PSDMeasurement, class_fractions

    sol = solve(load(CIRCUIT))
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=30e-6)[1:]
    survey, _ = synthetic_survey(sol, sieves, _Zero(), errors=ERRORS, additions=["sump"])
    streams = dict(survey.streams)
    for n in ("fresh", "mill_feed"):
        m = streams[n]
        p = m.psd.passing[:-1]
        psd = PSDMeasurement(sieves[:-1], p, ERRORS.fraction_sd(class_fractions(p)), m.psd.sd_rule)
        streams[n] = dataclasses.replace(m, psd=psd)
    bal = reconcile(dataclasses.replace(survey, streams=streams))
    _, _, ok = bal.passing("fresh")
    assert ok[:-1].all() and not ok[-1]
    model = CircuitModel(bal, ["units.cyclones.d50c_um"])
    feed = model.doc["units"]["fresh_feed"]["psd"]["size_um"]
    np.testing.assert_allclose([x for x in feed if x < 8000 * (1 - 1e-9)], bal.structure.sieves[ok] * 1e6)
    name = "units.cyclones.d50c_um"
    cf = fit_circuit(bal, [name], {name: (80.0, 300.0)}, starts=1, leave_one_out=False)
    assert cf.values[name] == pytest.approx(140.0, rel=1e-2)
