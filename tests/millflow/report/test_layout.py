"""The flowsheet drawing stays legible: boxes sized to their text (a wet label's longest
line fits, a long name is broken onto two lines or shortened), no box over another and
no route through a unit, on seeded random branched circuits of 20 units; the same
checked in headless Chromium on the boxes and text as the browser lays them out."""
import re

import pytest

from millflow.report.flowsheet import stream_label, unit_lines
from millflow.report.html import flowsheet_svg, page
from millflow.report.layout import crossings, layout, overlaps
from millflow.report.textsize import box_size, name_lines, text_width
from tests.millflow.report.circuits import random_circuit
from tests.millflow.report.test_report import render

WET = {"solids_tph": 524.1226, "water_tph": 128.7627, "solids_content_pct": 80.27790, "p80_um": 792.65}


def test_text_width_is_the_font_advance():
    # DejaVu Sans: digits 0.636 em, "m" 0.974 em, space 0.318 em; 4 % head-room
    assert text_width("00", 12.0) == pytest.approx(2 * 0.636 * 12 * 1.04, rel=1e-12)
    assert text_width("m m", 10.0) == pytest.approx((2 * 0.974 + 0.318) * 10 * 1.04, rel=1e-12)
    assert text_width("&#177;", 12.0) == text_width("\u00b1", 12.0, escaped=False)  # measured as shown
    assert text_width("ab", 12.0, bold=True) > text_width("ab", 12.0)


def test_wet_label_box_holds_its_longest_line():
    lines = stream_label("mill_feed", WET)
    assert "128.8 t/h water, 80.28 % solids" in lines
    w, h = box_size(lines)
    assert w >= text_width("128.8 t/h water, 80.28 % solids") + 16  # 8 px each side
    assert h == pytest.approx(15 * len(lines) + 6)
    lay = layout({"a": "feed", "b": "product"}, {"mill_feed": ("a", "b")}, label_text={"mill_feed": lines})
    assert lay.labels["mill_feed"].w == pytest.approx(w)


@pytest.mark.parametrize("name", ["secondary_cyclone_cluster_overflow_to_flotation_conditioning_tank_number_2",
                                  "x" * 90, "a long stream name with spaces in it and more words still"])
def test_long_names_are_broken_or_shortened(name):
    lines = name_lines(name)
    assert 1 <= len(lines) <= 2
    assert all(text_width(t, bold=True, escaped=False) <= 190.0 for t in lines)
    joined = "".join(lines).replace(" ", "")
    if lines[-1].endswith("\u2026"):
        assert name.replace(" ", "").startswith(joined[:-1])  # shortened: the beginning, then an ellipsis
    else:
        assert joined == name.replace(" ", "")
    if "_" in name:
        assert lines[0].endswith("_")  # broken after a separator where it can be


def test_short_names_stay_whole():
    assert name_lines("overflow") == ["overflow"]
    assert unit_lines("ball_mill", "mill") == ["ball_mill", "mill"]


SEEDS = range(200)


@pytest.mark.parametrize("seed", SEEDS)
def test_random_branched_circuits_have_no_collisions(seed):
    units, streams, labels = random_circuit(seed)
    assert len(units) == 20
    lay = layout(units, streams, label_text=labels, unit_text={u: unit_lines(u, k) for u, k in units.items()})
    assert overlaps(lay) == []
    assert crossings(lay.units, lay.routes, streams) == []
    for n, b in lay.labels.items():  # every label sized to its text, inside the drawing
        assert b.w >= max(text_width(t, bold=k == 0) for k, t in enumerate(labels[n])) + 16 - 1e-9
        assert 0 <= b.x - b.w / 2 and b.x + b.w / 2 <= lay.width and 0 <= b.y - b.h / 2 <= b.y + b.h / 2 <= lay.height


def test_random_circuits_render_without_overlaps_in_chromium(tmp_path):
    """Forty random circuits on one page: the page's script counts, on the browser's own
    layout, pairs of boxes (with their text) that overlap and lines of text outside their box."""
    svgs = []
    for seed in range(40):
        units, streams, labels = random_circuit(seed)
        ut = {u: unit_lines(u, k) for u, k in units.items()}
        lay = layout(units, streams, label_text=labels, unit_text=ut)
        svgs.append((f"circuit {seed}", flowsheet_svg(lay, ut, labels)))
    path = tmp_path / "circuits.html"
    path.write_text(page("random circuits", svgs), encoding="utf-8")
    dom = render(path)
    assert len(re.findall(r'<svg[^>]*class="flowsheet"', dom)) == 40
