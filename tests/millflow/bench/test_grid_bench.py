"""``millflow bench grid``: runs from any folder (its circuits are package data, not the
repository's files), on every shipped flowsheet."""
import json

import pytest

from millflow.bench import grid
from tests.paths import REPO


def test_the_suites_circuits_are_every_shipped_flowsheet():
    """The suite benchmarks every flowsheet shipped with the bench (whose text equals the
    repository's flowsheets/: tests/millflow/bench/test_bench_suites.py)."""
    assert set(grid.CIRCUITS) == {p.stem for p in (REPO / "flowsheets").glob("*.toml")}


def test_quick_run_outside_the_repository(tmp_path, monkeypatch, capsys):
    from millflow.cli import main

    monkeypatch.chdir(tmp_path)  # no flowsheets/ here
    assert main(["bench", "grid", "--quick", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    ca = {r["ratio"]: r["p80_rel_error"] for r in rows if r.get("scheme") == "class_average"
          and r["circuit"] == "closed_circuit_ball_mill"}
    ue = {r["ratio"]: r["p80_rel_error"] for r in rows if r.get("scheme") == "upper_edge"
          and r["circuit"] == "closed_circuit_ball_mill"}
    # class averages far below Austin's upper edges at every ratio (measured 0.1 % vs 14 % at 2^(1/4))
    assert all(ca[k] < 0.1 * ue[k] for k in ca)
    assert any(r.get("method") == "run cost" for r in rows)


def test_unknown_circuit_is_named():
    from millflow.errors import InputError

    with pytest.raises(InputError, match="not shipped with millflow.bench"):
        grid.document("no_such_circuit")
