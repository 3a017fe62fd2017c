"""`python -m rtd fit`: the tracer fit on its own (this file, like all of tests/rtd,
imports nothing from millflow)."""
import ast
import json
import pathlib
import subprocess
import sys

from rtd.cli import main

HERE = pathlib.Path(__file__).resolve().parent
EXAMPLE = HERE.parents[1] / "docs" / "examples" / "tracer_tis.csv"


def test_fit_prints_estimates_and_writes_the_folder(tmp_path, capsys):
    out = tmp_path / "tis"
    assert main(["fit", str(EXAMPLE), "--json", "--out", str(out)]) == 0
    js = json.loads(capsys.readouterr().out)
    # generating values tau = 12 min, n = 3 (docs/examples/tracer_tis.csv); within 3 SE
    assert abs(js["params"]["tau"]["value"] - 12.0) < 3 * js["params"]["tau"]["se"]
    assert json.loads((out / "fit.json").read_text()) == js and (out / "fit.png").stat().st_size > 1000
    (out / "mine.txt").write_text("x")
    assert main(["fit", str(EXAMPLE), "--out", str(out)]) == 2  # a folder with other files is refused
    assert "--overwrite" in capsys.readouterr().err and (out / "mine.txt").exists()


def test_bad_file_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,concentration\n0,0\n1,2\n0.5,1\n2,0\n")
    assert main(["fit", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.csv" in err and "time_s" in err


def test_python_dash_m_rtd_runs():
    r = subprocess.run([sys.executable, "-m", "rtd", "fit", str(EXAMPLE), "--model", "cstr", "--quiet"],
                       capture_output=True, text=True, cwd=HERE.parents[1], timeout=120)
    assert r.returncode == 0 and r.stdout == "" and r.stderr == ""


def test_rtd_tests_import_nothing_from_millflow():
    for path in HERE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("millflow", "tests") for n in names), (path, names)


def _cells_curve(tmp_path, n, tau=8.0, r=1.5):
    import numpy as np

    import rtd

    t = np.linspace(0.0, 6 * tau, 121)[1:]
    c = rtd.RecirculatingCells(tau, n, r).pdf(t)
    path = tmp_path / f"cells{n}.csv"
    path.write_text("time_min,concentration\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, c)))
    return path


def test_cells_option_reaches_the_model_under_every_name(tmp_path, capsys):
    # a noise-free 5-cell curve: --cells 5 must fix n = 5 under the canonical name as under
    # the alias, and then the fit recovers tau and r (to the fit's tolerance, 1e-4)
    path = _cells_curve(tmp_path, 5)
    for name in ("recirculating_cells", "cells"):
        assert main(["fit", str(path), "--model", name, "--cells", "5", "--json"]) == 0
        js = json.loads(capsys.readouterr().out)
        assert js["params"]["n"] == {"value": 5.0, "se": None}, js  # fixed, not fitted
        assert abs(js["params"]["tau"]["value"] - 8.0) < 1e-4 * 8.0
        assert abs(js["params"]["r"]["value"] - 1.5) < 1e-3


def test_cells_option_is_refused_for_a_model_without_cells(tmp_path, capsys):
    path = _cells_curve(tmp_path, 3)
    assert main(["fit", str(path), "--model", "tis", "--cells", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--cells 4" in err and "'tis' has no cells" in err
