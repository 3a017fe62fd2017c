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
    rejected, covered, cl_covered, closer, water, added = 0, [], [], [], [], []
    for _ in range(REPLICATES):
        survey, truth = synthetic_survey(sol, sieves, rng)
        bal = reconcile(survey)
        rejected += not bal.chi_square["passed"]
        for n in sol.flowsheet.stream_names:
            if survey.streams[n].solids is None:  # derived (unmeasured) flows
                v, sd, ok = bal.solids(n)
                assert ok
                covered.append(abs(v - truth["solids"][n]) <= 1.959964 * sd)
            if bal.structure.wet:  # water is never metered here: every stream's water is derived
                v, sd, ok = bal.water(n)
                assert ok
                water.append(abs(v - truth["water"][n]) <= 1.959964 * sd)
        for u in bal.structure.additions:  # unmetered additions, derived
            v, sd, ok = bal.addition(u)
            assert ok
            added.append(abs(v - truth["water_added"][u]) <= 1.959964 * sd)
        for n, (v, sd, _ok) in bal.circulating_loads().items():
            cl_covered.append(abs(v - truth["circulating_load"][n]) <= 1.959964 * sd)
        t = _truth_rows(bal, truth)
        closer.append((np.sum(((bal.adjusted - t) / bal.sd) ** 2), np.sum(((bal.measured - t) / bal.sd) ** 2)))
    rate = rejected / REPLICATES
    print(f"{name}: chi-square rejects {rate:.4f}; derived solids flows covered {np.mean(covered):.4f} "
          f"({len(covered)}), circulating load {np.mean(cl_covered):.4f} ({len(cl_covered)})"
          + (f", water flows {np.mean(water):.4f} ({len(water)}), water additions {np.mean(added):.4f} "
             f"({len(added)})" if water else ""))
    assert 0.03 <= rate <= 0.08, rate
    assert 0.90 <= np.mean(covered) <= 0.98, np.mean(covered)
    assert 0.90 <= np.mean(cl_covered) <= 0.98, np.mean(cl_covered)
    if name == "wet_cyclones":
        assert len(water) == REPLICATES * len(sol.flowsheet.stream_names) and len(added) >= REPLICATES
        assert 0.90 <= np.mean(water) <= 0.98, np.mean(water)
        assert 0.90 <= np.mean(added) <= 0.98, np.mean(added)
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


def _plant(rows, i):
    r = rows[i]
    g = {"stream": r["stream"], "sd": 10.0}
    if r["kind"] == "fraction":
        g["class"] = r["class"]
    else:
        g[r["kind"]] = True
    return g


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_gross_errors_planted_at_random_measurements(name):
    """A 10-SD error planted at a random measurement (size fraction, solids flow or % solids),
    200 replicates. Among the plantings at measurements the balance reports as detectable with
    power >= 0.9 (on the noise-free survey):

    - the planted measurement is named first, or is among the first candidate's
      not_separable_from (|rho| >= 0.9), in >= 90 %;
    - where the planted measurement has no such partner (it is separable), it is named first
      in >= 90 %.

    Named first alone is not >= 90 %: in a node whose size class is measured in every stream,
    an error in one stream's class moves the others' normalised adjustments as much (rho near
    1), and which of them is first is decided by the noise. Measured (seed 31): closed circuit
    first 56.8 % of 111 with power >= 0.9 (98.2 % with the group; separable 100 % of 34),
    34.0 % overall; wet circuit first 91.4 % of 163 (94.5 % with the group; separable 92.7 %
    of 109), 79.0 % overall. docs/survey.md records these."""
    sol, sieves = case(name)
    clean = reconcile(synthetic_survey(sol, sieves, _Zero())[0])
    rows = clean.structure.rows
    power = clean.detection_power(10.0)
    separable = [not clean.inseparable(i) for i in range(len(rows))]
    candidates = [i for i, r in enumerate(rows) if r["kind"] in ("fraction", "solids", "solids_content")]
    rng = np.random.default_rng(31)
    rec = []
    for _ in range(200):
        i = candidates[rng.integers(len(candidates))]
        survey, _ = synthetic_survey(sol, sieves, rng, gross=_plant(rows, i))
        bal = reconcile(survey)
        top = bal.ranked(1)[0]["row"]
        rec.append((power[i] >= 0.9, separable[i], top == i, top == i or i in bal.inseparable(top)))
    a = np.array(rec, bool)
    hi, sep, first, group = a.T
    print(f"{name}: named first {first.mean():.3f} overall; power >= 0.9 ({hi.sum()}): first "
          f"{first[hi].mean():.3f}, first or its group {group[hi].mean():.3f}; separable ({(hi & sep).sum()}): "
          f"first {first[hi & sep].mean():.3f}")
    assert hi.sum() >= 50 and (hi & sep).sum() >= 20  # enough plantings for the rates below
    assert group[hi].mean() >= 0.90, group[hi].mean()
    assert first[hi & sep].mean() >= 0.90, first[hi & sep].mean()
