"""report.html of `millflow fit` and `millflow scaleup`: the numbers shown are those of
the JSON the command prints (`--json`), and the page is one self-contained file."""
import json

import numpy as np
import pytest
import xarray as xr

from millflow.cli import main
from millflow.report.studies import scaleup_report
from tests import paths
from tests.millflow.report.test_report import Cells, check_numbers, render


def test_fit_report_shows_the_fit_json(tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit", str(paths.EXAMPLES / "scaleup" / "lab_fit.toml"), "--json", "--quiet", "--out", str(out)]) == 0
    js = json.loads(capsys.readouterr().out)
    text = (out / "report.html").read_text()
    n = check_numbers(text, js)
    assert n >= 5 * len(js["params"])  # value, SE, p (or -), both interval ends per parameter
    assert text.count("data:image/png;base64,") == 2  # fit_psd.png and parity.png inside the page
    assert "https://" not in text
    assert check_numbers(render(out / "report.html"), js) > 0


def test_scaleup_report_numbers_and_bands():
    x = np.geomspace(2e-3, 1e-5, 30)
    passing = np.linspace(1.0, 0.05, 30)
    ds = xr.Dataset({"passing": ("size", passing), "feed_passing": ("size", passing ** 2),
                     "passing_lo": (("estimator", "size"), [passing - 0.01]),
                     "passing_hi": (("estimator", "size"), [np.minimum(passing + 0.01, 1.0)])},
                    coords={"x": ("size", x), "estimator": ["delta"]})
    s = {"title": "plant", "fit": "fit.json", "scaling": "austin", "power_model": "bond", "feed_tph": 100.0,
         "p80_um": 150.6123, "power_net_kW": 1416.2, "specific_energy_kWh_t": 14.159, "tau_s": 262.93,
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
    assert main(["compare", str(paths.FLOWSHEETS / "open_circuit_ball_mill.toml"),
                 str(paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"), "--json", "--no-plots",
                 "--out", str(out)]) == 0
    js = json.loads(capsys.readouterr().out)
    text = (out / "report.html").read_text()
    assert check_numbers(text, js) >= 8 * len(js["streams"])
    assert text.count('class="flowsheet"') == 2
    assert check_numbers(render(out / "report.html"), js) > 0  # as the browser shows it


def test_sweep_report_shows_every_case(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", str(paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"), "--vary",
                 "units.ball_mill.power_kW=3000:4600:3", "--scheduler", "serial", "--no-plots", "--quiet", "--json",
                 "--out", str(out)]) == 0
    import pandas as pd

    cases = pd.read_csv(out / "sweep.csv")
    text = (out / "report.html").read_text()
    blob = json.loads(text.split('<script type="application/json" id="summary">')[1].split("</script>")[0])
    assert len(blob["cases"]) == len(cases) == 3
    n = check_numbers(text, blob)
    assert n >= 3 * 4  # power, P80, P50, circulating load ... of each case
    j = blob["columns"].index("p80_um")
    for k in range(3):  # the page's cases are the CSV's (6 digits there)
        assert blob["cases"][k][j] == pytest.approx(cases["p80_um"][k], rel=1e-5)
