"""Statistical properties of the reconciliation and the circuit fit over synthetic replicates.

Surveys of known circuits (the closed-circuit example and the wet cyclone circuit) with
noise drawn from the stated error model (millflow.survey.synthetic). Slow: run with
``python -m pytest -m slow tests/millflow/survey``.
"""
from functools import lru_cache

import numpy as np
import pytest

from millflow.flowsheet import load, solve
from millflow.survey import reconcile
from millflow.survey.reader import class_fractions
from millflow.survey.synthetic import grid_sieves, synthetic_survey
from tests import paths

CASES = {"closed_circuit": ("flowsheets/closed_circuit_ball_mill.toml", 8),
         "wet_cyclones": ("flowsheets/closed_circuit_wet_cyclones.toml", 10)}
#: Replicates: the 5 % test's rejection rate has a binomial SE of 1.1 % at 400, so the
#: 3-8 % window is 1.8 SE below and 2.7 SE above 5 %.
REPLICATES = 400


class _Zero:
    def standard_normal(self, size=None):
        return 0.0 if size is None else np.zeros(size)


@lru_cache(maxsize=None)
def case(name):
    path, every = CASES[name]
    sol = solve(load(paths.REPO / path))
    return sol, grid_sieves(sol.flowsheet.grid, every, bottom=20e-6)


def _truth_rows(bal, truth):
    out = []
    for row in bal.structure.rows:
        n = row["stream"]
        out.append({"solids": lambda: truth["solids"][n], "water": lambda: truth["water"][n],
                    "solids_content": lambda: truth["solids_content"][n],
                    "fraction": lambda: class_fractions(truth["passing"][n])[row["class"]]}[row["kind"]]())
    return np.array(out)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_reconciliation_statistics(name):
    sol, sieves = case(name)
    rng = np.random.default_rng(20261125)
    rejected, covered, cl_covered, closer = 0, [], [], []
    for _ in range(REPLICATES):
        survey, truth = synthetic_survey(sol, sieves, rng)
        bal = reconcile(survey)
        rejected += not bal.chi_square["passed"]
        for n in sol.flowsheet.stream_names:
            if survey.streams[n].solids is None:  # derived (unmeasured) flows
                v, sd, ok = bal.solids(n)
                assert ok
                covered.append(abs(v - truth["solids"][n]) <= 1.959964 * sd)
        for n, (v, sd, _ok) in bal.circulating_loads().items():
            cl_covered.append(abs(v - truth["circulating_load"][n]) <= 1.959964 * sd)
        t = _truth_rows(bal, truth)
        closer.append((np.sum(((bal.adjusted - t) / bal.sd) ** 2), np.sum(((bal.measured - t) / bal.sd) ** 2)))
    rate = rejected / REPLICATES
    assert 0.03 <= rate <= 0.08, rate
    assert 0.90 <= np.mean(covered) <= 0.98, np.mean(covered)
    assert 0.90 <= np.mean(cl_covered) <= 0.98, np.mean(cl_covered)
    adj, meas = np.mean(closer, axis=0)
    assert adj < meas  # adjusted values are closer to the truth than the measurements on average


@pytest.mark.slow
@pytest.mark.parametrize("name, stream, cls", [("closed_circuit", "underflow", 4), ("wet_cyclones", "cyclone_feed", 9),
                                               ("wet_cyclones", "mill_feed", 6)])
def test_planted_gross_error_is_named_first(name, stream, cls):
    """A 10-SD error in one size fraction of one sample: the largest normalised adjustment
    names that measurement in >= 90 % of replicates.

    Not every measurement can be singled out so often: where a class balance ties a
    measurement to others with as much leverage (the wet circuit's underflow, -707 +500 um,
    is named first in about 75 % of replicates), their normalised adjustments are nearly
    equal and the test names one of the group; that is the measurement test's known limit
    (equal-leverage measurements are not separable), not a defect of the reconciliation.

    The >= 90 % holds for measurements whose redundancy makes it possible: the three here
    are ones the balance reports as catching a 10-SD error with power >= 0.9 (checked
    below on the noise-free survey). A low-redundancy measurement (an almost empty class,
    a feed class) is caught far less often, as its reported power says: that is checked
    against the observed rate in test_gross_error_detection_rate_matches_the_predicted_power."""
    sol, sieves = case(name)
    clean = reconcile(synthetic_survey(sol, sieves, _Zero())[0])
    i = next(j for j, r in enumerate(clean.structure.rows)
             if r["stream"] == stream and r["kind"] == "fraction" and r["class"] == cls)
    assert clean.detection_power(10.0)[i] >= 0.9, clean.detection_power(10.0)[i]
    rng = np.random.default_rng(7)
    sample, exact, R = 0, 0, 150
    for _ in range(R):
        survey, _ = synthetic_survey(sol, sieves, rng, gross={"stream": stream, "class": cls, "sd": 10.0})
        bal = reconcile(survey)
        top = bal.ranked(1)[0]
        row = bal.structure.rows[top["row"]]
        sample += row["stream"] == stream and row["kind"] == "fraction"
        exact += row["stream"] == stream and row.get("class") == cls
    assert exact / R >= 0.90, (exact / R, sample / R)


@pytest.mark.slow
@pytest.mark.parametrize("stream, cls", [("underflow", 4), ("fresh", 2), ("fresh", 6), ("overflow", 12)])
def test_gross_error_detection_rate_matches_the_predicted_power(stream, cls):
    """The detectability the balance reports is the power of its measurement test.

    A gross error of 10 SD (at the true value) planted in one size fraction: over replicates,
    the share in which that measurement's |normalised adjustment| exceeds the threshold
    matches the mean predicted power P(|N(k sqrt(r), 1)| > threshold) within 3 binomial SEs.
    k is the planted error in the SDs the balance uses: the error model's SD at the
    reconciled value, which the gross error itself moves (a 10-SD error at the truth is
    ~7 SD at the reconciled value of the underflow's -2828 +2000 um class). The cases span
    redundancies 0.45 (power ~1) to 0.07 (power ~0.15): the >= 90 % detection of a 10-SD
    error holds only where the redundancy allows it, and the balance says where that is."""
    from millflow.survey.reader import class_fractions
    from millflow.survey.reconcile import test_power

    sol, sieves = case("closed_circuit")
    rng = np.random.default_rng(11)
    R, hits, pred = 200, 0, []
    for _ in range(R):
        survey, truth = synthetic_survey(sol, sieves, rng, gross={"stream": stream, "class": cls, "sd": 10.0})
        bal = reconcile(survey)
        i = next(j for j, r in enumerate(bal.structure.rows)
                 if r["stream"] == stream and r["kind"] == "fraction" and r["class"] == cls)
        sd_true = survey.errors.fraction_sd(class_fractions(truth["passing"][stream]))[cls]
        k = 10.0 * sd_true / bal.sd[i]
        pred.append(float(test_power(k, bal.redundancy[i], bal.threshold)))
        hits += abs(bal.normalised[i]) > bal.threshold
    rate, p = hits / R, float(np.mean(pred))
    se = np.sqrt(np.sum(np.array(pred) * (1 - np.array(pred)))) / R
    print(stream, cls, rate, p, se)
    # 3 binomial SEs, plus 0.15 for what the linearisation leaves out (the bilinear flow x fraction
    # terms and the SD moving with the reconciled value: the normalised adjustment's null SD is
    # ~1.1, not 1, and its shift under the error is off by up to ~0.3)
    assert abs(rate - p) <= 3 * max(se, 0.5 / R) + 0.15, (rate, p, se)
