"""Issue 10 §3: result folders are written whole or not at all, never over the user's
files; exit status 1 for a failed solve or write (130 for SIGINT), 2 for bad input; one
line on stderr, never a traceback."""
import errno
import json
import os
import signal

import pytest

import millflow.flowsheet as flowsheet_pkg
from millflow.cli import main
from millflow.commands.output import MANIFEST, file_sha256
from millflow.errors import SolverError
from tests import paths

OPEN = paths.FLOWSHEETS / "open_circuit_ball_mill.toml"


def _run(tmp_path, *extra):
    return main(["run", str(OPEN), "--no-plots", "--quiet", "--out", str(tmp_path / "res"), *extra])


def _one_line(err: str) -> str:
    err = err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    return err


def _leftovers(folder):
    """Temporary folders millflow may have left beside a target."""
    return [p.name for p in folder.iterdir() if ".millflow-" in p.name]


def test_manifest_names_files_version_and_input(tmp_path):
    assert _run(tmp_path) == 0
    m = json.loads((tmp_path / "res" / MANIFEST).read_text())
    on_disk = sorted(p.name for p in (tmp_path / "res").iterdir() if p.name != MANIFEST)
    assert m["files"] == on_disk and "results.nc" in on_disk
    assert m["input"] == str(OPEN.resolve()) and m["input_sha256"] == file_sha256(OPEN)
    assert m["millflow_version"] and m["command"] == "run" and m["written"]


def test_own_folder_is_replaced_user_files_are_refused(tmp_path, capsys):
    assert _run(tmp_path) == 0
    assert _run(tmp_path) == 0  # millflow's own folder: recognised by its manifest and replaced
    (tmp_path / "res" / "psd.csv").write_text("my edits")  # the user changed a file millflow wrote
    (tmp_path / "res" / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert _run(tmp_path) == 2
    err = _one_line(capsys.readouterr().err)
    assert "did not write (notes.txt)" in err and "--overwrite" in err
    assert (tmp_path / "res" / "notes.txt").read_text() == "mine"
    assert (tmp_path / "res" / "psd.csv").read_text() == "my edits"
    assert _run(tmp_path, "--overwrite") == 0
    assert not (tmp_path / "res" / "notes.txt").exists() and _leftovers(tmp_path) == []


def test_folder_of_a_user_without_manifest_is_refused(tmp_path, capsys):
    (tmp_path / "res").mkdir()
    (tmp_path / "res" / "summary.json").write_text("{}")
    assert _run(tmp_path) == 2
    assert "summary.json" in _one_line(capsys.readouterr().err)
    assert (tmp_path / "res" / "summary.json").read_text() == "{}"


def test_same_stem_other_flowsheet_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    other = tmp_path / "sub" / OPEN.name
    other.parent.mkdir()
    other.write_text(OPEN.read_text(encoding="utf-8"), encoding="utf-8")
    assert main(["run", str(OPEN), "--no-plots", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["run", str(other), "--no-plots", "--quiet"]) == 2  # default <stem>-results/ is taken
    assert "results of another input" in _one_line(capsys.readouterr().err)


@pytest.mark.parametrize("target, expect", [("afile", "is a file"), ("missing/parent/res", "does not exist")])
def test_unwritable_targets_exit_1(tmp_path, capsys, target, expect):
    (tmp_path / "afile").write_text("x")
    assert main(["run", str(OPEN), "--no-plots", "--out", str(tmp_path / target)]) == 1
    assert expect in _one_line(capsys.readouterr().err)
    assert (tmp_path / "afile").read_text() == "x"


def _failing_save(exc_factory):
    real = flowsheet_pkg.save

    def save(sol, out, *, plots=True, **kw):
        real(sol, out, plots=plots, **kw)  # some files are complete when the failure comes
        raise exc_factory()
    return save


@pytest.mark.parametrize("exc, code, expect", [
    (lambda: OSError(errno.ENOSPC, "No space left on device"), 1, "No space left on device"),
    (lambda: PermissionError(errno.EACCES, "Permission denied"), 1, "Permission denied"),
    (KeyboardInterrupt, 130, "interrupted"),
    (lambda: os.kill(os.getpid(), signal.SIGTERM), 1, "terminated"),
])
def test_failure_while_writing_leaves_the_old_folder_whole(tmp_path, capsys, monkeypatch, exc, code, expect):
    assert _run(tmp_path) == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "res").iterdir()}
    monkeypatch.setattr(flowsheet_pkg, "save", _failing_save(exc))
    capsys.readouterr()
    assert _run(tmp_path) == code
    assert expect in _one_line(capsys.readouterr().err)
    assert {p.name: p.read_bytes() for p in (tmp_path / "res").iterdir()} == before  # no mix of old and new
    assert _leftovers(tmp_path) == []


def test_failed_solve_exits_1_and_writes_nothing(tmp_path, capsys, monkeypatch):
    def solve(*a, **k):
        raise SolverError("units.ball_mill: mass balance 1.3e+01 above its tolerance 1e-09")
    monkeypatch.setattr(flowsheet_pkg, "solve", solve)
    assert _run(tmp_path) == 1
    assert "units.ball_mill" in _one_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_internal_error_is_one_line(tmp_path, capsys, monkeypatch):
    def solve(*a, **k):
        raise ZeroDivisionError("float division by zero")
    monkeypatch.setattr(flowsheet_pkg, "solve", solve)
    monkeypatch.delenv("MILLFLOW_DEBUG", raising=False)
    assert _run(tmp_path) == 1
    err = _one_line(capsys.readouterr().err)
    assert "internal error: ZeroDivisionError" in err and "MILLFLOW_DEBUG" in err


def test_version_and_help_examples(capsys):
    with pytest.raises(SystemExit) as ex:
        main(["--version"])
    assert ex.value.code == 0 and capsys.readouterr().out.startswith("millflow ")
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "example: millflow run" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["run", "fit", "fit-rtd", "scaleup", "falsify", "bench"])
def test_every_command_help_is_plain_text_with_an_example(capsys, command):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    out = capsys.readouterr().out
    assert "example: millflow " in out and "``" not in out and ":func:" not in out
    if command != "bench":  # bench writes no files
        assert "--out" in out and "--json" in out and "--quiet" in out


def test_error_lines_read_as_plain_text():
    """Issue 10 §5: no numpy reprs, no doubled prefixes, no '--1e+07' in messages."""
    from millflow.cli import one_line
    msg = one_line("f.toml: f.toml: units.x.d = np.float64(0.0): expected > --1e+07 (give --out)\n more")
    assert msg == "f.toml: units.x.d = 0.0: expected > -1e+07 (give --out) more"
