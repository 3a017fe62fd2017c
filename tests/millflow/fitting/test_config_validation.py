"""Issue 10 §5: fit-config settings are never silently ignored or coerced: each bad value
is one line naming the file, table, key and what was expected (exit 2 on the CLI)."""
import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.fitting.config import load_config
from tests.millflow.fitting.test_fit_cli import _write_batch_case


@pytest.mark.parametrize("old, new, match", [
    ("[params.beta]\nmin = 2.2", "[params.beta]\nmin = 2.2\nvary = \"no\"",
     r"\[params\]\.beta\.vary = 'no': expected true or false"),
    ("ratio = 1.189207115002721", "ratio = 1.189207115002721\nsharpness = 2", r"\[grid\]: unknown key sharpness"),
    ("ratio = 1.189207115002721", "ratio = \"fine\"", r"\[grid\]\.ratio = 'fine': expected a number"),
    ("ratio = 1.189207115002721", "ratio = 1.0", r"\[grid\]\.ratio = 1\.0: expected > 1"),
    ("starts = 3", "starts = 0", r"\[optimizer\]\.starts = 0: expected a whole number >= 1"),
    ("starts = 3", "starts = 2.7", r"\[optimizer\]\.starts = 2\.7: expected a whole number"),
    ("popsize = 6", "popsize = 0", r"\[optimizer\]\.popsize = 0: expected a whole number >= 1"),
    ("maxiter = 40", "maxiter = -1", r"\[optimizer\]\.maxiter = -1: expected a whole number >= 1"),
    ("maxiter = 40", "maxiter = 40\nseed = \"abc\"",
     r"\[optimizer\]\.seed = 'abc': expected a whole number"),
    ("[params.beta]\nmin = 2.2", "[params.beta]\nmin = 3.0\nmax = 3.0", r"min = 3 and max = 3; expected min < max"),
    ("[params.gamma]\nmax = 2.0", "[params.gamma]\nmax = [2.0, 3.0]",
     r"gamma\.max = \[2\.0, 3\.0\]: expected a number"),
    ("dir = \"out\"", "dir = \"out\"\nplot = false", r"\[output\]: unknown key plot"),
    ("[data]", "tracer = \"t.csv\"\n[data]", r"unknown tables \['tracer'\]"),
])
def test_bad_settings_are_named(tmp_path, capsys, old, new, match):
    cfg, _ = _write_batch_case(tmp_path)
    text = cfg.read_text()
    assert old in text, old
    cfg.write_text(text.replace(old, new))
    with pytest.raises(InputError, match=match):
        load_config(cfg)
    assert main(["fit", str(cfg), "--quiet", "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "np.float64" not in err and str(cfg) in err


def test_a_fixed_parameter_may_have_equal_bounds(tmp_path):
    cfg, _ = _write_batch_case(tmp_path)
    cfg.write_text(cfg.read_text().replace("[params.beta]\nmin = 2.2",
                                           "[params.beta]\nvalue = 3.0\nmin = 3.0\nmax = 3.0\nvary = false"))
    assert load_config(cfg).params["beta"].vary is False
