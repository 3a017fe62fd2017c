"""report.html and results.xlsx of `millflow balance`: the numbers shown (on the page as
headless Chromium renders it, and in the workbook) are summary.json's; the page has the
chi-square line, the gross-error candidates, the circulating load with its SD, the
adjustments in SDs, the input file's hash and the version; outputs are staged whole."""
import hashlib
import json
import math
import re

import pytest

from millflow.cli import main
from millflow.report.excel import excel_available
from millflow.report.flowsheet import _get
from millflow.report.html import fmt
from tests import paths
from tests.millflow.report.test_report import Cells, render

SURVEY = paths.EXAMPLES / "survey" / "survey.toml"
NUM = re.compile(r"(?<![A-Za-z0-9.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


@pytest.fixture(scope="module")
def balanced(tmp_path_factory):
    out = tmp_path_factory.mktemp("bal") / "res"
    rc = main(["balance", str(SURVEY), "--out", str(out), "--no-fit", "--no-plots", "--quiet"])
    assert rc == 0
    return out, json.loads((out / "summary.json").read_text())


def _close(shown: float, v: float) -> bool:
    """``shown`` is ``v`` at 4 significant digits (integers >= 1e4 whole): within half a unit of the last digit."""
    half = 0.5 if abs(v) >= 1e4 else 0.5 * 10 ** (math.floor(math.log10(abs(v))) - 3) if v else 0
    return abs(shown - v) <= half * (1 + 1e-9) + 1e-300


def check_numbers(text: str, summary: dict) -> dict:
    """Every keyed number (table cells; the first number of a keyed drawing label line)
    equals summary.json's at the digits shown; returns the count per first key part."""
    p = Cells()
    p.feed(text)
    counts = {}
    for key, scale, shown in p.cells:
        value = _get(summary, key)
        if value is None:
            assert shown.strip() == "-", (key, shown)
            continue
        if isinstance(value, bool):
            continue
        m = NUM.search(shown)
        assert m, (key, shown)
        assert _close(float(m.group()), value * scale), (key, shown, value)
        counts[key.split(".")[0]] = counts.get(key.split(".")[0], 0) + 1
    return counts


def _expectations(text: str, summary: dict, counts: dict) -> None:
    streams = summary["streams"]
    n_meas = len(summary["measurements"])
    assert n_meas > 50
    # every stream: measured and adjusted solids with SD, water, % solids, P80, P50 in the table; label lines
    assert counts["streams"] >= 8 * len(streams)
    assert counts["measurements"] >= 6 * n_meas  # measured, SD, adjusted, its SD, adjustment in SDs, normalised
    assert counts["chi_square"] == 5 and counts["circulating_load"] == 2
    for name, s in streams.items():
        label = text.split(f'<g class="stream-label" data-stream="{name}">')[1].split("</g>")[0]
        assert f"{fmt(s['solids_tph'])} &#177; {fmt(s['solids_sd_tph'], 2)} t/h solids" in label
        assert f"{fmt(s['water_tph'])} t/h water, {fmt(s['solids_content_pct'])} % solids" in label
        assert f"P80 {fmt(s['p80_um'])} um" in label
    chi = summary["chi_square"]
    assert f"SSR {fmt(chi['ssr'])} on {chi['dof']} degrees of freedom" in text
    for c in summary["gross_error_candidates"]:
        assert c["measurement"] in text.split("Gross-error candidates")[1]
    assert summary["input_sha256"] == hashlib.sha256(SURVEY.read_bytes()).hexdigest()
    assert summary["input_sha256"] in text and summary["millflow_version"] in text
    assert "http://" not in text.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "https://" not in text


def test_summary_carries_what_the_report_shows(balanced):
    _, s = balanced
    # the example plants an 8-point % solids error the balance names
    assert s["gross_error_candidates"], "the example's planted gross error is not named"
    for n, v in s["streams"].items():
        cls = [c for c in v["class_tph"]]
        assert len(cls) == len(s["classes"]) == len(s["sieves_um"]) + 1
        assert math.isclose(sum(cls), v["solids_tph"], rel_tol=1e-10), n
        # the adjusted passing is the class flows' cumulative from the fine end
        below = [sum(cls[k + 1:]) / v["solids_tph"] * 100 for k in range(len(s["sieves_um"]))]
        assert all(math.isclose(a, b, abs_tol=1e-9) for a, b in zip(below, v["passing_adjusted_pct"]))
        # P80 lies between the sieves whose passing brackets 80 %
        P = v["passing_adjusted_pct"]
        k = next(i for i in range(len(P) - 1) if P[i] >= 80 > P[i + 1])
        assert s["sieves_um"][k + 1] <= v["p80_um"] <= s["sieves_um"][k]
    for m in s["measurements"]:
        if m["sd"]:
            assert math.isclose(m["adjustment_in_sd"], (m["adjusted"] - m["measured"]) / m["sd"], rel_tol=1e-9,
                                abs_tol=1e-12)


def test_page_numbers_are_summary_json(balanced):
    out, summary = balanced
    text = (out / "report.html").read_text()
    _expectations(text, summary, check_numbers(text, summary))


def test_page_in_headless_chromium(balanced):
    out, summary = balanced
    dom = render(out / "report.html")  # no console messages, rendered, no overlapping boxes
    counts = check_numbers(dom, summary)
    assert counts["streams"] >= 8 * len(summary["streams"]) and counts["measurements"] > 300


@pytest.mark.skipif(not excel_available(), reason="openpyxl not installed (pip install 'millflow[report]')")
def test_workbook_numbers_are_summary_json(balanced):
    import openpyxl

    out, summary = balanced
    wb = openpyxl.load_workbook(out / "results.xlsx")
    keys = {"solids measured t/h": "solids_measured_tph", "solids adjusted t/h": "solids_tph",
            "solids SD t/h": "solids_sd_tph", "water measured t/h": "water_measured_tph",
            "water adjusted t/h": "water_tph", "water SD t/h": "water_sd_tph",
            "% solids measured": "solids_content_measured_pct", "% solids adjusted": "solids_content_pct",
            "P80 adjusted um": "p80_um", "P50 adjusted um": "p50_um"}
    rows = list(wb["Streams"].values)
    head = rows[0]
    assert set(keys) <= set(head)
    n = 0
    for row in rows[1:]:
        s = summary["streams"][row[0]]
        for h, v in zip(head, row):
            if h in keys:
                assert (v is None) == (s[keys[h]] is None), (row[0], h)
                if v is not None:
                    assert math.isclose(v, s[keys[h]], rel_tol=1e-12), (row[0], h)
                    n += 1
    assert n == sum(s[k] is not None for s in summary["streams"].values() for k in keys.values()) >= 40
    # size-by-stream balance: classes x streams, a total row equal to the stream's adjusted solids
    rows = list(wb["Size tph"].values)
    names = rows[0][1:]
    assert [r[0] for r in rows[1:-1]] == summary["classes"] and rows[-1][0] == "total"
    for j, name in enumerate(names, start=1):
        cls = [r[j] for r in rows[1:-1]]
        assert all(math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12)
                   for a, b in zip(cls, summary["streams"][name]["class_tph"]))
        assert math.isclose(sum(cls), rows[-1][j], rel_tol=1e-10)
        assert math.isclose(rows[-1][j], summary["streams"][name]["solids_tph"], rel_tol=1e-12)
    rows = list(wb["Size % passing"].values)
    for j, name in enumerate(rows[0][1:], start=1):
        assert [r[j] for r in rows[1:]] == pytest.approx(summary["streams"][name]["passing_adjusted_pct"], rel=1e-12)
    rows = list(wb["Measurements"].values)
    assert len(rows) - 1 == len(summary["measurements"])
    for r, m in zip(rows[1:], summary["measurements"]):
        assert r[0] == m["key"]
        for h, v in zip(rows[0], r):
            if h in ("measured", "sd", "adjusted", "adjusted_sd", "adjustment_in_sd") and m[h] is not None:
                assert math.isclose(v, m[h], rel_tol=1e-12, abs_tol=1e-15), (m["key"], h)
    about = dict(r for r in wb["About"].values)
    assert about["chi-square SSR"] == pytest.approx(summary["chi_square"]["ssr"], rel=1e-12)
    for n_, c in summary["circulating_load"].items():
        assert about[f"circulating load {n_} %"] == pytest.approx(c["value_pct"], rel=1e-12)
        assert about[f"circulating load {n_} SD %"] == pytest.approx(c["sd_pct"], rel=1e-12)


def test_report_staged_with_the_other_outputs(tmp_path, monkeypatch, capsys):
    """A failure while writing the report leaves no output folder (whole or not at all)."""
    import millflow.report.balance as rb

    def boom(*a, **k):
        raise RuntimeError("report failed")

    monkeypatch.setattr(rb, "write_balance_report", boom)
    out = tmp_path / "res"
    rc = main(["balance", str(SURVEY), "--out", str(out), "--no-fit", "--no-plots", "--quiet"])
    assert rc != 0 and "report failed" in capsys.readouterr().err
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_quiet_still_prints_the_results(capsys, tmp_path):
    rc = main(["balance", str(SURVEY), "--out", str(tmp_path / "q"), "--no-fit", "--no-plots", "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "weighted SSR" in out and "report.html" in out
