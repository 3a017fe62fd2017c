"""One meaning per flag (docs/cli.md): --quiet hides progress only, --method is gone where
two methods were meant (--tear-method in run, --band-method in scaleup, the old name a
deprecated alias), one default output folder (<input stem>-<kind> in the current folder),
fit-rtd's moments, model comparison and parameters at a bound, compare's and fit's tables."""
import json

import pytest

from millflow.cli import build_parser, main
from millflow.commands.output import QUIET_HELP
from tests import paths

OPEN = paths.FLOWSHEETS / "open_circuit_ball_mill.toml"
CLOSED = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"
AGG = paths.FLOWSHEETS / "stirred_mill_recirculation.toml"  # non-linear: solved by tearing
TRACER = paths.DOCS / "examples" / "tracer_tis.csv"
# Levenspiel, Chemical Reaction Engineering, 3rd ed., example 11.1: a pulse read every 5 min;
# mean 15 min, variance 47.5 min^2 (his sums over equal intervals = trapezoids with c = 0 at the ends)
LEVENSPIEL = "time_min,concentration\n0,0\n5,3\n10,5\n15,5\n20,4\n25,2\n30,1\n35,0\n"


def _options(name):
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return {o: a for a in sub.choices[name]._actions for o in a.option_strings}


@pytest.mark.parametrize("name", ["run", "fit", "fit-rtd", "scaleup", "sweep", "compare", "falsify", "balance",
                                  "diagnose", "bench"])
def test_quiet_has_one_meaning(name):
    opts = _options(name)
    assert opts["--quiet"].help == QUIET_HELP  # the same words in every command


def test_method_names_one_method_each():
    run, scaleup = _options("run"), _options("scaleup")
    assert "--tear-method" in run and "--band-method" in scaleup
    # the old names survive only as hidden deprecated aliases
    assert run["--method"].help == "==SUPPRESS==" and scaleup["--method"].help == "==SUPPRESS=="


def test_deprecated_method_alias_warns_and_works(tmp_path, capsys):
    assert main(["run", str(AGG), "--method", "substitution", "--no-plots", "--no-grid-check", "--json",
                 "--out", str(tmp_path / "a")]) == 0
    cap = capsys.readouterr()
    assert "--method is deprecated here; use --tear-method" in cap.err
    assert main(["run", str(AGG), "--tear-method", "substitution", "--no-plots", "--no-grid-check", "--json",
                 "--out", str(tmp_path / "b")]) == 0
    cap2 = capsys.readouterr()
    assert "deprecated" not in cap2.err
    a, b = json.loads(cap.out), json.loads(cap2.out)
    assert a["solver"]["tear"]["method"] == b["solver"]["tear"]["method"] == "substitution"


def test_quiet_still_prints_the_results(tmp_path, capsys):
    assert main(["run", str(OPEN), "--quiet", "--no-plots", "--no-grid-check", "--out", str(tmp_path / "r")]) == 0
    cap = capsys.readouterr()
    assert "P80 um" in cap.out and "mass balance error" in cap.out
    assert cap.err == ""


def test_default_output_folders_are_in_the_current_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(OPEN), "--no-plots", "--no-grid-check", "--quiet"]) == 0
    assert (tmp_path / "open_circuit_ball_mill-results" / "summary.json").is_file()
    assert main(["compare", str(OPEN), str(CLOSED), "--no-plots", "--quiet"]) == 0
    assert (tmp_path / "open_circuit_ball_mill-vs-closed_circuit_ball_mill" / "compare.json").is_file()
    out = capsys.readouterr().out
    # circulating load as the engineer reads it, not a Python dict
    assert "circulating load (recycle / new feed): A none (no recycle); B " in out and "{" not in out
    assert main(["fit-rtd", str(TRACER), "--quiet"]) == 0
    assert (tmp_path / "tracer_tis-rtd" / "fit.json").is_file()
    assert main(["balance", str(paths.EXAMPLES / "survey" / "survey.toml"), "--no-fit", "--no-plots",
                 "--quiet"]) == 0
    assert (tmp_path / "survey-balance" / "report.html").is_file()


def test_diagnose_default_output_folder_is_in_the_current_folder(tmp_path, monkeypatch):
    """Where diagnose would write (checked before its fits, which are long): <config stem>-diagnose here."""
    import millflow.commands.output as output

    seen = []

    def stop(out, **kw):
        seen.append(out)
        raise KeyboardInterrupt

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(output, "check_target", stop)
    with pytest.raises(KeyboardInterrupt):
        from millflow.commands.diagnose import run

        run(build_parser().parse_args(["diagnose", str(paths.EXAMPLES / "scaleup" / "lab_fit.toml")]))
    assert seen == [tmp_path / "lab_fit-diagnose"]


def test_fit_rtd_moments_match_levenspiel(tmp_path, capsys):
    csv = tmp_path / "lev.csv"
    csv.write_text(LEVENSPIEL)
    assert main(["fit-rtd", str(csv), "--no-plots", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)["moments"]
    assert m["mean"] == pytest.approx(15.0, rel=1e-12)
    assert m["variance"] == pytest.approx(47.5, rel=1e-12)
    assert m["n_from_variance"] == pytest.approx(225 / 47.5, rel=1e-12)  # 4.74
    assert main(["fit-rtd", str(csv), "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "mean 15 min, variance 47.5 min^2, N from the variance (mean^2/variance) 4.74" in text


def test_fit_rtd_compares_models_and_flags_bounds(capsys):
    assert main(["fit-rtd", str(TRACER), "--model", "tis", "--model", "cells", "--model", "cstr",
                 "--no-plots", "--json"]) == 0
    cap = capsys.readouterr()
    js = json.loads(cap.out)
    assert set(js["models"]) == {"tis", "cells", "cstr"}
    aic = {k: v["aic"] for k, v in js["models"].items()}
    assert js["best_model"] == min(aic, key=aic.get) == js["model"]
    # the data are tanks in series: recirculating cells collapse to them with r -> 0 (its lower bound)
    assert any(b.startswith("r = ") and "lower bound 0" in b for b in js["models"]["cells"]["at_bounds"])
    assert "cells: r = " in cap.err and js["models"]["tis"]["at_bounds"] == []
    assert main(["fit-rtd", str(TRACER), "--model", "tis", "--model", "cstr", "--no-plots"]) == 0
    text = capsys.readouterr().out
    table = text.split("model comparison:")[1].splitlines()
    assert table[1].split()[:6] == ["model", "params", "SSR", "AIC", "BIC", "dAIC"]
    assert table[3].split()[0] == "tis" and table[4].split()[0] == "cstr"  # lowest AIC first
    assert float(table[3].split()[5]) == 0.0


def test_fit_ranking_table_aligns_long_names_and_says_why_not_best():
    from millflow.commands.fit import ranking_table

    long = "austin-klimpel selection with a very long descriptive candidate label"
    rows = [{"model": long, "ssr": 1.0, "n_params": 4, "aic": -10.0, "bic": -8.0, "delta_aic": 0.0},
            {"model": "base", "ssr": 2.0, "n_params": 3, "aic": -5.0, "bic": -4.0, "delta_aic": 5.0}]
    text = ranking_table(rows, "base")
    lines = text.splitlines()
    starts = {line.index("AIC") if "AIC" in line and "model" in line else None for line in lines[1:2]}
    col = starts.pop()
    # every value row has its AIC right-aligned under the header's AIC column
    assert lines[2][col - 7:col + 3].strip() == "-10.00" and lines[3][col - 7:col + 3].strip() == "-5.00"
    assert "note: the estimates above are of the config's [model] 'base' (dAIC 5.00)" in text
    assert repr(long) in text
    assert "note" not in ranking_table(rows, long)


class _Terminal:
    """A stderr that says it is a terminal (progress is shown only on one)."""

    def __init__(self):
        import io

        self.buf = io.StringIO()

    def write(self, s):
        return self.buf.write(s)

    def flush(self):
        pass

    def isatty(self):
        return True


@pytest.mark.parametrize("quiet", [False, True])
def test_progress_on_a_terminal_and_quiet_hides_it(tmp_path, monkeypatch, capsys, quiet):
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    argv = ["run", str(OPEN), "--no-plots", "--out", str(tmp_path / "r")] + (["--quiet"] if quiet else [])
    assert main(argv) == 0
    err = term.buf.getvalue()
    assert "P80 um" in capsys.readouterr().out  # the results print either way
    if quiet:
        assert err == ""
    else:
        assert "millflow run" in err and "grid check" in err and "write" in err


def _where_it_would_write(monkeypatch, argv):
    """The folder a command checks before its work (its output folder); the work is not done."""
    import millflow.commands.output as output

    seen = []

    def stop(out, **kw):
        seen.append(out)
        raise KeyboardInterrupt

    monkeypatch.setattr(output, "check_target", stop)
    args = build_parser().parse_args(argv)
    with pytest.raises(KeyboardInterrupt):
        args.func(args)
    return seen[0]


@pytest.mark.parametrize("output", ["", '[output]\ndir = "my-fit"\n'])
def test_fit_writes_into_the_current_folder(tmp_path, monkeypatch, output):
    """An [output] dir of a config is relative to the current folder, as --out; without it
    <config stem>-fit in the current folder: never into the folder of the config."""
    import shutil

    src = paths.EXAMPLES / "scaleup"
    cfgdir, work = tmp_path / "configs", tmp_path / "work"
    cfgdir.mkdir()
    work.mkdir()
    for f in ("lab_psd.csv", "lab_process.csv"):
        shutil.copyfile(src / f, cfgdir / f)
    (cfgdir / "lab.toml").write_text((src / "lab_fit.toml").read_text() + output)
    monkeypatch.chdir(work)
    out = _where_it_would_write(monkeypatch, ["fit", str(cfgdir / "lab.toml")])
    assert out.resolve() == (work / ("my-fit" if output else "lab-fit")).resolve()


@pytest.mark.parametrize("argv,folder", [
    (["run", "{fs}/open_circuit_ball_mill.toml"], "open_circuit_ball_mill-results"),
    (["compare", "{fs}/open_circuit_ball_mill.toml", "{fs}/closed_circuit_ball_mill.toml"],
     "open_circuit_ball_mill-vs-closed_circuit_ball_mill"),
    (["sweep", "{fs}/open_circuit_ball_mill.toml", "--vary", "units.ball_mill.power_kW=1:2:2"],
     "open_circuit_ball_mill-sweep"),
    (["balance", "{ex}/survey/survey.toml"], "survey-balance"),
    (["fit", "{ex}/scaleup/lab_fit.toml"], "lab_fit-fit"),
    (["diagnose", "{ex}/scaleup/lab_fit.toml"], "lab_fit-diagnose"),
    (["falsify", "{docs}/examples/falsify/tanks.toml"], "tanks-falsify"),
    (["scaleup", "fit.json", "--to", "{ex}/scaleup/plant.toml"], "plant-scaleup"),
    (["fit-rtd", "{docs}/examples/tracer_tis.csv"], "tracer_tis-rtd"),
])
def test_every_command_defaults_to_stem_kind_in_the_current_folder(tmp_path, monkeypatch, argv, folder):
    monkeypatch.chdir(tmp_path)
    argv = [a.format(fs=paths.FLOWSHEETS, ex=paths.EXAMPLES, docs=paths.DOCS) for a in argv]
    assert _where_it_would_write(monkeypatch, argv).resolve() == (tmp_path / folder).resolve()


def test_shipped_configs_name_no_output_folder():
    import tomllib

    for toml in [*paths.REPO.glob("examples/**/*.toml"), *paths.REPO.glob("docs/**/*.toml"),
                 *paths.FLOWSHEETS.glob("*.toml")]:
        doc = tomllib.loads(toml.read_text(encoding="utf-8"))
        assert "dir" not in (doc.get("output") or {}), f"{toml}: [output] dir in a shipped example"
