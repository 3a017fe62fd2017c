"""report.html of `millflow fit`, `scaleup`, `compare` and `sweep` at the run report's
standard: one self-contained page that names the JSON file of its folder its numbers come
from (fit.json, scaleup.json, compare.json, summary.json), every number shown equal to
that file's at the digits shown, the input files with their SHA-256, plots as inline SVG,
and it renders in headless Chromium without console errors or overlapping boxes."""
import hashlib
import json
import re

import numpy as np
import pytest
import xarray as xr

from millflow.cli import main
from millflow.report.studies import scaleup_report
from tests import paths
from tests.millflow.report.test_report import Cells, check_numbers, render

LAB_FIT = paths.EXAMPLES / "scaleup" / "lab_fit.toml"
PLANT = paths.EXAMPLES / "scaleup" / "plant.toml"


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _page(folder, source):
    """The page's text, the JSON file it names (loaded), and how many numbers match it."""
    text = (folder / "report.html").read_text(encoding="utf-8")
    assert f'<body data-source="{source}">' in text
    assert f'<script type="application/json" id="summary" data-source="{source}">' in text
    data = json.loads((folder / source).read_text(encoding="utf-8"))
    assert "http://" not in text.replace('xmlns="http://www.w3.org/2000/svg"', "") and "https://" not in text
    return text, data, check_numbers(text, data)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "fit"
    assert main(["fit", str(LAB_FIT), "--quiet", "--out", str(out)]) == 0
    return out


def test_fit_report_shows_fit_json(fitted):
    text, js, n = _page(fitted, "fit.json")
    assert n >= 5 * len(js["params"])  # value, SE, p (or -), both interval ends per parameter
    assert "data:image/png" not in text  # plots are SVG, drawn from the fit's numbers
    assert text.count('<svg xmlns="http://www.w3.org/2000/svg" class="plot"') == 3  # two conditions and the parity
    for f in (LAB_FIT, LAB_FIT.parent / "lab_psd.csv", LAB_FIT.parent / "lab_process.csv"):
        assert _sha(f) in text  # the config and the data files it reads, with their SHA-256
    assert check_numbers(render(fitted / "report.html"), js) == n


@pytest.fixture(scope="module")
def scaled(fitted, tmp_path_factory):
    out = tmp_path_factory.mktemp("scaleup") / "plant"
    fit_json = fitted / "fit.json"
    assert main(["scaleup", str(fit_json), "--to", str(PLANT), "--target-p80-um", "200", "--band-method", "delta",
                 "--quiet", "--no-plots", "--out", str(out)]) == 0
    return out, fit_json


def test_scaleup_report_shows_circuit_contributions_and_both_inputs(scaled):
    out, fit_json = scaled
    text, s, n = _page(out, "scaleup.json")
    assert _sha(PLANT) in text and _sha(fit_json) in text  # the plant file and the lab fit
    c = s["circuit"]
    assert set(c["streams"]) == {"fresh_feed", "mill_feed", "mill_discharge", "classifier_coarse", "product"}
    # the circuit at the estimate closes: product = fresh feed, recycle / fresh = the circulating load
    assert c["streams"]["product"]["solids_tph"] == pytest.approx(s["feed_tph"], rel=1e-9)
    assert c["streams"]["classifier_coarse"]["solids_tph"] / s["feed_tph"] == pytest.approx(s["circulating_load"],
                                                                                            rel=1e-9)
    assert c["streams"]["product"]["p80_um"] == pytest.approx(s["p80_um"], rel=1e-9)
    assert c["units"]["mill"]["tau_s"] == pytest.approx(s["tau_s"], rel=1e-9)
    p = Cells()
    p.feed(text)
    keys = {k for k, _, _ in p.cells}
    for src in s["model_form"]["contributions"]:  # each contribution is in the page's table, not only in the JSON
        assert f"model_form.contributions.{src}.half_width" in keys
    for name in c["streams"]:
        assert f"circuit.streams.{name}.solids_tph" in keys and f"circuit.streams.{name}.p80_um" in keys
    assert "circuit.units.mill.power_kW" in keys and 'class="flowsheet"' in text
    assert "specific_energy_kWh_per_t" in s and "specific_energy_kWh_t" not in s  # one name in every file
    assert n >= 40
    assert check_numbers(render(out / "report.html"), s) == n


def test_scaleup_report_numbers_and_bands():
    x = np.geomspace(2e-3, 1e-5, 30)
    passing = np.linspace(1.0, 0.05, 30)
    ds = xr.Dataset({"passing": ("size", passing), "feed_passing": ("size", passing ** 2),
                     "passing_lo": (("estimator", "size"), [passing - 0.01]),
                     "passing_hi": (("estimator", "size"), [np.minimum(passing + 0.01, 1.0)])},
                    coords={"x": ("size", x), "estimator": ["delta"]})
    s = {"title": "plant", "fit": "fit.json", "scaling": "austin", "power_model": "bond", "feed_tph": 100.0,
         "p80_um": 150.6123, "power_net_kW": 1416.2, "specific_energy_kWh_per_t": 14.159, "tau_s": 262.93,
         "circulating_load": 1.3421, "mass_balance": 3e-16, "target_p80_um": 150.0, "throughput_tph": 99.2871,
         "bands": {"p80_um": {"delta": {"lo": 144.93, "hi": 156.41}},
                   "throughput_tph": {"delta": {"lo": 92.75, "hi": 105.8}}}}
    text = scaleup_report(s, ds)
    assert check_numbers(text, s) == 13  # 8 quantities given, the circulating load in %, 2 bands x 2 ends
    p = Cells()
    p.feed(text)
    shown = {k: v for k, _, v in p.cells}
    assert shown["circulating_load"] == "134.2" and shown["bands.p80_um.delta.hi"] == "156.4"


def test_compare_report_shows_compare_json(tmp_path, capsys):
    out = tmp_path / "cmp"
    a, b = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml", paths.FLOWSHEETS / "closed_circuit_wet_cyclones.toml"
    assert main(["compare", str(a), str(b), "--json", "--no-plots", "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    text, js, n = _page(out, "compare.json")
    assert printed == js
    assert _sha(a) in text and _sha(b) in text
    assert text.count('class="flowsheet"') == 2 and text.count('<table class="units">') == 2
    wet = [r for r in js["streams"] if r["water_tph_b"] is not None]
    assert wet and all(r["water_tph_a"] is None for r in js["streams"])  # B is wet, A dry
    p = Cells()
    p.feed(text)
    keys = {k for k, _, _ in p.cells}
    k = js["streams"].index(wet[0])
    assert {f"streams.{k}.water_tph_b", f"streams.{k}.solids_content_pct_b"} <= keys
    assert "summaries.b.units.ball_mill.power_kW" in keys
    assert n >= 9 * len(js["streams"]) + len(js["summaries"]["a"]["units"]) + len(js["summaries"]["b"]["units"])
    assert check_numbers(render(out / "report.html"), js) == n


@pytest.mark.parametrize("vary", [["units.ball_mill.power_kW=3000:4600:3", "units.fresh_feed.solids_tph=150:300:2"],
                                  ["units.ball_mill.power_kW=3000:4600:4"]])
def test_sweep_report_plots_outputs_against_each_key(tmp_path, vary):
    out = tmp_path / "sw"
    argv = ["sweep", str(paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"), "--scheduler", "serial",
            "--no-plots", "--quiet", "--json", "--out", str(out)]
    for v in vary:
        argv += ["--vary", v]
    assert main(argv) == 0
    import pandas as pd

    cases = pd.read_csv(out / "sweep.csv")
    text, summary, n = _page(out, "summary.json")
    assert len(summary["rows"]) == len(cases) == summary["n_rows"]
    assert n >= 4 * len(cases)  # power, P80, P50, circulating load ... of each case
    j = summary["columns"].index("p80_um")
    for k in range(len(cases)):  # the page's rows are the CSV's (6 digits there)
        assert summary["rows"][k][j] == pytest.approx(cases["p80_um"][k], rel=1e-5)
    plots = re.findall(r'<svg xmlns="http://www.w3.org/2000/svg" class="plot"[^>]*aria-label="([^"]*)"', text)
    # P80, P50, circulating load and kWh/t against each varied key
    assert len(plots) == 4 * len(vary)
    assert _sha(paths.FLOWSHEETS / "closed_circuit_ball_mill.toml") in text
    assert check_numbers(render(out / "report.html"), summary) == n
