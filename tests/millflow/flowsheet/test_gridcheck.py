"""Principle IV for circuits: the refined-grid check reports how far P80, P50 and
circulating loads move, and says when the grid is too coarse."""
import re

import pytest

import numpy as np

from millflow.flowsheet import from_dict, load, loads, solve
from millflow.flowsheet.gridcheck import grid_check, refine_document
from tests.paths import FLOWSHEETS
from tests.closed_circuit import per_time_text

CIRCUIT = FLOWSHEETS / "closed_circuit_ball_mill.toml"


def test_refine_document_halves_every_class():
    assert refine_document({"grid": {"ratio": 4.0}})["grid"]["ratio"] == 2.0
    assert refine_document({"grid": {"n": 10}})["grid"]["n"] == 19
    edges = refine_document({"grid": {"edges_um": [400, 100, 25]}})["grid"]["edges_um"]
    assert edges == pytest.approx([400, 200, 100, 50, 25], rel=1e-15)


def test_refined_document_keeps_every_edge_of_the_grid():
    fs = load(CIRCUIT)
    doc = refine_document(fs.meta["document"], 2, fs.grid)
    fine = from_dict(doc)
    assert fine.grid.n == 2 * fs.grid.n - 1
    np.testing.assert_array_equal(fine.grid.x[::2], fs.grid.x)  # nested: the sink edge too


def test_coarse_grid_is_said_too_coarse_and_fine_grid_passes():
    # Austin's upper-edge scheme at 2^(1/4): first order, P50 moves ~7 % on refinement and the
    # grid error (3 x 2 x the change) is ~40 %, far above the 0.5 % threshold
    coarse = loads(re.sub(r"(?m)^ratio = .*$", 'ratio = 1.189207115\nscheme = "upper_edge"', per_time_text()))
    g = grid_check(solve(coarse))
    assert g["status"] == "grid too coarse" and g["order"] == 1 and 0.2 < g["worst"] < 0.6
    assert set(g["streams"]) == set(coarse.stream_names) and "underflow" in g["circulating_load"]
    # the class-averaged scheme at 2^(1/2) is still too coarse (grid error ~3 %)
    half = loads(re.sub(r"(?m)^ratio = .*$", "ratio = 1.4142135623730951", per_time_text()))
    assert grid_check(solve(half))["status"] == "grid too coarse"
    fine = grid_check(solve(load(CIRCUIT)))
    assert fine["status"] == "ok" and fine["worst"] <= 0.005 and fine["refined_classes"] > 300


def test_flowsheet_without_document_says_not_available():
    fs = load(CIRCUIT)
    fs.meta.pop("document")
    assert grid_check(solve(fs))["status"] == "not available"


def test_breakage_table_on_the_default_grid_says_why_no_grid_check(tmp_path):
    """A b matrix given per class is the discrete model: the refined grid cannot carry it,
    and the check says so (not a failed run)."""
    from millflow.breakage import NormalizedBreakage

    text = CIRCUIT.read_text()
    fs = load(CIRCUIT)
    np.savetxt(tmp_path / "b.csv", NormalizedBreakage(0.55, 0.8, 3.5).b(fs.grid.x), delimiter=",", fmt="%.17g")
    text = text.replace('breakage = {form = "normalized", phi = 0.55, gamma = 0.8, beta = 3.5}',
                        'breakage = {form = "table", file = "b.csv", matrix = "b"}')
    (tmp_path / "fs.toml").write_text(text)
    g = grid_check(solve(load(tmp_path / "fs.toml")))
    assert g["status"] == "not available" and "discrete model itself" in g["reason"]
