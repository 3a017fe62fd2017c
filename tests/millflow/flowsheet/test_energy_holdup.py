"""Mills driven by energy and hold-up: S_i = S_i^E P / H (Herbst and Fuerstenau 1980) with
tau = H / F, so S_i tau = S_i^E P / F: the product depends on the specific energy P / F and
the shape of the residence time distribution only."""
import json

import numpy as np
import pytest

from millflow.breakage.energy import T_PER_KWH, from_lab, time_rates
from millflow.breakage import PowerLawRate
from millflow.cli import main
from millflow.errors import InputError
from millflow.flowsheet import Flowsheet, load, solve, summary
from millflow.sweep import parse_vary, run_sweep
from tests import paths

CLOSED = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"


def open_mill(power_kW=1000.0, feed_tph=100.0, mill=None, rate=None):
    """One well-mixed mill, two classes and a sink: product of class 1 known exactly."""
    rate = rate or {"form": "power", "A_E_t_per_kWh": 0.8, "alpha": 1.0, "x0_um": 1000}
    m = {"type": "mill", "rate": rate, "power_kW": power_kW,
         "breakage": {"form": "normalized", "phi": 0.5, "gamma": 0.8, "beta": 3.0}}
    m.update(mill or {"holdup_t": 20})
    return Flowsheet.from_dict({
        # upper-edge values: the exact product below takes S at the edge (class averages: docs/core.md)
        "grid": {"top_um": 2000, "bottom_um": 500, "n": 3, "scheme": "upper_edge"},
        "units": {"feed": {"type": "feed", "solids_tph": feed_tph,
                           "psd": {"form": "ggs", "xmax_um": 2000, "m": 0.8}},
                  "mill": m, "product": {"type": "product"}},
        "streams": {"s1": {"from": "feed", "to": "mill"}, "s2": {"from": "mill", "to": "product"}}})


def test_time_rates_is_S_E_times_power_over_holdup():
    # 1 t/kWh in a mill drawing 3600 kW per t held breaks at 1 per second: exact in SI
    assert time_rates([T_PER_KWH], 3.6e6, 1000.0)[0] == pytest.approx(1.0, rel=1e-15)
    # a lab fit carried per energy and back in the lab mill returns the lab rate
    lab = PowerLawRate(0.02, 1.0, 1e-3)
    x = np.array([2e-3, 1e-3])
    np.testing.assert_allclose(from_lab(lab, 1500.0, 3.0).time_rates(x, 1500.0, 3.0), lab(x), rtol=1e-15)


@pytest.mark.parametrize("mill", [{"holdup_t": 20}, {"holdup_t": 3}, {"tau_min": 2}, {"tau_min": 40}],
                         ids=["holdup20", "holdup3", "tau2", "tau40"])
def test_perfect_mixing_top_class_is_exact(mill):
    # well mixed: top class leaves as m1 / (1 + S1 tau), S1 tau = S1^E P / F whatever H or tau
    P, F = 1000.0, 100.0
    fs = open_mill(P, F, mill)
    sol = solve(fs)
    x1 = fs.grid.x[0]
    s_tau = 0.8 * (x1 / 1e-3) * P / F  # t/kWh * kW / (t/h) = dimensionless
    feed1 = sol.flow("s1")[0]
    assert sol.flow("s2")[0] == pytest.approx(feed1 / (1 + s_tau), rel=1e-12)  # tear tol 1e-13


def test_equal_specific_energy_gives_equal_product_whatever_holdup():
    a = solve(open_mill(1000.0, 100.0, {"holdup_t": 20}))
    b = solve(open_mill(2500.0, 250.0, {"holdup_t": 4}))
    np.testing.assert_allclose(a.flow("s2") / 100.0, b.flow("s2") / 250.0, rtol=1e-11)


def test_per_energy_and_per_time_agree_at_the_operating_point():
    # S^E = S H / P: the per-time mill at H, P and the per-energy one give the same product
    A = 0.8 * 1000.0 / 20.0 / 60.0  # 1/min: S = S^E P / H with P = 1000 kW, H = 20 t
    per_time = open_mill(1000.0, 100.0, {"holdup_t": 20},
                         rate={"form": "power", "A_per_min": A, "alpha": 1.0, "x0_um": 1000})
    np.testing.assert_allclose(solve(per_time).flow("s2"), solve(open_mill()).flow("s2"), rtol=1e-11)


def _run(tmp_path, text, tag):
    p = tmp_path / f"{tag}.toml"
    p.write_text(text)
    out = tmp_path / f"{tag}-out"
    assert main(["run", str(p), "--json", "--no-plots", "--no-grid-check", "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


def _edit(text, **kw):
    for old, new in kw.values():
        assert old in text, old
        text = text.replace(old, new)
    return text


def test_cli_equal_kwh_per_t_gives_equal_product(tmp_path):
    """Herbst-Fuerstenau through the command line: power and feed x1.6, hold-up x0.5 -> same product."""
    text = CLOSED.read_text()
    base = _run(tmp_path, text, "base")
    scaled = _run(tmp_path, _edit(text, p=("power_kW = 3800", "power_kW = 6080"),
                                  f=("solids_tph = 250", "solids_tph = 400"),
                                  h=("holdup_t = 47.5 ", "holdup_t = 23.75 ")), "scaled")
    a, b = base["streams"]["overflow"], scaled["streams"]["overflow"]
    np.testing.assert_allclose(a["cum_passing"], b["cum_passing"], rtol=1e-10, atol=1e-12)  # tear tol 1e-13
    assert b["solids_tph"] == pytest.approx(1.6 * a["solids_tph"], rel=1e-10)
    assert (scaled["units"]["ball_mill"]["specific_energy_kWh_per_t"]
            == pytest.approx(base["units"]["ball_mill"]["specific_energy_kWh_per_t"], rel=1e-10))
    assert base["notes"] == []  # power drives breakage: no information-only note


def test_p80_rises_with_feed_and_falls_with_power():
    ds = run_sweep(CLOSED, [parse_vary("units.ball_mill.power_kW=2000:6000:3"),
                            parse_vary("units.fresh_feed.solids_tph=150:350:3")], scheduler="serial", progress=False)
    p80 = ds["p80_um"].sel(product="overflow").transpose("units.ball_mill.power_kW",
                                                          "units.fresh_feed.solids_tph").values
    assert np.all(np.diff(p80, axis=1) > 0)  # more feed at fixed power: coarser
    assert np.all(np.diff(p80, axis=0) < 0)  # more power at fixed feed: finer
    assert ds.attrs["n_failed"] == 0


def test_power_of_a_per_time_mill_is_information_only():
    text = CLOSED.read_text().replace("A_E_t_per_kWh = 0.675", "A_per_min = 0.9")
    from millflow.flowsheet import loads
    s1 = summary(solve(loads(text)))
    s2 = summary(solve(loads(text.replace("power_kW = 3800", "power_kW = 7600"))))
    assert len(s1["notes"]) == 1 and "information only" in s1["notes"][0] and "ball_mill" in s1["notes"][0]
    assert s1["units"]["ball_mill"]["power_role"].startswith("information only")
    # per-time rates: power changes only the printed kWh/t, not the product
    np.testing.assert_allclose(s1["streams"]["overflow"]["cum_passing"], s2["streams"]["overflow"]["cum_passing"],
                               rtol=1e-12)
    # but tau = H / F follows the feed rate: more feed, coarser product
    s3 = summary(solve(loads(text.replace("solids_tph = 250", "solids_tph = 300"))))
    assert s3["streams"]["overflow"]["p80_um"] > s1["streams"]["overflow"]["p80_um"]


def test_results_label_the_residence_time_and_basis(tmp_path):
    sol = solve(load(CLOSED))
    r = sol.units["ball_mill"]
    assert r["breakage_basis"].startswith("per energy") and r["tau_from"].startswith("solids hold-up")
    assert r["holdup_kg"] == pytest.approx(47.5e3, rel=1e-12)
    fixed = solve(open_mill(mill={"tau_min": 2})).units["mill"]
    assert fixed["tau_from"].startswith("fixed tau")


@pytest.mark.parametrize("edit, match", [
    (("power_kW = 3800 ", "#"), r"units\.ball_mill: the rates are per energy .*give the mill's power"),
    (("A_E_t_per_kWh = 0.675", "A_E_t_per_kWh = 0.675, A_per_min = 0.9"), r"A_E_t_per_kWh and A_per_min both give A"),
    (("A_E_t_per_kWh = 0.675", "A_E_t_per_MWh = 0.675"), r"unknown unit 't_per_MWh' for A_E"),
])
def test_bad_energy_inputs_are_one_line(tmp_path, capsys, edit, match):
    p = tmp_path / "bad.toml"
    p.write_text(CLOSED.read_text().replace(*edit))
    with pytest.raises(InputError, match=match):
        load(p)
    assert main(["run", str(p), "--no-plots", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("millflow run: error: ")


def test_material_per_energy_carries_a_lab_rate():
    rate = {"form": "power", "A_per_min": 1.2, "alpha": 1.0, "x0_um": 1000}
    doc = {"grid": {"top_um": 2000, "bottom_um": 500, "n": 3, "scheme": "upper_edge"},
           "materials": {"ore": {"rate": rate, "breakage": {"form": "normalized", "phi": 0.5, "gamma": 0.8,
                                                            "beta": 3.0},
                                 "per_energy": {"lab_power_kW": 0.5, "lab_holdup_kg": 10}}},
           "units": {"feed": {"type": "feed", "solids_tph": 100, "psd": {"form": "ggs", "xmax_um": 2000, "m": 0.8}},
                     "mill": {"type": "mill", "material": "ore", "holdup_t": 20, "power_kW": 1000},
                     "product": {"type": "product"}},
           "streams": {"s1": {"from": "feed", "to": "mill"}, "s2": {"from": "mill", "to": "product"}}}
    sol = solve(Flowsheet.from_dict(doc))
    # S1 = S_lab (P/H) / (P_lab/H_lab) = 1.2/min x (1000/20) / (0.5/0.01); tau = 20 t / 100 t/h
    x1 = sol.flowsheet.grid.x[0]
    s_tau = 1.2 * (x1 / 1e-3) * (1000 / 20) / (0.5 / 0.01) * (0.2 * 60)
    assert sol.flow("s2")[0] == pytest.approx(sol.flow("s1")[0] / (1 + s_tau), rel=1e-12)
