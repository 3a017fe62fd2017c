"""Flowsheets: every example solves with closed mass balances; circulating load vs the
independent two-product formula; nonlinear tearing; outputs; CLI; exit check."""
import json
import math

import numpy as np
import pytest

from millflow.cli import main
from millflow.errors import SolverError
from millflow.flowsheet import circulating_loads, load, loads, save, solve, summary
from millflow.flowsheet.results import mass_balance, stream_properties
from millflow.psd import cum_passing
from tests import paths
from tests.closed_circuit import per_time_text

FLOWSHEETS = paths.FLOWSHEETS
EXAMPLES = sorted(FLOWSHEETS.glob("*.toml"))
CLOSED = FLOWSHEETS / "closed_circuit_ball_mill.toml"


def test_all_required_examples_exist():
    names = {p.stem for p in EXAMPLES}
    assert {"open_circuit_ball_mill", "closed_circuit_ball_mill", "cement_two_compartment_mill",
            "stirred_mill_recirculation", "hammer_mill_screen"} <= names


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_mass_balance(path):
    sol = solve(load(path))
    mb = mass_balance(sol)
    # one sparse LU + one refinement step: the residual is a few ulp of the largest flow,
    # so 1e-12 leaves a margin of ~1e3 over rounding; a circuit torn on a mill's inlet vector
    # (non-linear kinetics) balances to its tear: a relative change of tol per class, summed
    tear = sol.solver.get("tear") or {}
    limit = 1e-12 if tear.get("torn") != "inlet flow vector" else max(1e-12, tear["tolerance"] * sol.flowsheet.grid.n)
    assert mb["overall"] < limit
    assert max(mb["units"].values()) < limit
    assert np.all(sol.flows >= -1e-12 * sol.flows.max())
    # mass balance per unit also holds class by class where no breakage happens
    fs = sol.flowsheet
    for name, unit in fs.units.items():
        if unit.type in ("classifier", "mixer", "splitter"):
            fin = sum(sol.flow(s) for s in fs.inlets(name))
            fout = sum(sol.flow(s) for s in fs.outlets(name))
            np.testing.assert_allclose(fout, fin, rtol=0, atol=1e-12 * fin.sum())


def _two_product(f, u, o):
    """U/O from the cumulative passing of feed f, coarse u and fine o (least squares over sizes)."""
    return np.sum((f - o) * (u - f)) / np.sum((u - f) ** 2)


@pytest.mark.parametrize("path,stream,feed,coarse,fine", [
    (CLOSED, "underflow", "mill_discharge", "underflow", "overflow"),
    (FLOWSHEETS / "cement_two_compartment_mill.toml", "rejects", "mill_discharge", "rejects", "fines"),
])
def test_circulating_load_two_product_formula(path, stream, feed, coarse, fine):
    """Recycle / new feed equals U/O at steady state (O = new feed): the two-product formula."""
    sol = solve(load(path))
    f, u, o = (cum_passing(sol.flow(s) / sol.flow(s).sum()) for s in (feed, coarse, fine))
    C = _two_product(f, u, o)
    assert circulating_loads(sol)[stream] == pytest.approx(C, rel=1e-9)
    assert 1.0 < C < 5.0


def test_closed_circuit_holdup_is_torn_and_matches_linear():
    text = per_time_text().replace("tau_min = 3.5", "holdup_t = 45")
    fs = loads(text)
    results = {}
    for method in ("wegstein", "newton", "substitution"):
        sol = solve(fs, method=method)
        assert sol.solver["tear"]["converged"]
        results[method] = sol
    sol = results["wegstein"]
    tau_min = float(45.0 / (sol.flow("mill_feed").sum() * 3.6) * 60)
    lin = solve(loads(per_time_text().replace("tau_min = 3.5", f"tau_min = {tau_min!r}")))
    assert lin.solver["tear"] is None
    np.testing.assert_allclose(sol.flows, lin.flows, rtol=0, atol=1e-9 * lin.flows.max())
    np.testing.assert_allclose(results["newton"].flows, sol.flows, rtol=0, atol=1e-9 * lin.flows.max())
    assert mass_balance(sol)["overall"] < 1e-12


def test_no_exit_loop_names_the_loop():
    # the mill does not break (A = 0) and the screen returns all coarse material exactly
    text = per_time_text().replace("A_per_min = 0.9", "A_per_min = 0").replace(
        'curve = "whiten"\nd50c_um = 140\nalpha = 3.0\nbeta = 0.0                  # > 0 gives a fish-hook\n'
        'bypass = 0.30               # water split to underflow, R_f', 'curve = "screen"\nd50_um = 300\nm = 8')
    assert 'curve = "screen"' in text
    with pytest.raises(SolverError, match=r"can never leave the loop .*ball_mill.*cyclones.*underflow"):
        solve(loads(text))


def test_save_outputs(tmp_path):
    sol = solve(load(CLOSED))
    files = save(sol, tmp_path / "out")
    for name in ("results.nc", "streams.csv", "units.csv", "psd.csv", "summary.json", "psd.png",
                 "classifiers.png", "flowsheet.png"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    import xarray as xr

    with xr.open_dataset(files["netcdf"], engine="scipy") as ds:
        assert ds["mass_flow"].dims == ("stream", "size")
        assert ds["mass_flow"].attrs["units"] == "kg/s"
        np.testing.assert_allclose(ds["mass_flow"].values, sol.flows)
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["streams"]["overflow"]["solids_tph"] == pytest.approx(250.0, rel=1e-12)


def test_cli_json(tmp_path, capsys):
    code = main(["run", str(CLOSED), "--json", "--no-plots", "--out", str(tmp_path / "res")])
    assert code == 0
    s = json.loads(capsys.readouterr().out)
    for key in ("streams", "circulating_load", "mass_balance_error", "runtime_s"):
        assert key in s
    ov = s["streams"]["overflow"]
    assert set(ov) >= {"solids_tph", "p80_um", "size_um", "cum_passing"}
    assert len(ov["size_um"]) == len(ov["cum_passing"])
    assert 50 < ov["p80_um"] < 200
    assert s["mass_balance_error"] < 1e-12
    assert (tmp_path / "res" / "results.nc").exists()


def test_cli_table_and_error(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(CLOSED), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "P80 um" in out and "circulating load (recycle / new feed): underflow" in out
    assert "closed_circuit_ball_mill-results" in out
    assert (tmp_path / "closed_circuit_ball_mill-results" / "summary.json").exists()
    # the files line names what was written, and only that: no plots with --no-plots
    listed = out.split("results written to ")[1].split("(")[1].rstrip(")\n").split(", ")
    written = sorted(p.name for p in (tmp_path / "closed_circuit_ball_mill-results").iterdir())
    assert sorted(listed + [".millflow-manifest.json"]) == written  # and millflow's manifest
    assert not any(name.endswith(".png") for name in listed)
    bad = tmp_path / "bad.toml"
    bad.write_text(CLOSED.read_text().replace('type = "hydrocyclone"', 'type = "cyclone"'))
    assert main(["run", str(bad), "--no-plots"]) == 2
    assert "units.cyclones.type" in capsys.readouterr().err


def test_stream_properties_p80_matches_psd():
    from millflow.psd import p80

    sol = solve(load(CLOSED))
    props = stream_properties(sol)
    f = np.maximum(sol.flow("overflow"), 0.0)  # rounding-level negatives (~1e-21) of the linear solve
    assert props["overflow"]["p80_m"] == pytest.approx(p80(sol.flowsheet.grid, f / f.sum()), rel=1e-12)
    s = summary(sol)
    assert math.isfinite(s["specific_energy_kWh_per_t"])
    assert s["specific_energy_kWh_per_t"] == pytest.approx(3800 / 250, rel=1e-12)


def test_python_api_without_toml():
    # the same objects the file reader builds, in SI units
    from millflow.breakage import NormalizedBreakage, PowerLawRate
    from millflow.errors import InputError
    from millflow.flowsheet import Classifier, Feed, Flowsheet, MillUnit, Mixer, Product, Splitter, Stream
    from millflow.grid import SizeGrid

    grid = SizeGrid.geometric(4e-3, 2 ** 0.5, 20)
    feed = np.zeros(grid.n)
    feed[:3] = [0.2, 0.5, 0.3]
    units = {
        "f": Feed("f", 10.0, feed), "mix": Mixer("mix"),
        "mill": MillUnit("mill", PowerLawRate(0.02, 1.0, 1e-3), NormalizedBreakage(0.5, 0.8, 3.0),
                     "tanks_in_series", {"n": 3}, tau=300.0),
        "cyc": Classifier("cyc", "hydrocyclone", "whiten", {"d50c": 2e-4, "alpha": 2.0, "beta": 0.4, "bypass": 0.2}),
        "split": Splitter("split", {"back": 0.3, "out": 0.7}), "p": Product("p"),
    }
    streams = {n: Stream(n, *rest) for n, *rest in [
        ("s1", "f", "out", "mix"), ("s2", "mix", "out", "mill"), ("s3", "mill", "out", "cyc"),
        ("s4", "cyc", "underflow", "mix"), ("s5", "cyc", "overflow", "split"), ("s6", "split", "back", "mix"),
        ("s7", "split", "out", "p")]}
    sol = solve(Flowsheet(grid, units, streams))
    assert sol.flow("s7").sum() == pytest.approx(10.0, rel=1e-13)
    assert set(circulating_loads(sol)) == {"s4", "s6"}  # the recycle streams
    assert circulating_loads(sol)["s6"] == pytest.approx(0.3 * sol.flow("s5").sum() / 10.0, rel=1e-12)
    with pytest.raises(InputError, match="fractions summing to 1"):
        Splitter("s", {"a": 0.5, "b": 0.6})
    with pytest.raises(InputError, match="exactly one of tau"):
        MillUnit("m", PowerLawRate(0.02, 1.0), NormalizedBreakage(0.5, 0.8, 3.0))


def test_nearly_closed_loop_is_reported():
    # a splitter sending all but 1e-14 back: the loop gain is 1 to rounding for every size
    text = CLOSED.read_text().replace('overflow = {from = "cyclones.overflow", to = "overflow_product"}',
                                      'overflow = {from = "cyclones.overflow", to = "bleed"}\n'
                                      'back = {from = "bleed.back", to = "chute"}\n'
                                      'out = {from = "bleed.out", to = "overflow_product"}')
    text += '\n[units.bleed]\ntype = "splitter"\nfractions = {back = 1.0, out = 0.0}\n'
    with pytest.raises(SolverError, match=r"can never leave the loop .*bleed"):
        solve(loads(text))
