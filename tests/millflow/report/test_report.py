"""report.html and results.xlsx of `millflow run`: the numbers shown are summary.json's,
the page renders in a real browser (headless Chromium) without console errors, and the
flowsheet drawing has no overlapping boxes."""
import json
import math
import shutil
import subprocess
from html.parser import HTMLParser

import pytest

from millflow.cli import main
from millflow.report.excel import excel_available
from millflow.report.flowsheet import _get, flowsheet_layout_of
from millflow.report.layout import crossings, layout, overlaps
from tests import paths

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


@pytest.fixture(scope="module", params=["closed_circuit_wet_cyclones", "open_circuit_ball_mill"])
def result(request, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "res"
    rc = main(["run", str(paths.FLOWSHEETS / f"{request.param}.toml"), "--out", str(out), "--no-grid-check",
               "--no-plots", "--quiet"])
    assert rc == 0
    return out, json.loads((out / "summary.json").read_text())


class Cells(HTMLParser):
    """(data-key, data-scale, text) of every element with a data-key, and <body>'s attributes."""

    def __init__(self):
        super().__init__()
        self.cells, self.body, self._open = [], {}, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "body":
            self.body = a
        if "data-key" in a:
            self._open = [a["data-key"], float(a.get("data-scale", 1)), ""]

    def handle_data(self, data):
        if self._open is not None:
            self._open[2] += data

    def handle_endtag(self, tag):
        if self._open is not None and tag in ("td", "text"):
            self.cells.append(tuple(self._open))
            self._open = None


def check_numbers(text: str, summary: dict) -> int:
    """Every number shown equals summary.json's at the 4 significant digits shown."""
    p = Cells()
    p.feed(text)
    n = 0
    for key, scale, shown in p.cells:
        value = _get(summary, key)
        if value is None:
            assert shown.strip() == "-", key
            continue
        v = value * scale
        s = float(shown)
        # shown at 4 significant digits (integers >= 1e4 whole): half a unit of the last digit
        half = 0.5 if abs(v) >= 1e4 else 0.5 * 10 ** (math.floor(math.log10(abs(v))) - 3) if v else 0
        assert abs(s - v) <= half * (1 + 1e-9) + 1e-300, (key, shown, v)
        n += 1
    return n


def test_page_numbers_are_summary_json(result):
    out, summary = result
    text = (out / "report.html").read_text()
    n = check_numbers(text, summary)
    wet = any("water_tph" in s for s in summary["streams"].values())
    per_stream = 7 if wet else 5  # solids, (water, % solids), P80, P50, two named sizes
    assert n >= per_stream * len(summary["streams"]) + len(summary["units"])
    assert "http://" not in text.replace('xmlns="http://www.w3.org/2000/svg"', "")  # nothing from the network
    assert "https://" not in text
    assert summary["input_sha256"] in text and summary["millflow_version"] in text
    # the stream labels of the drawing: every stream's solids t/h, P80 (and water, % solids)
    for name, s in summary["streams"].items():
        from millflow.report.html import fmt

        label = text.split(f'<g class="stream-label" data-stream="{name}">')[1].split("</g>")[0]
        assert f"{fmt(s['solids_tph'])} t/h solids" in label and f"P80 {fmt(s['p80_um'])} um" in label
        if wet:
            assert f"{fmt(s['water_tph'])} t/h water, {fmt(s['solids_content_pct'])} % solids" in label


def _browser():
    return next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)


def render(page) -> str:
    """The DOM of ``page`` after headless Chromium loaded it; fails on any console message
    and unless the page's script marked it rendered with no overlapping boxes."""
    browser = _browser()
    if browser is None:
        pytest.skip("no Chromium or Chrome on this machine (.ci/run installs chromium with apt-get)")
    proc = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr",
                           "--v=0", "--virtual-time-budget=5000", "--dump-dom", page.resolve().as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line]
    assert not console, console
    p = Cells()
    p.feed(proc.stdout)
    assert p.body.get("data-rendered") == "ok", proc.stdout[:2000]
    assert p.body.get("data-overlaps") == "0"  # boxes and their text as the browser laid them out
    assert p.body.get("data-spills") == "0"  # no line of text outside its box
    return proc.stdout


def test_page_renders_in_headless_chromium(result):
    out, summary = result
    dom = render(out / "report.html")
    assert check_numbers(dom, summary) > 0  # the numbers the browser shows


@pytest.mark.skipif(not excel_available(), reason="openpyxl not installed (pip install 'millflow[report]')")
def test_workbook_numbers_are_summary_json(result):
    import openpyxl

    out, summary = result
    wb = openpyxl.load_workbook(out / "results.xlsx")
    rows = list(wb["Streams"].values)
    head = rows[0]
    for row in rows[1:]:
        s = summary["streams"][row[0]]
        got = dict(zip(head, row))
        for col, key in (("solids t/h", "solids_tph"), ("water t/h", "water_tph"), ("% solids", "solids_content_pct"),
                         ("P80 um", "p80_um"), ("P50 um", "p50_um")):
            if key in s:
                assert got[col] == pytest.approx(s[key], rel=1e-12)
        for x, v in s["passing_pct"].items():
            assert got[f"% passing {x} um"] == pytest.approx(v, rel=1e-12)
    # size-by-stream balance: the classes add up to the stream, and at a mixer/mill the
    # inlets' classes add up to what enters (here: the totals, to rounding)
    size = list(wb["Size tph"].values)
    names = size[0][1:]
    classes, total = size[1:-1], size[-1]
    assert total[0] == "total"
    for j, name in enumerate(names, start=1):
        assert math.fsum(r[j] for r in classes) == pytest.approx(summary["streams"][name]["solids_tph"], rel=1e-12)
        assert total[j] == pytest.approx(summary["streams"][name]["solids_tph"], rel=1e-12)
    passing = list(wb["Size % passing"].values)
    for j, name in enumerate(passing[0][1:], start=1):
        for k, r in enumerate(passing[1:]):
            want = summary["streams"][name]["cum_passing"][k]
            assert r[j] == pytest.approx(100 * want, rel=1e-12)


@pytest.mark.parametrize("path", sorted(paths.FLOWSHEETS.glob("*.toml")), ids=lambda p: p.stem)
def test_no_label_collisions_in_shipped_flowsheets(path):
    from millflow.flowsheet import load

    fs = load(path)
    for lines in (3, 4):
        lay = layout({u: x.type for u, x in fs.units.items()},
                     {n: (s.source, s.target) for n, s in fs.streams.items()}, lines)
        assert overlaps(lay) == []
        assert crossings(lay.units, lay.routes, {n: (s.source, s.target) for n, s in fs.streams.items()}) == []
        # every box inside the drawing
        for b in list(lay.units.values()) + list(lay.labels.values()):
            assert 0 <= b.x - b.w / 2 and b.x + b.w / 2 <= lay.width
            assert 0 <= b.y - b.h / 2 and b.y + b.h / 2 <= lay.height


@pytest.mark.parametrize("recycles", [0, 1, 4])
def test_twenty_unit_circuits_stay_legible(recycles):
    units = {"feed": "feed"}
    streams, prev = {}, "feed"
    for k in range(18):
        units[f"m{k}"] = "mill"
        streams[f"s{k}"] = (prev, f"m{k}")
        prev = f"m{k}"
    units["p"] = "product"
    streams["out"] = (prev, "p")
    for k in range(3, 3 + 4 * recycles, 4):
        streams[f"r{k}"] = (f"m{k}", f"m{k - 2}")
    lay = layout(units, streams, 4)
    assert len(lay.units) == 20 and overlaps(lay) == [] and crossings(lay.units, lay.routes, streams) == []
    assert lay.width < 2000  # wrapped onto rows, not one 7000 px line


def test_layout_of_summary_matches_units(result):
    _, summary = result
    lay = flowsheet_layout_of(summary)
    assert set(lay.units) == set(summary["units"]) and set(lay.labels) == set(summary["streams"])


def test_png_labels_equal_report_labels():
    """flowsheet.png's labels (from the flows) are the report's (from the Dataset/summary)."""
    from millflow.flowsheet import load, solve, to_dataset
    from millflow.flowsheet.plots import _flowsheet_labels

    sol = solve(load(paths.FLOWSHEETS / "closed_circuit_wet_cyclones.toml"))
    assert _flowsheet_labels(sol) == _flowsheet_labels(sol, to_dataset(sol))


def test_branched_circuit_routes_avoid_unit_boxes():
    """Two feeds, a splitter into two cyclone lines, a regrind loop across rows, a screen
    fed by both overflows: straight lines would cross cyclones_2, regrind_chute and screen."""
    units = {"feed_a": "feed", "feed_b": "feed", "chute": "mixer", "primary_mill": "mill", "splitter": "splitter",
             "cyclones_1": "hydrocyclone", "cyclones_2": "hydrocyclone", "regrind_chute": "mixer",
             "regrind_mill": "mill", "screen": "screen", "final": "product", "oversize_bin": "product"}
    streams = {"fa": ("feed_a", "chute"), "fb": ("feed_b", "chute"), "mill_feed": ("chute", "primary_mill"),
               "discharge": ("primary_mill", "splitter"), "l1": ("splitter", "cyclones_1"),
               "l2": ("splitter", "cyclones_2"), "u1": ("cyclones_1", "chute"), "u2": ("cyclones_2", "regrind_chute"),
               "regrind_feed": ("regrind_chute", "regrind_mill"), "regrind_out": ("regrind_mill", "cyclones_2"),
               "o1": ("cyclones_1", "screen"), "o2": ("cyclones_2", "screen"), "scr_over": ("screen", "oversize_bin"),
               "scr_under": ("screen", "final")}
    for lines in (3, 4):
        lay = layout(units, streams, lines)
        assert overlaps(lay) == [] and crossings(lay.units, lay.routes, streams) == []
        xs = [x for r in lay.routes.values() for x, _ in r]
        assert max(xs) <= lay.width and min(xs) >= 0
