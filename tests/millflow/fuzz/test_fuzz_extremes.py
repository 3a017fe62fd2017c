"""Property tests over keys at the edge of floating point and wrong types at unit names:
every flowsheet either runs or is refused in one line naming the key (exit 2), never a
traceback or an internal error."""
import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from millflow.cli import main
from tests import paths

BASE = (paths.FLOWSHEETS / "closed_circuit_ball_mill.toml").read_text()


def _run(tmp_path, text, capsys):
    f = tmp_path / "f.toml"
    f.write_text(text)
    code = main(["run", str(f), "--out", str(tmp_path / "o"), "--overwrite", "--quiet", "--no-plots"])
    err = capsys.readouterr().err
    assert "internal error" not in err and "Traceback" not in err, err
    return code, err


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(exp=st.integers(-330, 330), key=st.sampled_from(["holdup_t", "tau_min"]))
def test_huge_and_tiny_mill_keys_run_or_are_named(tmp_path_factory, capsys, exp, key):
    tmp = tmp_path_factory.mktemp("x")
    code, err = _run(tmp, BASE.replace("tau_min = ", f"{key} = 1e{exp} #"), capsys)
    assert code in (0, 1, 2)
    if code == 2:
        assert f"units.ball_mill.{key}" in err and err.count("\n") == 1


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(['material = "ore"', 'type = "mill"', 'from = "fresh_feed"', 'to = "chute"']),
       value=st.sampled_from([["ore"], [], 1, {"a": 1}, True]))
def test_a_non_string_where_a_name_is_expected_is_named(tmp_path_factory, capsys, field, value):
    tmp = tmp_path_factory.mktemp("x")
    key, _ = field.split(" = ")
    toml_value = json.dumps(value).replace(":", "=").replace('"a"', "a").replace("true", "true")
    code, err = _run(tmp, BASE.replace(field, f"{key} = {toml_value}", 1), capsys)
    assert code == 2 and err.count("\n") == 1 and key in err, err


def test_the_memory_guard_counts_the_run_and_its_grid_check(tmp_path, capsys, monkeypatch):
    # ~420 classes: one N x N matrix (1.4 MB) is within a 10 MiB budget, but the run's
    # transfer matrices and the grid check's on ~840 classes are not; refused before solving
    monkeypatch.setenv("MILLFLOW_MEMORY_BUDGET_GB", str(10 / 1024))
    text = BASE.replace("ratio = 1.044273782427414", "ratio = 1.0173")
    assert "ratio = 1.0173" in text
    code, err = _run(tmp_path, text, capsys)
    assert code == 2 and err.count("\n") == 1
    assert "for the grid check needs about" in err and "--no-grid-check" in err
    assert not (tmp_path / "o").exists()
    # without the grid check the same run fits the budget and runs
    f = tmp_path / "f.toml"
    assert main(["run", str(f), "--out", str(tmp_path / "o2"), "--quiet", "--no-plots", "--no-grid-check"]) == 0
    # and a budget below even that refuses it too
    monkeypatch.setenv("MILLFLOW_MEMORY_BUDGET_GB", str(2 / 1024))
    assert main(["run", str(f), "--out", str(tmp_path / "o3"), "--quiet", "--no-plots", "--no-grid-check"]) == 2
    assert "MILLFLOW_MEMORY_BUDGET_GB" in capsys.readouterr().err
