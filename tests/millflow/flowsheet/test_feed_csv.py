"""A feed PSD from a CSV file (issue 14 §2), with the tail below the finest sieve extrapolated.

The grid's edges include every sieve (grid ratio 2^(1/2) from 6700 um is not exact, so the
checks interpolate): cumulative passing at a sieve edge is the measured value to the
interpolation's exactness at data points (1e-12).
"""
import numpy as np
import pytest

from millflow.errors import InputError, MillflowError
from millflow.flowsheet import load, solve
from millflow.psd import cum_passing_at

SIEVES = [6700, 4750, 3350, 2360, 1700, 1180, 850, 600, 425, 300, 212, 150, 106, 75, 53]
RETAINED = [0, 7, 13, 14, 12, 10, 8, 7, 5, 4.5, 3.5, 3, 2.5, 2, 1.5]
PAN = 7.0

FLOWSHEET = """
[grid]
edges_um = EDGES
[units.f]
type = "feed"
solids_tph = 100
psd = {form = "csv", file = "feed.csv" TAIL}
[units.p]
type = "product"
[streams]
s = {from = "f", to = "p"}
"""


def _write(tmp_path, csv, tail=""):
    edges = SIEVES + [37.5, 26.5, 19, 13.2, 9.4]
    (tmp_path / "feed.csv").write_text(csv)
    (tmp_path / "fs.toml").write_text(FLOWSHEET.replace("EDGES", str(edges)).replace("TAIL", tail))
    return tmp_path / "fs.toml"


def _retained_csv():
    rows = [f"{s},{r}" for s, r in zip(SIEVES, RETAINED)] + [f"0,{PAN}"]
    return "size_um,retained_pct\n" + "\n".join(rows) + "\n"


def test_retained_csv_reproduces_the_sieves(tmp_path):
    sol = solve(load(_write(tmp_path, _retained_csv())))
    fs = sol.flowsheet
    frac = sol.flow("s") / sol.flow("s").sum()
    measured = 1 - np.cumsum(RETAINED) / 100
    got = cum_passing_at(fs.grid, frac, np.array(SIEVES) * 1e-6)
    np.testing.assert_allclose(got, measured, atol=1e-12)
    # default tail "sink": everything below 53 um (the pan, 7 %) sits in the sink class
    assert frac[-1] == pytest.approx(PAN / 100, abs=1e-12)


def test_cumulative_passing_csv_same_as_retained(tmp_path):
    passing = 100 - np.cumsum(RETAINED)
    csv = "size_mm,passing_pct\n" + "\n".join(f"{s / 1000},{p}" for s, p in zip(SIEVES, passing)) + "\n"
    a = solve(load(_write(tmp_path, csv))).flow("s")
    (tmp_path / "b").mkdir()
    b = solve(load(_write(tmp_path / "b", _retained_csv()))).flow("s")
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("tail", ["rosin_rammler", "ggs"])
def test_tail_rule_spreads_the_fines_below_the_finest_sieve(tmp_path, tail):
    sol = solve(load(_write(tmp_path, _retained_csv(), f', tail = "{tail}"')))
    frac = sol.flow("s") / sol.flow("s").sum()
    below = frac[len(SIEVES) - 1:]  # classes under 53 um and the sink
    assert below.sum() == pytest.approx(PAN / 100, abs=1e-12)  # mass below the finest sieve is kept
    assert below[-1] < PAN / 100 and np.all(below[:-1] > 0)  # ... and spread by the stated rule
    passing = 1 - np.cumsum(frac)[:-1]
    assert np.all(np.diff(passing) <= 1e-15)  # cumulative passing falls towards fine sizes


@pytest.mark.parametrize("csv, match", [
    ("size,passing_pct\n100,100\n50,20\n", "column .size.: units of measure missing"),
    ("size_um,passing\n100,100\n50,20\n", "one of passing_pct"),
    ("size_um,retained_pct\n100,0\n50,60\n0,30\n", "sums to 90"),
    ("size_um,passing_pct\n100,100\n50,abc\n", "row 3, column passing_pct"),
    ("size_um,passing_pct\n100,100\n50,-2\n", "row 3"),
    ("size_um,passing_pct\n100,90\n50,20\n", "passes only 90"),
])
def test_bad_feed_csv_is_named(tmp_path, csv, match):
    with pytest.raises(MillflowError, match=match):  # InputError or GridError, both exit 2
        load(_write(tmp_path, csv))


def test_missing_feed_csv_names_the_key(tmp_path):
    p = _write(tmp_path, _retained_csv())
    (tmp_path / "feed.csv").unlink()
    with pytest.raises(InputError, match=r"units.f.psd.file: .*feed.csv not found"):
        load(p)


@pytest.mark.parametrize("csv", ["size_um,passing_pct\n", "size_um,passing_pct\n6700,100\n"])
def test_feed_csv_with_fewer_than_two_rows_is_named(tmp_path, csv):
    with pytest.raises(InputError, match="expected at least two sieves"):
        load(_write(tmp_path, csv))
