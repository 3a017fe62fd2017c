"""Numbers printed in the docs are the code's: the sweep table of docs/sweeps.md and the
quick-start output of docs/flowsheets.md, recomputed and compared to their printed rounding.

(tests/test_docs.py runs the python blocks; these pages' numbers sit in tables and output
blocks, which it does not check.)
"""
import json
import re

import numpy as np
import pytest

from millflow.cli import main
from tests import paths


def test_sweep_table_is_what_run_sweep_gives():
    """Every entry of the kW x t/h table of P80 within 0.1 um of run_sweep (printed to 0.1 um:
    0.05 of rounding, the rest for a solver tolerance far below it)."""
    from millflow.sweep import parse_vary, run_sweep

    text = (paths.DOCS / "sweeps.md").read_text(encoding="utf-8")
    head = re.search(r"^\| kW \\ t/h \|(.*)\|$", text, re.M)
    feeds = [float(x) for x in head.group(1).split("|")]
    rows = re.findall(r"^\| (\d+) \| ([\d. |]+)\|$", text[head.end():], re.M)
    powers = [float(r[0]) for r in rows]
    table = np.array([[float(x) for x in r[1].split("|")] for r in rows])
    assert table.shape == (5, 4) and powers == [2000, 3000, 4000, 5000, 6000] and feeds == [150, 200, 250, 300]
    ds = run_sweep(str(paths.REPO / "flowsheets" / "closed_circuit_ball_mill.toml"),
                   [parse_vary("units.ball_mill.power_kW=2000:6000:5"),
                    parse_vary("units.fresh_feed.solids_tph=150:300:4")], scheduler="serial", progress=False)
    p80 = ds["p80_um"].sel(product="overflow").transpose("units.ball_mill.power_kW", "units.fresh_feed.solids_tph")
    np.testing.assert_allclose(table, p80.values, atol=0.1)
    # the sentence under the table: equal kWh/t, equal P80
    for value in re.findall(r"([\d.]+) um at [\d.]+ kWh/t", text):
        assert np.any(np.abs(p80.values - float(value)) <= 0.1), value


def test_flowsheets_quick_start_output_is_what_millflow_run_prints(tmp_path, capsys):
    """The output block of docs/flowsheets.md against millflow run --json on the same file:
    each stream's t/h (printed to 0.1), P80 and P50 (to 1 um), % passing (to 0.1), the
    circulating load (to 0.1 %), and the solve's structure (the mill's hold-up is torn)."""
    text = (paths.DOCS / "flowsheets.md").read_text(encoding="utf-8")
    block = text[text.index("```\nClosed-circuit ball mill with hydrocyclones\n"):]
    block = block[:block.index("```", 4)]
    assert main(["run", str(paths.REPO / "flowsheets" / "closed_circuit_ball_mill.toml"), "--json", "--no-plots",
                 "--out", str(tmp_path / "o")]) == 0
    s = json.loads(capsys.readouterr().out)
    rows = re.findall(r"^(\w+)\s+\S+ -> \S+\s+([\d.]+)\s+(\d+)\s+(\d+)\s+([\d.]+)\s+([\d.]+)$", block, re.M)
    assert {r[0] for r in rows} == set(s["streams"])
    for name, tph, p80, p50, f75, f150 in rows:
        v = s["streams"][name]
        assert float(tph) == pytest.approx(v["solids_tph"], abs=0.05 + 1e-9), name
        assert float(p80) == pytest.approx(v["p80_um"], abs=0.5 + 1e-9), name
        assert float(p50) == pytest.approx(v["p50_um"], abs=0.5 + 1e-9), name
        assert float(f75) == pytest.approx(v["passing_pct"]["75"], abs=0.05 + 1e-9), name
        assert float(f150) == pytest.approx(v["passing_pct"]["150"], abs=0.05 + 1e-9), name
    cl = float(re.search(r"underflow ([\d.]+) %", block).group(1))
    assert cl == pytest.approx(100 * s["circulating_load"]["underflow"], abs=0.05 + 1e-9)
    assert s["solver"]["structure"] in block
