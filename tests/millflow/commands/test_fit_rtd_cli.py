"""`millflow fit-rtd` on the example tracer file (TanksInSeries(12 min, 3), 2 % noise)."""
import json
import pytest

from millflow.cli import main
from tests import paths

EXAMPLE = paths.DOCS / "examples" / "tracer_tis.csv"


def test_fit_rtd_json_on_example(tmp_path, capsys):
    folder = tmp_path / "tis"
    code = main(["fit-rtd", str(EXAMPLE), "--model", "tis", "--json", "--out", str(folder)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and (folder / "fit.png").stat().st_size > 1000
    assert json.loads((folder / "fit.json").read_text()) == out  # --out is a folder: plot and JSON
    assert out["plot"] == str(folder / "fit.png")
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
    code = main(["fit-rtd", str(EXAMPLE), "--model", model, "--json", "--no-plots"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and set(out["params"]) == keys and out["plot"] is None
    assert main(["fit-rtd", str(EXAMPLE), "--model", model, "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "tau" in text and "AIC" in text


def test_default_folder_in_the_working_directory(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    csv = tmp_path / "run1.csv"
    csv.write_text(EXAMPLE.read_text())
    assert main(["fit-rtd", str(csv)]) == 0
    assert (tmp_path / "run1-rtd" / "fit.png").exists() and (tmp_path / "run1-rtd" / "fit.json").exists()
    # nothing written beside the CSV, and --no-plots without --out writes nothing
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run1-rtd", "run1.csv"]


def test_bad_file_exits_2_naming_file_and_column(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,concentration\n0,0\n1,2\n0.5,1\n2,0\n")
    assert main(["fit-rtd", str(bad), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "time_s" in err and "row 3" in err
    assert main(["fit-rtd", str(tmp_path / "missing.csv")]) == 2


def test_fit_rtd_with_inlet_column_and_step_file(tmp_path, capsys):
    import numpy as np

    import rtd
    t = np.linspace(0, 30, 151)
    inlet = rtd.TanksInSeries(1.0, 2).pdf(t)
    out = 2.0 * rtd.convolve_inlet(rtd.TanksInSeries(6.0, 2.5).cdf, t, inlet)
    pulse = tmp_path / "inlet.csv"
    pulse.write_text("time_s,concentration,inlet\n"
                     + "".join(f"{a},{b},{c}\n" for a, b, c in zip(t, out, inlet)))
    assert main(["fit-rtd", str(pulse), "--json", "--no-plots"]) == 0
    params = json.loads(capsys.readouterr().out)["params"]
    assert params["tau"]["value"] == pytest.approx(6.0, rel=1e-5)
    assert params["n"]["value"] == pytest.approx(2.5, rel=1e-5)
    step = tmp_path / "step.csv"
    f = rtd.AxialDispersion(4.0, 12.0).cdf(t)
    step.write_text("time_min,F\n" + "".join(f"{a},{b}\n" for a, b in zip(t, f)))
    assert main(["fit-rtd", str(step), "--model", "ad-closed", "--json", "--no-plots"]) == 0
    params = json.loads(capsys.readouterr().out)["params"]
    assert params["pe"]["value"] == pytest.approx(12.0, rel=1e-5)


def test_both_columns_on_the_command_line_is_one_line_exit_2(tmp_path, capsys):
    import numpy as np

    from millflow.cli import main

    t = np.linspace(0.0, 60.0, 61)
    path = tmp_path / "c.csv"
    path.write_text("time_min,concentration,F\n" + "".join(f"{a!r},{a * np.exp(-a / 10)!r},0.5\n" for a in t))
    assert main(["fit-rtd", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "both 'concentration' and 'F'" in err and "Traceback" not in err
