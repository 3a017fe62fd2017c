"""`millflow fit-rtd` on the example tracer file (TanksInSeries(12 min, 3), 2 % noise)."""
import json
from pathlib import Path

import pytest

from millflow.cli import main

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "tracer_tis.csv"


def test_fit_rtd_json_on_example(tmp_path, capsys):
    plot = tmp_path / "fit.png"
    code = main(["fit-rtd", str(EXAMPLE), "--model", "tis", "--json", "--out", str(plot)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and plot.stat().st_size > 1000
    assert {"model", "params", "ssr", "ser", "aic", "bic"} <= set(out)
    assert out["model"] == "tis" and out["time_unit"] == "min"
    tau, n = out["params"]["tau"], out["params"]["n"]
    assert set(tau) == {"value", "se"} and tau["se"] > 0 and n["se"] > 0
    # generating values tau = 12 min, n = 3; estimates within 3 standard errors
    assert abs(tau["value"] - 12.0) < 3 * tau["se"] and abs(n["value"] - 3.0) < 3 * n["se"]


@pytest.mark.parametrize("model, keys", [("ad-closed", {"tau", "pe"}), ("ad-open", {"tau", "pe"}),
                                          ("cells", {"tau", "n", "r", "dead", "bypass"}),
                                          ("cstr", {"tau"}), ("plug", {"tau"})])
def test_fit_rtd_other_models_and_text_output(tmp_path, capsys, model, keys):
    code = main(["fit-rtd", str(EXAMPLE), "--model", model, "--json", "--no-plot"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and set(out["params"]) == keys and out["plot"] is None
    assert main(["fit-rtd", str(EXAMPLE), "--model", model, "--no-plot"]) == 0
    text = capsys.readouterr().out
    assert "tau" in text and "AIC" in text


def test_default_plot_next_to_csv(tmp_path, capsys):
    csv = tmp_path / "run1.csv"
    csv.write_text(EXAMPLE.read_text())
    assert main(["fit-rtd", str(csv)]) == 0
    assert (tmp_path / "run1_fit.png").exists()


def test_bad_file_exits_2_naming_file_and_column(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,concentration\n0,0\n1,2\n0.5,1\n2,0\n")
    assert main(["fit-rtd", str(bad), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "time_s" in err and "row 3" in err
    assert main(["fit-rtd", str(tmp_path / "missing.csv")]) == 2
