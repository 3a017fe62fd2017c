"""Reconciliation of plant surveys: exact cases, observability, bad inputs, outputs.

The statistical properties over replicates (chi-square, coverage, gross errors) are in
test_statistics.py (marked slow).
"""
import json
import math
from functools import lru_cache

import numpy as np
import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.flowsheet import load, solve
from millflow.survey import read_survey, reconcile
from millflow.survey.reader import ErrorModel, class_fractions
from millflow.survey.synthetic import grid_sieves, synthetic_survey
from tests import paths

EXAMPLE = paths.REPO / "examples" / "survey"


@lru_cache(maxsize=None)
def solved(name):
    return solve(load(paths.REPO / name))


def _noise_free(sol, sieves, **kw):
    """A survey whose measurements are the truth (error model SDs, zero noise)."""
    class Zero:
        def standard_normal(self, size=None):
            return 0.0 if size is None else np.zeros(size)
    return synthetic_survey(sol, sieves, Zero(), **kw)


def test_noise_free_survey_is_returned_exactly():
    """Measurements that already close every balance are not adjusted, SSR is 0 and the
    derived flows and circulating load equal the truth (to the solver's 1e-9 tolerance)."""
    sol = solved("examples/survey/circuit.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)
    survey, truth = _noise_free(sol, sieves, additions=["sump"])
    bal = reconcile(survey)
    assert bal.chi_square["ssr"] < 1e-12
    assert bal.balance_error < 1e-12
    np.testing.assert_allclose(bal.adjusted, bal.measured, atol=1e-9)
    for n in sol.flowsheet.stream_names:
        M, sd, ok = bal.solids(n)
        assert ok and sd > 0
        assert M == pytest.approx(truth["solids"][n], rel=1e-9)
        W, _, wok = bal.water(n)
        assert wok and W == pytest.approx(truth["water"][n], rel=1e-8)
        p, _, pok = bal.passing(n)
        np.testing.assert_allclose(p, truth["passing"][n], atol=1e-9)
    cl = bal.circulating_loads()["underflow"]
    assert cl[0] == pytest.approx(truth["circulating_load"]["underflow"], rel=1e-9)
    assert bal.addition("ball_mill")[0] == pytest.approx(sol.flowsheet.water_added["ball_mill"], rel=1e-8)


def test_adjusted_values_close_every_balance():
    sol = solved("flowsheets/closed_circuit_ball_mill.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 8, bottom=20e-6)
    survey, _ = synthetic_survey(sol, sieves, np.random.default_rng(3))
    bal = reconcile(survey)
    st = bal.structure
    # the balances are eliminated exactly: what is left is rounding of flows ~100 kg/s
    assert np.max(np.abs(st.A @ bal.z - st.b)) < 1e-10 * np.abs(bal.z).max()
    assert bal.chi_square["dof"] == st.y.size - bal.rank > 0
    # adjusted fractions of a stream's analysis sum to at most 1 (the pan takes the rest)
    assert bal.solids("fresh")[2] and bal.solids("underflow")[2]


def test_partly_unobservable_survey_says_so():
    """Without the overflow's % solids and the sump's water meter, the cyclone feed's and the
    overflow's water and the sump's addition are unobservable: reported, and given no value."""
    sol = solved("examples/survey/circuit.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)
    water = [n for n in sol.flowsheet.stream_names if n not in ("overflow", "cyclone_feed")]
    survey, truth = synthetic_survey(sol, sieves, np.random.default_rng(0), water=water)
    bal = reconcile(survey)
    bad = set(bal.observability()["unobservable"])
    assert {"streams.overflow.water_tph", "streams.cyclone_feed.water_tph", "water_additions.sump.water_tph"} <= bad
    assert "streams.underflow.water_tph" not in bad
    assert math.isnan(bal.water("overflow")[0]) and not bal.water("overflow")[2]
    assert bal.solids("overflow")[2]


def _write(tmp_path, text, name="survey.toml"):
    (tmp_path / "circuit.toml").write_text((EXAMPLE / "circuit.toml").read_text())
    p = tmp_path / name
    p.write_text('flowsheet = "circuit.toml"\n' + text)
    return p


PSD = "size_um = [2000, 1000, 500, 250, 125]\npassing_pct = [100, 80, 55, 30, 15]\n"


@pytest.mark.parametrize("text, message", [
    ("[streams.nowhere]\nsolids_tph = 10\n", "streams.nowhere: not a stream of the flowsheet"),
    ("[streams.fresh]\nsolids_tph = 250\nsolids_sd_tph = -2\n[streams.fresh.psd]\n" + PSD,
     "streams.fresh.solids_sd_tph = -2: expected a value >= 0"),
    ("[streams.fresh]\nsolids_tph = 250\n[streams.fresh.psd]\n" + PSD
     + "[streams.overflow.psd]\nsize_um = [2000, 1020, 500]\npassing_pct = [100, 90, 80]\n",
     "survey.toml: streams.overflow.psd: sieves do not nest: 1020 um is within 5 % of the 1000 um sieve"),
    ("[streams.fresh.psd]\n" + PSD + "[streams.overflow.psd]\n" + PSD, "unobservable system"),
    ("[streams.fresh]\nsolids_tph = 250\nsolids_sd_tph = 0\n[streams.fresh.psd]\n" + PSD
     + "[streams.overflow]\nsolids_tph = 240\nsolids_sd_tph = 0\n[streams.overflow.psd]\n" + PSD,
     "survey.toml: the exact values (SD 0)"),
    ("[streams.fresh]\nsolids = 250\n", "streams.fresh: unknown key solids"),
    ("[streams.fresh.psd]\nsize_um = [2000, 1000]\npassing_pct = [50, 80]\n", "passing rises"),
])
def test_bad_surveys_give_one_line_and_exit_2(tmp_path, capsys, text, message):
    p = _write(tmp_path, text)
    assert main(["balance", str(p), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and message in err, err
    assert not (tmp_path / "out").exists()


def test_balance_command_writes_everything_or_nothing(tmp_path, capsys):
    out = tmp_path / "bal"
    assert main(["balance", str(EXAMPLE / "survey.toml"), "--out", str(out), "--no-fit", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    for f in ("results.nc", "measurements.csv", "streams.csv", "passing.csv", "summary.json",
              "stream_overflow.png"):
        assert (out / f).is_file(), f
    assert s["chi_square"]["dof"] > 0 and s["observability"]["unobservable"] == []
    # the example plants an 8-point error in the underflow's % solids: it is the first candidate
    assert s["gross_error_candidates"][0]["measurement"] == "streams.underflow.solids_content_pct"
    import xarray as xr

    ds = xr.open_dataset(out / "results.nc", engine="scipy")
    assert set(ds["passing_adjusted"].dims) == {"stream", "size"}
    assert {"passing_measured", "passing_sd", "solids_adjusted", "solids_sd"} <= set(ds.data_vars)
    ds.close()
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    assert main(["balance", str(EXAMPLE / "survey.toml"), "--out", str(user), "--no-fit"]) == 2
    assert sorted(p.name for p in user.iterdir()) == ["notes.txt"]


def test_error_model_fraction_sd():
    e = ErrorModel(psd_sd=0.02, psd_floor=0.001)
    assert e.fraction_sd(0.5) == pytest.approx(0.021)
    assert e.fraction_sd(0.0) == pytest.approx(0.001)
    np.testing.assert_allclose(class_fractions([0.9, 0.5, 0.1]), [0.1, 0.4, 0.4, 0.1])


def test_reader_reads_the_example():
    s = read_survey(EXAMPLE / "survey.toml")
    assert s.streams["fresh"].solids == pytest.approx(s.streams["fresh"].solids)  # read, in kg/s
    assert s.streams["fresh"].solids * 3.6 > 200
    assert s.fit and "units.cyclones.d50c_um" in s.fit["names"]
    with pytest.raises(InputError, match="fit.parameters.units.cyclones.nothing"):
        from millflow.survey.fit import _get
        _get(s.flowsheet.meta["document"], "units.cyclones.nothing")


def test_agrees_with_a_direct_constrained_minimisation():
    """An independent solution of the same problem: scipy's SLSQP on the component flows with
    the balances as equality constraints (no elimination, no Gauss-Newton) reaches the same
    minimum. Tolerance 1e-6 relative on the SSR and 1e-4 of an SD on the adjusted values:
    SLSQP stops at ftol 1e-12 of an SSR ~ 10-50."""
    from scipy.optimize import minimize

    sol = solved("flowsheets/closed_circuit_ball_mill.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 32, bottom=100e-6)  # 2, 4 ... sieves: a small problem
    survey, _ = synthetic_survey(sol, sieves, np.random.default_rng(4))
    bal = reconcile(survey, reweight=0)
    st = bal.structure

    def ssr(z):
        return float(np.sum(((st.measure(z)[0] - st.y) / st.sd) ** 2))

    def grad(z):
        h, J = st.measure(z)
        return 2 * J.T @ ((h - st.y) / st.sd ** 2)

    z0 = bal.z * (1 + 0.02 * np.random.default_rng(0).standard_normal(bal.z.size))
    res = minimize(ssr, z0, jac=grad, method="SLSQP", options={"ftol": 1e-12, "maxiter": 2000},
                   constraints=[{"type": "eq", "fun": lambda z: st.A @ z - st.b, "jac": lambda z: st.A}])
    assert res.success, res.message
    assert res.fun == pytest.approx(bal.chi_square["ssr"], rel=1e-6)
    np.testing.assert_allclose(st.measure(res.x)[0], bal.adjusted, atol=1e-4 * st.sd.min())


def test_psd_from_a_feed_style_csv_equals_the_inline_one(tmp_path):
    """A sieve analysis as a CSV (retained_pct with a pan row, as feed CSVs) reads to the same
    cumulative passing as the inline passing_pct table."""
    (tmp_path / "of.csv").write_text("size_um,retained_pct\n2000,0\n1000,20\n500,25\n250,25\n125,15\n0,15\n")
    inline = _write(tmp_path, "[streams.fresh]\nsolids_tph = 250\n[streams.fresh.psd]\n" + PSD, "a.toml")
    csv = _write(tmp_path, "[streams.fresh]\nsolids_tph = 250\n[streams.fresh.psd]\nfile = \"of.csv\"\n", "b.toml")
    a, b = read_survey(inline).streams["fresh"].psd, read_survey(csv).streams["fresh"].psd
    np.testing.assert_allclose(a.sizes, b.sizes)
    np.testing.assert_allclose(a.passing, b.passing, atol=1e-12)


def test_redundancy_is_the_share_of_an_error_that_shows_in_its_own_adjustment():
    """r_i = 1 - H_ii against a direct measurement of it: a small error delta planted in one
    size fraction of a noise-free survey is adjusted by -r_i delta (linear regime), and the
    reported power of the test is the normal-tail formula at k sqrt(r_i)."""
    from scipy import stats

    sol = solved("flowsheets/closed_circuit_ball_mill.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 8, bottom=20e-6)
    base = reconcile(_noise_free(sol, sieves)[0])
    rows = base.structure.rows
    for stream, cls in [("underflow", 4), ("fresh", 2), ("overflow", 12), ("underflow", 10)]:
        i = next(j for j, r in enumerate(rows) if r["stream"] == stream and r["kind"] == "fraction"
                 and r["class"] == cls)
        bal = reconcile(_noise_free(sol, sieves, gross={"stream": stream, "class": cls, "sd": 1e-3})[0])
        delta = bal.measured[i] - base.measured[i]
        assert -bal.adjustment[i] / delta == pytest.approx(base.redundancy[i], rel=2e-3, abs=1e-5), stream
        c, r = base.threshold, base.redundancy[i]
        assert base.detection_power(10.0)[i] == pytest.approx(
            stats.norm.sf(c - 10 * math.sqrt(r)) + stats.norm.cdf(-c - 10 * math.sqrt(r)), rel=1e-12)
        # the error detectable with probability 0.9 is detected with (at least, the far tail) 0.9
        k90 = base.detectable_sd(0.9)[i]
        assert base.detection_power(k90)[i] == pytest.approx(0.9, abs=1e-6)
    # no error: the power is the false-alarm rate of one measurement, 2 sf(threshold)
    assert base.detection_power(0.0)[base.redundant] == pytest.approx(2 * stats.norm.sf(base.threshold))
    assert set(base.redundancy[~base.redundant]) <= {0.0}


def test_balance_reports_detectability(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["balance", str(EXAMPLE / "survey.toml"), "--out", str(out), "--no-fit", "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "a gross error of 10 SD would be detected with probability >= 0.9 in" in text
    s = json.loads((out / "summary.json").read_text())
    d = s["gross_error_detectability"]
    assert d["n_redundant"] + d["n_not_redundant"] == s["n_measured"]
    powers = [c["power"] for c in d["least_detectable"]]
    assert powers == sorted(powers)
    import pandas as pd

    m = pd.read_csv(out / "measurements.csv")
    assert {"redundancy", "power_10sd", "detectable_sd_90"} <= set(m.columns)
    assert d["n_detected_at_power"] == int((m["power_10sd"] >= 0.9).sum())
    assert m["power_10sd"].min() == pytest.approx(powers[0], rel=1e-6)


# ------------------------------------------------------------------ starts and physical solutions
def _without_solids(survey):
    """The survey with no solids flow measured (the weightometer missing): the flow scale must come
    from the water meter and the % solids either side of the sump."""
    import dataclasses

    streams = {n: dataclasses.replace(m, solids=None, solids_sd=None, solids_rel=None)
               for n, m in survey.streams.items()}
    return dataclasses.replace(survey, streams=streams)


def test_no_solids_meter_the_flows_follow_from_the_water_meter_and_the_pct_solids():
    """Fresh-feed solids flow removed, the sump's water meter kept: solvable (the meter and the
    % solids of the mill discharge and the cyclone feed fix the flow through the sump). The start
    derived from them reaches the physical minimum; over 20 replicates the fresh feed's 95 %
    interval covers the truth in >= 17 (binomial: P(< 17 | p = 0.95) = 1.6 %), every solution is
    physical and the chi-square test passes as often as it should (<= 4 of 20 rejected)."""
    from millflow.survey.reconcile import unphysical

    sol = solved("examples/survey/circuit.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=40e-6)[1:]
    errors = ErrorModel(solids_rel=0.02, water_rel=0.05, solids_content_sd=0.01, psd_sd=0.01, psd_floor=0.001)
    rng = np.random.default_rng(27)
    covered, rejected = 0, 0
    for _ in range(20):
        survey, truth = synthetic_survey(sol, sieves, rng, errors=errors, additions=["sump"])
        bal = reconcile(_without_solids(survey))
        assert unphysical(bal) == []
        M, sd, ok = bal.solids("fresh")
        assert ok and sd > 0
        covered += abs(M - truth["solids"]["fresh"]) <= 1.959964 * sd
        rejected += not bal.chi_square["passed"]
        content = bal.adjusted[[i for i, r in enumerate(bal.structure.rows) if r["kind"] == "solids_content"]]
        assert np.all((content > 0.3) & (content < 1.0))  # no % solids "adjusted" to 0
    assert covered >= 17, covered
    assert rejected <= 4, rejected


def test_a_poor_start_is_refused_not_reported(monkeypatch, tmp_path, capsys):
    """From the measured-or-typical start (1 kg/s where nothing is measured), the survey without a
    solids meter falls into a minimum with water flows of -1e8 t/h and every % solids adjusted to 0
    (SSR ~ 2e4): unphysical() names it; reconcile() keeps only physical solutions, and when none
    is reached says so in one line (exit 1 on the command line)."""
    import millflow.survey.start as start_mod
    from millflow.errors import SolverError
    from millflow.survey.reconcile import _particular, _solve_from, unphysical
    from millflow.survey.structure import build_structure

    survey = _without_solids(read_survey(EXAMPLE / "survey.toml"))
    st = build_structure(survey)
    z_p, N = _particular(st)
    bad = _solve_from(st, survey, z_p, N, start_mod.naive_start(st, survey), 100, 2,
                      st.sd.copy())
    problems = unphysical(bad)
    assert problems and "water" in problems[0], problems
    assert bad.chi_square["ssr"] > 1e3
    good = reconcile(survey)
    assert unphysical(good) == [] and good.chi_square["passed"]
    assert good.meta["start"].startswith("derived")

    monkeypatch.setattr(start_mod, "derived_start", lambda st, survey: None)
    with pytest.raises(SolverError, match="no physical solution from 1 starts") as exc:
        reconcile(survey)
    assert "\n" not in str(exc.value) and "water" in str(exc.value)
    text = (EXAMPLE / "survey.toml").read_text().replace("solids_tph = ", "# solids_tph = ")
    p = _write(tmp_path, text.replace('flowsheet = "circuit.toml"', ""))
    assert main(["balance", str(p), "--out", str(tmp_path / "out"), "--no-fit"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no physical solution" in err, err
    assert not (tmp_path / "out").exists()


def test_values_below_zero_within_their_errors_are_reported_not_clipped(tmp_path):
    """Adjusted class fractions a little below 0 (a nearly empty coarse class) are listed in
    summary.json's outside_physical_range with their values, and the adjusted values keep them."""
    out = tmp_path / "out"
    assert main(["balance", str(EXAMPLE / "survey.toml"), "--out", str(out), "--no-fit", "--no-plots"]) == 0
    s = json.loads((out / "summary.json").read_text())
    neg = s["outside_physical_range"]
    bal = reconcile(read_survey(EXAMPLE / "survey.toml"))
    st = bal.structure
    n_neg = int(np.sum(bal.z[: st.S * st.K] < 0))
    assert len([v for v in neg if v["quantity"].startswith("class")]) == n_neg
    assert all(v["value_pct"] < 0 for v in neg if "value_pct" in v)


# ------------------------------------------------------------------ sieve series
def _rebin(psd, sizes, truth_passing=None):
    """The analysis on the sieves ``sizes`` (a subset of its own, or with sieves whose true passing
    is given in ``truth_passing``), SDs from the error model."""
    from millflow.survey.reader import PSDMeasurement

    lookup = {round(x * 1e9): p for x, p in zip(psd.sizes, psd.passing)}
    lookup.update(truth_passing or {})
    passing = np.array([lookup[round(x * 1e9)] for x in sizes])
    e = ErrorModel()
    return PSDMeasurement(np.asarray(sizes), passing, e.fraction_sd(class_fractions(passing)), psd.sd_rule)


def test_analyses_on_different_ranges_of_one_series():
    """The underflow's analysis lacks the top sieve and adds a finer one (as c2c of the audit);
    the common series is the union, each analysis's classes are ranges of it. Noise-free: every
    flow is returned exactly (1e-9), SSR 0; the finer sieve is determined only for the underflow
    (and the streams the class balances tie to it), and observability names the others at that
    sieve instead of refusing the survey."""
    import dataclasses

    sol = solved("examples/survey/circuit.toml")
    sieves = grid_sieves(sol.flowsheet.grid, 2, bottom=30e-6)[1:]  # 5657 ... 31 um
    survey, truth = _noise_free(sol, sieves, additions=["sump"])
    streams = dict(survey.streams)
    for n, m in streams.items():
        keep = sieves[:-1] if n != "underflow" else sieves[1:]  # the others stop at 44 um
        streams[n] = dataclasses.replace(m, psd=_rebin(m.psd, keep))
    survey = dataclasses.replace(survey, streams=streams)
    bal = reconcile(survey)
    np.testing.assert_allclose(bal.structure.sieves, sieves)
    assert bal.chi_square["ssr"] < 1e-12
    for n in sol.flowsheet.stream_names:
        assert bal.solids(n)[0] == pytest.approx(truth["solids"][n], rel=1e-9)
    p, _, ok = bal.passing("underflow")
    assert ok.all()
    np.testing.assert_allclose(p, truth["passing"]["underflow"], atol=1e-9)
    bad = bal.observability()["unobservable"]
    assert f"streams.overflow.psd at {sieves[-1] * 1e6:.6g} um" in bad
    p, _, ok = bal.passing("overflow")
    assert ok[:-1].all() and not ok[-1]
    np.testing.assert_allclose(p[:-1], truth["passing"]["overflow"][:-1], atol=1e-9)


def test_a_near_duplicate_sieve_names_the_stream_that_brings_it(tmp_path, capsys):
    """4100 um in one analysis (which also has the most sieves) against 4000 um in five: the
    error names the underflow, which brings the odd sieve, and the survey file."""
    text = (EXAMPLE / "survey.toml").read_text()
    head, rest = text.split("[streams.underflow.psd]", 1)
    block, tail = rest.split("\n\n", 1)
    block = block.replace("size_um = [5657, 4000,", "size_um = [5657, 4100,").replace("44]", "44, 31]")
    block = block.replace("]\n", "]\n", 1)
    lines = block.strip().splitlines()
    lines[-1] = lines[-1].rstrip("]") + ", 4.0]"
    p = _write(tmp_path, (head + "[streams.underflow.psd]\n" + "\n".join(lines) + "\n\n" + tail).replace(
        'flowsheet = "circuit.toml"', ""))
    assert main(["balance", str(p), "--out", str(tmp_path / "out"), "--no-fit"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "survey.toml: streams.underflow.psd: sieves do not nest: 4100 um" in err, err


def test_an_absurd_ssr_is_refused_naming_the_largest_adjustments(tmp_path, capsys):
    """SDs understated 20-fold (psd_sd 0.05 % instead of 1 %, floor 0.005 %): the weighted SSR
    grows ~400-fold, beyond 100 per degree of freedom, which no single gross error explains; the
    balance is refused in one line naming the largest normalised adjustments (exit 2), not
    printed as a result."""
    text = (EXAMPLE / "survey.toml").read_text()
    text = text.replace("psd_sd_pct = 1 ", "psd_sd_pct = 0.05 ")
    text = text.replace("psd_floor_pct = 0.1 ", "psd_floor_pct = 0.005 ")
    assert "psd_sd_pct = 0.05" in text and "psd_floor_pct = 0.005" in text
    p = _write(tmp_path, text.replace('flowsheet = "circuit.toml"', ""))
    assert main(["balance", str(p), "--out", str(tmp_path / "out"), "--no-fit"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "survey.toml: the measurements contradict each other far beyond their SDs" in err, err
    assert "largest normalised adjustments: streams." in err
    assert not (tmp_path / "out").exists()
