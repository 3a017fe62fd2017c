"""Issue 16 / 15 §4: a slow fit says what it is doing (stderr, after 2 s), quiet silences it."""
from millflow.fitting.progress import StageReporter, reporter


def test_stage_reporter_is_silent_for_quick_runs_then_reports(capsys):
    r = StageReporter("fit", after_s=3600.0)
    r("local starts 5/20")
    assert capsys.readouterr().err == ""  # a quick run stays silent
    r = StageReporter("fit", after_s=0.0)
    r("local starts 5/20")
    err = capsys.readouterr().err
    assert err.startswith("[millflow fit ") and err.rstrip().endswith("local starts 5/20")


def test_quiet_and_a_given_callable():
    got = []
    reporter(None, True, "fit")("x")  # quiet: nothing, no error
    reporter(got.append, False, "fit")("y")
    assert got == ["y"] and isinstance(reporter(None, False, "fit"), StageReporter)


def test_fit_reports_stages_to_a_given_callable(tmp_path):
    from millflow.fitting.config import load_config
    from millflow.fitting.estimate import fit
    from tests.millflow.fitting.test_fit_cli import _write_batch_case
    cfg, _ = _write_batch_case(tmp_path)
    c = load_config(cfg)
    got = []
    fit(c.model(), c.params, global_search=False, starts=2, grid_check=False, progress=got.append)
    assert any("local starts" in m for m in got) and got[-1].startswith("done")
