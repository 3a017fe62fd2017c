"""Issue 10 §4: the user's files in other encodings, with a BOM, binary, or with a list
where one number belongs: one named error (exit 2 on the command line), or the same
result as the plain file."""
import codecs

import pytest

from millflow.cli import main
from millflow.errors import GridError, InputError
from millflow.flowsheet import load
from millflow.inputs import read_csv, read_text, read_toml
from tests import paths
from tests.closed_circuit import per_time_text

CLOSED = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"


@pytest.mark.parametrize("raw, match", [
    ("x = 1\n".encode("utf-16"), "UTF-16 encoded; save it as UTF-8"),
    (b"title = 'caf\xe9'\n", r"byte 12 \(line 1\) is not UTF-8 \(0xe9\)"),
    (b"\x7fELF\x02\x01\x01\x00\x00", "binary .a NUL byte at offset 7"),
])
def test_encodings_named_with_byte_offset(tmp_path, raw, match):
    p = tmp_path / "f.toml"
    p.write_bytes(raw)
    with pytest.raises(InputError, match=match) as exc:
        read_text(p)
    assert str(p) in str(exc.value)


def test_bom_is_utf8(tmp_path):
    p = tmp_path / "f.toml"
    p.write_bytes(codecs.BOM_UTF8 + b"x = 1\n")
    assert read_toml(p) == {"x": 1}
    p.write_bytes(codecs.BOM_UTF8 + b"a,b\n1,2\n")
    assert list(read_csv(p).columns) == ["a", "b"]


def test_flowsheet_with_bom_equals_plain(tmp_path):
    p = tmp_path / "c.toml"
    p.write_bytes(codecs.BOM_UTF8 + CLOSED.read_bytes())
    a, b = load(CLOSED), load(p)
    assert a.grid == b.grid and list(a.units) == list(b.units)


@pytest.mark.parametrize("old, new, match", [
    ("tau_min = 3.5", "tau_min = [3.5, 4.0]", r"units\.ball_mill\.tau_min = \[3\.5, 4\.0\]: expected a number$"),
    ("solids_tph = 250", "solids_tph = [250, 10]", r"units\.fresh_feed\.solids_tph = \[250, 10\]: expected a number$"),
    ("top_um = 8000", "top_um = 1e300", r"grid: top_m = 1e\+294 m: expected a particle size of at most 10 m"),
])
def test_lists_and_absurd_sizes_are_named(tmp_path, capsys, old, new, match):
    text = per_time_text()
    assert old in text
    p = tmp_path / "bad.toml"
    p.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises((InputError, GridError), match=match):
        load(p)
    assert main(["run", str(p), "--no-plots", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("millflow run: error: ") and str(p) in err
    assert not (tmp_path / "o").exists()


def test_passing_below_the_finest_edge_is_unknown_not_the_edge_value(tmp_path, capsys):
    """Issue 10 §5: "% passing 5 um" with the finest edge at ~10 um showed the value at the edge."""
    text = CLOSED.read_text(encoding="utf-8")
    assert "passing_um = [75, 150]" in text
    p = tmp_path / "c.toml"
    p.write_text(text.replace("passing_um = [75, 150]", "passing_um = [5, 75, 150]"), encoding="utf-8")
    assert main(["run", str(p), "--json", "--no-plots", "--out", str(tmp_path / "o")]) == 0
    import json
    s = json.loads(capsys.readouterr().out)
    assert s["streams"]["overflow"]["passing_pct"]["5"] is None
    assert 0 < s["streams"]["overflow"]["passing_pct"]["75"] < 100
