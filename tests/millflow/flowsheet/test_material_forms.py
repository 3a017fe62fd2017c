"""Material forms from TOML (issue 14 §2): Austin's rate with its ball-size terms, and a
user's b_ij or B_ij matrix from a CSV file."""
import numpy as np
import pytest

from millflow.breakage import AustinRate, NormalizedBreakage, b_from_B
from millflow.errors import InputError
from millflow.flowsheet import load, loads, solve

BASE = """
[grid]
top_um = 4000
bottom_um = 40
n = 14
[materials.ore]
RATE
BREAKAGE
[units.f]
type = "feed"
solids_tph = 10
psd = {form = "ggs", xmax_um = 4000, m = 0.8}
[units.mill]
type = "mill"
material = "ore"
tau_min = 5
transport = {model = "tanks_in_series", n = 3}
[units.p]
type = "product"
[streams]
s1 = {from = "f", to = "mill"}
s2 = {from = "mill", to = "p"}
"""
POWER = 'rate = {form = "power", A_per_min = 0.6, alpha = 1.1}'
NORMAL = 'breakage = {form = "normalized", phi = 0.5, gamma = 0.8, beta = 3.0}'


def _fs(tmp_path, rate=POWER, breakage=NORMAL, scheme=None):
    p = tmp_path / "fs.toml"
    text = BASE.replace("RATE", rate).replace("BREAKAGE", breakage)
    if scheme:
        text = text.replace("[grid]", f'[grid]\nscheme = "{scheme}"', 1)
    p.write_text(text)
    return load(p)


def test_austin_rate_with_ball_size_terms_is_the_library_form(tmp_path):
    fs = _fs(tmp_path, rate='rate = {form = "austin", A_per_min = 0.6, alpha = 1.1, mu_um = 2000, Lambda = 2.5, '
                           'x_b_mm = 40, x_b0_mm = 30, xi = 0.8, eta = 0.5}')
    ref = AustinRate(0.6 / 60, 1.1, 2e-3, 2.5, xi=0.8, x_b=0.04, x_b0=0.03, eta=0.5, x0=1e-3)
    np.testing.assert_allclose(fs.units["mill"].rate(fs.grid.x), ref(fs.grid.x), rtol=1e-15)


@pytest.mark.parametrize("kind", ["B", "b"])
def test_breakage_matrix_from_csv_equals_the_form(tmp_path, kind):
    # a table is the discrete model itself, used as given: it equals the form evaluated at
    # the upper edges (Austin's scheme), with the same rates at the upper edges
    fs0 = _fs(tmp_path, scheme="upper_edge")
    B = NormalizedBreakage(0.5, 0.8, 3.0).B(fs0.grid.x)
    np.savetxt(tmp_path / "m.csv", B if kind == "B" else b_from_B(B), delimiter=",", fmt="%.17g")
    fs = _fs(tmp_path, breakage=f'breakage = {{form = "table", file = "m.csv", matrix = "{kind}"}}')
    assert fs.units["mill"].discretisation(fs.grid) == "discrete (as given)"
    a, b = solve(fs0).flow("s2"), solve(fs).flow("s2")
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-15 * a.sum())  # %.17g round-trips exactly


def test_breakage_matrix_of_the_wrong_size_is_named(tmp_path):
    np.savetxt(tmp_path / "m.csv", np.eye(5), delimiter=",")
    with pytest.raises(InputError, match="5 x 5 matrix but the grid has 14 classes"):
        _fs(tmp_path, breakage='breakage = {form = "table", file = "m.csv", matrix = "B"}')


def test_ball_size_needs_both_sizes():
    text = BASE.replace("RATE", 'rate = {form = "austin", A_per_min = 0.6, alpha = 1.1, mu_um = 2000, '
                                'Lambda = 2.5, x_b_mm = 40}').replace("BREAKAGE", NORMAL)
    with pytest.raises(InputError, match="give both ball sizes"):
        loads(text)
