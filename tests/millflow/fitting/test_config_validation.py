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


def test_retained_fractions_above_one_are_refused_naming_the_sample():
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames
    rows = pd.DataFrame({"condition": "c1", "location": "product", "time_min": 1.0,
                         "size_mm": [4.0, 2.0, 1.0], "retained": [0.5, 0.56, 0.5]})  # sums to 1.56
    with pytest.raises(InputError, match=r"sample \('c1', 'product', 60\.0\): retained fractions sum to 1\.56"):
        psd_data_from_frames(rows, None)


def test_a_feed_whose_top_sieve_retains_mass_is_an_error_with_the_fix():
    import numpy as np
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.models import ForwardModel, ModelSpec
    feed = pd.DataFrame({"condition": "*", "location": "feed", "time_min": 0.0, "size_mm": [4.0, 2.0],
                         "passing": [0.9, 0.0]})  # 10 % above the top sieve: no measured size
    prod = pd.DataFrame({"condition": "c1", "location": "mill", "time_min": 1.0, "size_mm": [4.0, 2.0, 1.0],
                         "passing": [1.0, 0.5, 0.1]})
    data = psd_data_from_frames(pd.concat([feed, prod]), None)
    with pytest.raises(InputError, match=r"top sieve \(4 mm\) passes only 90 %.*add a feed row"):
        ForwardModel(ModelSpec(mode="batch"), data).predict(np.zeros(0))


def test_fit_config_reads_unit_suffixed_keys_like_flowsheets(tmp_path):
    """Issue 11 §2: one reader of unit-suffixed keys (millflow.inputs.quantity) for both."""
    cfg, _ = _write_batch_case(tmp_path)
    text = cfg.read_text()
    cfg.write_text(text.replace("ratio = 1.189207115002721", "ratio = 1.189207115002721\ntop_um = 4000.0"))
    a = load_config(cfg).grid
    cfg.write_text(text.replace("ratio = 1.189207115002721", "ratio = 1.189207115002721\ntop_mm = 4.0"))
    assert load_config(cfg).grid == a
    cfg.write_text(text.replace("ratio = 1.189207115002721", "ratio = 1.189207115002721\ntop = 4.0"))
    with pytest.raises(InputError, match=r"\[grid\]\.top: units of measure missing; write top_<unit>"):
        load_config(cfg)
