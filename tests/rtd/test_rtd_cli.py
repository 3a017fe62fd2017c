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
    # --quiet hides progress only (one meaning everywhere): the fit still prints
    assert r.returncode == 0 and "cstr" in r.stdout and r.stderr == ""


def test_rtd_tests_import_nothing_from_millflow():
    for path in HERE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("millflow", "tests") for n in names), (path, names)


def _five_cell_curve(path):
    import numpy as np

    import rtd

    t = np.linspace(0.0, 60.0, 121)
    c = rtd.RecirculatingCells(10.0, 5, r=0.5).pdf(t)
    path.write_text("time_min,concentration\n" + "".join(f"{a:.10g},{b:.12g}\n" for a, b in zip(t, c)))
    return path


def test_cells_reach_the_model_for_every_alias(tmp_path, capsys):
    # --cells used to reach the model only for the alias "cells": n = 3 was fitted to a
    # 5-cell curve through "recirculating_cells"
    csv = _five_cell_curve(tmp_path / "five.csv")
    for name in ("recirculating_cells", "cells", "RecirculatingCells"):
        assert main(["fit", str(csv), "--model", name, "--cells", "5", "--json", "--no-plots",
                     "--out", str(tmp_path / name)]) == 0
        js = json.loads(capsys.readouterr().out)
        assert "n=5" in js["repr"].replace(" ", "")
        # noise-free data of the same model: the fit recovers tau and r
        assert abs(js["params"]["tau"]["value"] - 10.0) < 1e-4
        assert abs(js["params"]["r"]["value"] - 0.5) < 1e-3


def test_cells_for_another_model_is_refused(tmp_path, capsys):
    csv = _five_cell_curve(tmp_path / "five.csv")
    assert main(["fit", str(csv), "--model", "tis", "--cells", "5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--cells 5" in err


def test_duplicated_column_is_refused(tmp_path, capsys):
    bad = tmp_path / "dup.csv"
    bad.write_text("time_s,concentration,concentration\n0,0,0\n1,2,5\n2,1,3\n3,0,0\n")
    assert main(["fit", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'concentration' appears twice" in err

