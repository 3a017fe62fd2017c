"""Every CSV every command writes keeps the conventions of docs/cli.md: a column of a
size, a flow or a passing says its unit in its name (``size_um``, ``solids_tph``,
``passing_75um_pct``), passing is in %, and numbers (also those inside text cells) carry
at most the significant digits stated for the file."""
import csv
import json
import re

import pytest

from millflow.cli import main
from tests import paths

#: Significant digits of each command's CSVs (docs/cli.md, "Units and digits in files").
DIGITS = {"run": 10, "balance": 8, "fit": 8, "compare": 6, "sweep": 6, "scaleup": 6, "falsify": 6, "diagnose": 6}

SIZE = {"size", "p80", "p50", "p20", "d50", "d50c", "d80"}
FLOW = {"tph", "flow", "throughput"}
UNITS = {"um", "mm", "m", "pct", "tph", "kg", "m3"}
NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.])")

FALSIFY = """replicates = 2
seed = 12
workers = 1
drift_replicates = 2
[truth]
type = "tanks_in_series"
strengths = [1, 5]
[assumed]
mode = "well_mixed"
[design]
tau_min = [0.5, 1, 2, 4]
top_size_um = 4000
n_sieves = 12
[noise]
kind = "gaussian"
sigma = 0.01
"""


def significant(text: str) -> int:
    """Significant digits of a number as written ("0.02742" 4, "3000" 1, "1.7053e-16" 5)."""
    mantissa = text.lower().split("e")[0].lstrip("+-")
    digits = mantissa.replace(".", "").lstrip("0")
    if "." not in mantissa:
        digits = digits.rstrip("0")
    return max(len(digits), 1)


def check_names(name: str, columns: list) -> None:
    for col in columns:
        tokens = set(re.split(r"[._]", col.lower()))
        if tokens & (SIZE | FLOW | {"passing"}):
            assert tokens & UNITS or re.search(r"\d+um", col), f"{name}: column {col!r} has no unit in its name"
        if "passing" in tokens:
            assert "pct" in tokens, f"{name}: column {col!r}: passing in a CSV is in % (_pct)"


def check_digits(name: str, rows: list, limit: int) -> int:
    n = 0
    for row in rows:
        for cell in row:
            for m in NUMBER.finditer(cell):
                assert significant(m.group(0)) <= limit, f"{name}: {cell!r} has more than {limit} significant digits"
                n += 1
    return n


def _stub_diagnose(monkeypatch):
    """diagnose's candidate fits take minutes: its CSV is checked on a Diagnosis of the same shape."""
    import millflow.fitting.diagnose as diag

    row = {"model": "linear", "ssr": 0.002037026564089351, "n_params": 6, "bic": -866.0898947965032,
           "aicc": -879.583886498654, "delta_bic": 0.0, "loco_rmse": None, "drift_pct": 1.2345678901234,
           "drift_se": 0.98765432109876, "lag1": -0.0031036118484412353, "runs_reject": 0.0}
    monkeypatch.setattr(diag, "diagnose", lambda cfg, **kw: diag.Diagnosis([row], {}, {}, "linear", "linear", 0.1))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("conventions")
    fs = paths.FLOWSHEETS
    lab = paths.EXAMPLES / "scaleup" / "lab_fit.toml"
    (tmp / "tanks.toml").write_text(FALSIFY)
    runs = {
        "run": [["run", str(fs / "closed_circuit_wet_cyclones.toml"), "--no-grid-check", "--no-plots"]],
        "compare": [["compare", str(fs / "open_circuit_ball_mill.toml"), str(fs / "closed_circuit_wet_cyclones.toml"),
                     "--no-plots"]],
        "sweep": [["sweep", str(fs / "closed_circuit_ball_mill.toml"), "--vary", "units.ball_mill.power_kW=3000:4600:2",
                   "--scheduler", "serial", "--no-plots"]],
        "balance": [["balance", str(paths.EXAMPLES / "survey" / "survey.toml"), "--no-fit", "--no-plots"]],
        "fit": [["fit", str(lab), "--no-plots"]],
        "scaleup": [["scaleup", str(tmp / "fit" / "fit.json"), "--to", str(paths.EXAMPLES / "scaleup" / "plant.toml"),
                     "--band-method", "delta", "--no-plots"]],
        "falsify": [["falsify", str(tmp / "tanks.toml"), "--no-plots"]],
        "diagnose": [["diagnose", str(lab), "--no-plots", "--no-loco"]],
    }
    mp = pytest.MonkeyPatch()
    _stub_diagnose(mp)
    try:
        for kind, argvs in runs.items():
            for argv in argvs:
                assert main(argv + ["--quiet", "--out", str(tmp / kind)]) == 0, argv
    finally:
        mp.undo()
    return tmp


@pytest.mark.parametrize("kind", list(DIGITS))
def test_every_csv_names_its_units_and_keeps_its_digits(folders, kind, capsys):
    capsys.readouterr()
    files = sorted((folders / kind).glob("*.csv"))
    assert files, f"{kind} wrote no CSV"
    for f in files:
        with f.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
        check_names(f"{kind}/{f.name}", rows[0])
        assert check_digits(f"{kind}/{f.name}", rows[1:], DIGITS[kind]) > 0


def test_scaleup_contributions_in_the_quantitys_unit(folders):
    with (folders / "scaleup" / "scaleup_contributions.csv").open(newline="") as fh:
        head = next(csv.reader(fh))
    assert {"half_width_um", "half_width_pct", "low_um", "high_um"} <= set(head)  # P80 [um], share [%]
    assert all(c.endswith("_um") for c in head if c.startswith("at_"))


def test_one_name_per_quantity_across_commands(folders):
    """% solids is solids_content_pct and specific energy specific_energy_kWh_per_t in every file."""
    texts = {p: p.read_text(encoding="utf-8") for k in DIGITS for p in (folders / k).glob("*.[cj]s*")}
    for p, text in texts.items():
        for old in ("solids_pct", "specific_energy_kWh_t", "kWh_t\""):
            assert not re.search(rf"(?<![\w]){old}", text), f"{p.name} still says {old}"
    run = json.loads((folders / "run" / "summary.json").read_text())
    bal = json.loads((folders / "balance" / "summary.json").read_text())
    assert "solids_content_pct" in next(iter(run["streams"].values()))
    assert "solids_content_pct" in next(iter(bal["streams"].values()))
    su = json.loads((folders / "scaleup" / "scaleup.json").read_text())
    assert "specific_energy_kWh_per_t" in su and "specific_energy_kWh_per_t" in run["units"]["ball_mill"]


def test_significant_digits_counting():
    assert [significant(s) for s in ("0.02742", "3000", "1.7053e-16", "-5.4593935", "100", "0", "3.10")] == \
        [4, 1, 5, 8, 1, 1, 3]
