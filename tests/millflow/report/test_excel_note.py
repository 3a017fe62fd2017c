"""Without openpyxl (the extra ``report``) run and balance still write everything else and
say once, on stderr, that results.xlsx was not written and how to get it."""
import sys

import pytest

from millflow.cli import main
from millflow.commands.output import EXCEL_NOTE
from tests import paths


@pytest.fixture
def no_openpyxl(monkeypatch):
    """``import openpyxl`` fails, as where the extra is not installed."""
    for name in [m for m in sys.modules if m == "openpyxl" or m.startswith("openpyxl.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "openpyxl", None)  # None in sys.modules: ImportError on import


@pytest.mark.parametrize("argv", [
    ["run", str(paths.FLOWSHEETS / "closed_circuit_wet_cyclones.toml"), "--no-grid-check", "--no-plots"],
    ["balance", str(paths.EXAMPLES / "survey" / "survey.toml"), "--no-fit", "--no-plots"],
], ids=["run", "balance"])
@pytest.mark.parametrize("json", [False, True], ids=["text", "json"])
def test_one_note_when_openpyxl_is_missing(no_openpyxl, tmp_path, capsys, argv, json):
    with pytest.raises(ImportError):
        import openpyxl  # noqa: F401
    out = tmp_path / "o"
    assert main(argv + ["--quiet", "--out", str(out)] + (["--json"] if json else [])) == 0
    err = capsys.readouterr().err
    assert err.count(EXCEL_NOTE) == 1 and EXCEL_NOTE == "results.xlsx not written: pip install 'millflow[report]'"
    assert (out / "report.html").is_file() and not (out / "results.xlsx").exists()


def test_no_note_with_openpyxl(tmp_path, capsys):
    pytest.importorskip("openpyxl")
    assert main(["run", str(paths.FLOWSHEETS / "open_circuit_ball_mill.toml"), "--no-grid-check", "--no-plots",
                 "--quiet", "--out", str(tmp_path / "o")]) == 0
    assert EXCEL_NOTE not in capsys.readouterr().err and (tmp_path / "o" / "results.xlsx").is_file()
