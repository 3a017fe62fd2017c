"""The user's files in one dialect. CSV columns carry their unit in the name and are read through
millflow.inputs.unit_column: the PSD table of a fit, its tracer table and a flowsheet's
feed sieve file accept every unit of millflow.inputs.UNITS, and a column without its unit
or with an unknown one is one error line naming the file and the column; matrices are read
through millflow.inputs.read_matrix (encodings and non-numbers named)."""
import numpy as np
import pandas as pd
import pytest

from millflow.errors import InputError
from millflow.inputs import UNITS, unit_column


@pytest.mark.parametrize("cols, stem, dim, want", [
    (["condition", "size_um"], "size", "length", ("size_um", 1e-6)),
    (["size_in", "passing"], "size", "length", ("size_in", 0.0254)),
    (["time_h", "F"], "time", "time", ("time_h", 3600.0)),
    ([" time_min ", "F"], "time", "time", ("time_min", 60.0)),
])
def test_unit_column_finds_the_unit(cols, stem, dim, want):
    assert unit_column(cols, stem, dim, "f.csv") == want


@pytest.mark.parametrize("cols, match", [
    (["size", "passing"], r"f\.csv: column 'size': units of measure missing; name it size_<unit> with one of _um"),
    (["size_cm", "passing"], r"f\.csv: column 'size_cm': unknown unit 'cm' for size \(length\)"),
    (["size_um", "size_mm"], r"f\.csv: columns size_um, size_mm give 'size' twice"),
    (["passing"], r"f\.csv: no column size_<unit> \(length: _um, _mm"),
])
def test_unit_column_refuses_in_one_line(cols, match):
    with pytest.raises(InputError, match=match) as err:
        unit_column(cols, "size", "length", "f.csv")
    assert "\n" not in str(err.value)


def test_optional_column_absent():
    assert unit_column(["size_um"], "time", "time", "f.csv", required=False) == (None, None)


def _psd(size_col, factor, time_col=None, tfactor=1.0):
    from millflow.fitting.data import psd_data_from_frames

    sizes_mm = np.array([4.0, 2.0, 1.0])
    feed = pd.DataFrame({"condition": "c", "location": "feed", size_col: sizes_mm * 1e-3 / factor,
                         "passing": [1.0, 0.4, 0.1]})
    prod = pd.DataFrame({"condition": "c", "location": "mill", size_col: sizes_mm * 1e-3 / factor,
                         "passing": [1.0, 0.7, 0.3]})
    if time_col:
        feed[time_col], prod[time_col] = 0.0, 60.0 / tfactor
    return psd_data_from_frames(pd.concat([feed, prod]), source="psd.csv")


@pytest.mark.parametrize("unit", ["um", "mm", "m", "in", "ft"])
def test_fit_psd_table_in_any_length_unit(unit):
    """The same sieves written in any length unit are the same sizes in m (rtol 1e-12:
    one multiplication and one division by the unit factor)."""
    got = _psd(f"size_{unit}", UNITS["length"][unit]).table.size_m.to_numpy()
    ref = _psd("size_mm", 1e-3).table.size_m.to_numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_fit_psd_table_time_in_hours_and_legacy_micron():
    t = _psd("size_micron", 1e-6, "time_h", 3600.0).table
    assert set(t.time_s) == {0.0, 60.0}
    np.testing.assert_allclose(sorted(set(t.size_m)), [1e-3, 2e-3, 4e-3], rtol=1e-12)


@pytest.mark.parametrize("col, match", [("size", "units of measure missing"), ("size_cm", "unknown unit 'cm'")])
def test_fit_psd_table_refuses_a_size_column_without_unit(col, match):
    with pytest.raises(InputError, match=rf"psd\.csv: column '{col}': {match}"):
        _psd(col, 1e-3)


@pytest.mark.parametrize("col, factor", [("time_s", 1.0), ("time_min", 60.0), ("time_h", 3600.0)])
def test_tracer_table_in_any_time_unit(tmp_path, col, factor):
    from millflow.fitting.config import read_tracer_table

    p = tmp_path / "tracer.csv"
    pd.DataFrame({"condition": "c", col: np.array([60.0, 120.0]) / factor, "F": [0.3, 0.6]}).to_csv(p, index=False)
    np.testing.assert_allclose(read_tracer_table(p).time_s, [60.0, 120.0], rtol=1e-12)


@pytest.mark.parametrize("col, match", [("time", "column 'time': units of measure missing"),
                                        ("time_d", "column 'time_d': unknown unit 'd'")])
def test_tracer_table_refuses_time_without_unit(tmp_path, col, match):
    from millflow.fitting.config import read_tracer_table

    p = tmp_path / "tracer.csv"
    pd.DataFrame({"condition": "c", col: [60.0, 120.0], "F": [0.3, 0.6]}).to_csv(p, index=False)
    with pytest.raises(InputError, match=match):
        read_tracer_table(p)


def _feed_sheet(tmp_path, header, rows):
    from millflow.flowsheet import loads

    (tmp_path / "feed.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    text = f"""
grid = {{top_um = 8000, bottom_um = 100, ratio = 2}}
[units]
fresh = {{type = "feed", solids_tph = 10, psd = {{form = "csv", file = "{(tmp_path / 'feed.csv').as_posix()}"}}}}
out = {{type = "product"}}
[streams]
s = {{from = "fresh", to = "out"}}
"""
    return loads(text)


def test_flowsheet_feed_csv_in_inches_equals_mm(tmp_path):
    """A feed sieve file in inches gives the feed of the same file in mm (atol 1e-12 on
    mass fractions: the same interpolation of the same sizes)."""
    mm = _feed_sheet(tmp_path, "size_mm,passing_pct", ["8,100", "2,50", "0.5,10"]).units["fresh"].psd
    inch = _feed_sheet(tmp_path, "size_in,passing_pct",
                       [f"{v / 25.4!r},{p}" for v, p in ((8, 100), (2, 50), (0.5, 10))]).units["fresh"].psd
    np.testing.assert_allclose(inch, mm, rtol=0, atol=1e-12)


def test_flowsheet_feed_csv_size_without_unit(tmp_path):
    with pytest.raises(InputError, match=r"feed\.csv: column 'size': units of measure missing"):
        _feed_sheet(tmp_path, "size,passing_pct", ["8,100", "2,50"])


def test_matrix_files_are_read_through_inputs(tmp_path):
    """A breakage matrix CSV in UTF-16 or with a word in it: one line naming the file."""
    from millflow.inputs import read_matrix

    p = tmp_path / "b.csv"
    p.write_text("# b of two classes\n0,0\n1,0\n")
    np.testing.assert_array_equal(read_matrix(p), [[0.0, 0.0], [1.0, 0.0]])
    p.write_bytes("0,0\n1,0\n".encode("utf-16"))
    with pytest.raises(InputError, match=r"b\.csv: the breakage matrix is UTF-16 encoded; save it as UTF-8"):
        read_matrix(p, "breakage matrix")
    p.write_text("0,0\n1,x\n")
    with pytest.raises(InputError, match=r"b\.csv: not a CSV matrix of numbers: could not convert string 'x'"):
        read_matrix(p)
