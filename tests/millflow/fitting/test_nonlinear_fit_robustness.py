"""Robustness of non-linear fits at the edges of the bounds: a steady solve that fails at
some corners of the box (Newton's iteration cap, say) is a note, not a refusal; a start
that cannot be solved is dropped; a model undefined at the centre and the start is still
refused. Also: the standard errors do not depend on the finite-difference step of the
sensitivities beyond a stated tolerance (the step balances the ODE noise, rtol / h,
against the truncation, h^2)."""
import numpy as np
import pytest

from millflow.errors import InputError, SolverError
from millflow.falsify.design import batch_design, continuous_design
from millflow.falsify.nonlinear_truths import PopulationTruth
from millflow.falsify.study import study_parameters
from millflow.falsify.truths import BREAKAGE_TRUTH
from millflow.fitting import kinetics as fk
from millflow.fitting.estimate import check_problem, fit
from millflow.fitting.models import ForwardModel, ModelSpec, Parameter

DESIGN = continuous_design([60, 120, 240, 480, 960], n_sieves=8, sieve_ratio=2.0, grid_per_sieve=1)


def _model():
    truth = PopulationTruth(1.0)
    M = truth.mass_fractions(DESIGN)
    clean = DESIGN.passing_at_sieves(M).ravel()
    data = DESIGN.data(clean + 0.005 * np.random.default_rng(3).standard_normal(clean.size), DESIGN.sample_keys())
    spec = ModelSpec(mode="well_mixed", tau_column="tau_s", kinetics=("population",))
    params = study_parameters(spec, BREAKAGE_TRUTH)
    params["lam_pop"] = Parameter("lam_pop", -1.0, -2.0, 1.0)
    return ForwardModel(spec, data, DESIGN.grid), params


def _failing_below(monkeypatch, lam_limit):
    """Newton 'fails' (as at its iteration cap) wherever lambda < lam_limit."""
    from millflow.mill import nonlinear as nl
    real = nl.well_mixed

    def capped(kin, *args, **kwargs):
        if kin.population is not None and kin.population.lam < lam_limit:
            raise SolverError("non-linear well-mixed mill: Newton reached its iteration cap (test)")
        return real(kin, *args, **kwargs)

    monkeypatch.setattr(nl, "well_mixed", capped)


def test_failed_solves_at_corners_are_a_note_and_the_fit_goes_on(monkeypatch):
    _failing_below(monkeypatch, -1.5)
    model, params = _model()
    prob = check_problem(model, params)
    assert len(prob.notes) == 1 and "failed at" in prob.notes[0] and "iteration cap (test)" in prob.notes[0]
    res = fit(model, params, global_search=False, starts=3, grid_check=False, quiet=True, profile=False)
    assert any("failed at" in n for n in res.notes)
    lam = res.stats["params"]["lam_pop"]
    assert np.isfinite(res.ssr) and -1.5 <= lam["value"] <= 1.0
    assert lam["ci95"][0] <= -1.0 <= lam["ci95"][1]  # the truth, inside the solvable region
    assert "note: the non-linear solve failed at" in res.summary()


def test_a_model_unsolvable_at_centre_and_start_is_refused(monkeypatch):
    _failing_below(monkeypatch, 2.0)  # fails everywhere in [-2, 1]
    model, params = _model()
    with pytest.raises(InputError, match="non-finite values at a corner"):
        check_problem(model, params)


def test_unsolvable_starts_are_dropped(monkeypatch):
    from millflow.fitting import estimate

    model, params = _model()
    prob = check_problem(model, params)
    z_bad = prob.full[prob.idx].copy()
    calls = {"n": 0}
    real = prob.resid

    def resid(z):  # the first start cannot be solved
        calls["n"] += 1
        return np.full(model.n_data, np.nan) if np.array_equal(z, z_bad) else real(z)

    monkeypatch.setattr(prob, "resid", resid)
    z, s = estimate._local(prob, z_bad)
    assert s == np.inf and np.array_equal(z, z_bad)


def test_failures_are_recorded_by_the_compiled_kinetics():
    design = batch_design([30, 60, 120], n_sieves=6, sieve_ratio=2.0, grid_per_sieve=1)
    spec = ModelSpec(mode="batch", kinetics=("population",))
    data = design.data(design.passing_at_sieves(PopulationTruth(1.0).mass_fractions(design)).ravel(),
                       design.sample_keys())
    m = ForwardModel(spec, data, design.grid)
    th = np.array([[{**BREAKAGE_TRUTH, "lam_pop": -1.0}[n] for n in spec.param_names]])
    m._nonlinear.failures.clear()
    assert np.isfinite(m.predict(th)).all() and m._nonlinear.failures == []
    stack = fk.StackedKinetics(np.full((1, design.grid.n), np.nan), np.eye(design.grid.n)[None], None,
                               np.zeros(1), None, np.zeros(1))
    fails = []
    out = fk.stacked_batch(stack, np.eye(design.grid.n)[0], np.array([10.0]), failures=fails)
    assert np.isnan(out).all() and len(fails) == 1 and "stacked batch solve" in fails[0]


@pytest.mark.parametrize("form, extra", [("population", {"lam_pop": -1.0}), ("aggregation", {"beta0": 0.01})])
def test_standard_errors_do_not_depend_on_the_difference_step(monkeypatch, form, extra):
    """SEs from the Jacobian at the fitted optimum, with the default step (rtol^(1/3) x
    scale, rtol 1e-7), a step twice as long, and a step from a solve a hundred times
    tighter (rtol 1e-9): they agree to 1 % (their own sampling uncertainty with 96 values
    and 6 parameters is ~7 %; the differences are the O(h^2) truncation and the rtol/h
    noise, both ~1e-4 relative; measured: at most 8e-4 for a longer step, 3e-4 for the
    tighter solve)."""
    from millflow.falsify.nonlinear_truths import AggregationTruth
    from millflow.fitting.statistics import parameter_statistics

    design = batch_design([30.0 * 2 ** k for k in range(6)])
    truth = PopulationTruth(1.0) if form == "population" else AggregationTruth(0.01)
    clean = design.passing_at_sieves(truth.mass_fractions(design)).ravel()
    data = design.data(clean + 0.01 * np.random.default_rng(5).standard_normal(clean.size), design.sample_keys())
    spec = ModelSpec(mode="batch", kinetics=(form,))
    params = study_parameters(spec, {**BREAKAGE_TRUTH, **extra})
    model = ForwardModel(spec, data, design.grid)
    res = fit(model, params, global_search=False, starts=1, grid_check=False, quiet=True, profile=False)
    prob = check_problem(model, {n: Parameter(n, v.value, v.min, v.max) for n, v in res.params.items()})
    z = prob.full[prob.idx]

    def ses():
        J = prob.jac(z)
        st = parameter_statistics(prob.names, z, J, res.ssr, model.n_data, prob.lower, prob.upper)
        return np.array([st["params"][n]["se"] for n in prob.names])

    base = ses()
    model.fd_noise = 8 * fk.ODE_RTOL  # step x 2
    longer = ses()
    model.fd_noise = 1e-9  # the step of a solve at rtol 1e-9 ...
    monkeypatch.setattr(fk.stacked_batch, "__defaults__", (1e-9, 1e-12, None))  # ... and that solve
    tighter = ses()
    assert np.all(np.isfinite(base)) and np.all(base > 0)
    assert np.abs(longer / base - 1).max() < 0.01, (longer / base)
    assert np.abs(tighter / base - 1).max() < 0.01, (tighter / base)
