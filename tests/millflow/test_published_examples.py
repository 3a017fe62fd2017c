"""Published worked examples (complete inputs and printed results) reproduced with millflow.

Each test cites where the example was published and what it prints; the expected values
are the published figures, and every tolerance is the printed rounding of the example
(stated per test). The sources are web pages with worked examples: no textbook example of
the Plitt or Nageswararao cyclone models with complete numbers was reachable (see
tests/millflow/test_cyclones.py), so these cover the slurry and balance arithmetic that a
plant survey feeds into a flowsheet.
"""
import math

import pytest

import millflow as mf
from millflow.balances import circulating_load, dilution, three_product, two_product
from millflow.cyclones import CycloneFeed
from millflow.errors import InputError
from millflow.flowsheet import solve
from millflow.flowsheet.results import circulating_loads, stream_properties
from millflow.flowsheet.water import Slurry, slurry_properties

# ------------------------------------------------------------------ slurry properties


def test_slurry_density_processconvert_worked_example():
    """processconvert.com, "Slurry Density Calculator", worked example (2025 page
    https://www.processconvert.com/calculators/slurry-density): water 1000 kg/m3, solids
    2650 kg/m3, 30 % solids by mass -> slurry density 1229.7 kg/m3, solids volume fraction
    0.139211 (13.9211 %), liquid volume fraction 0.860789. Tolerances: half a unit of the last
    printed digit (0.05 kg/m3; 5e-7 on the fractions)."""
    props = slurry_properties(0.30, 0.70, Slurry(2650.0, 1000.0))  # 0.3 kg/s solids + 0.7 kg/s water
    assert props["pulp_density_kg_m3"] == pytest.approx(1229.7, abs=0.05)
    assert props["solids_volume_fraction"] == pytest.approx(0.139211, abs=5e-7)
    assert 1.0 - props["solids_volume_fraction"] == pytest.approx(0.860789, abs=5e-7)
    assert props["solids_content"] == pytest.approx(0.30, rel=1e-15)
    # the cyclone models' feed takes the same volume fraction from the mass flows
    assert CycloneFeed.from_flows(0.70, 0.30, 2650.0).solids_volume_fraction == pytest.approx(0.139211, abs=5e-7)
    assert CycloneFeed.from_flows(0.70, 0.30, 2650.0).slurry_density_kg_m3 == pytest.approx(1229.7, abs=0.05)


def test_slurry_density_engineering_toolbox_example():
    """The Engineering ToolBox, "Slurry Density" (https://www.engineeringtoolbox.com/
    slurry-density-d_1188.html), example: solids 2500 kg/m3, liquid 1000 kg/m3, 30 % solids by
    weight -> 1220 kg/m3. The page prints three significant figures (the formula gives
    1219.5), so the tolerance is half a unit of the printed tens: 5 kg/m3."""
    props = slurry_properties(30.0, 70.0, Slurry(2500.0, 1000.0))
    assert props["pulp_density_kg_m3"] == pytest.approx(1220.0, abs=5.0)


# ------------------------------------------------------------------ two- and three-product formulas


def test_two_product_formula_processconvert_worked_example():
    """processconvert.com, "Two Product Formula Calculator", worked example
    (https://www.processconvert.com/calculators/two-product-formula): feed 1.0 % Cu,
    concentrate 10.0 % Cu, tailing 0.2 % Cu -> mass yield 8.163 % (calculator: 8.16327 %),
    recovery 81.63 % (81.6327 %), ratio of concentration 12.25, enrichment ratio 10. Tolerance:
    half a unit of the calculator's sixth significant digit."""
    y = two_product(1.0, 10.0, 0.2)
    assert 100 * y == pytest.approx(8.16327, abs=5e-6)
    assert 100 * y * 10.0 / 1.0 == pytest.approx(81.6327, abs=5e-5)
    assert 1 / y == pytest.approx(12.25, abs=5e-3)


def test_three_product_formula_processconvert_worked_example():
    """processconvert.com, "Three Product Formula Calculator", worked example
    (https://www.processconvert.com/calculators/three-product-formula): a Pb-Zn circuit, feed
    3.0 % Pb / 6.0 % Zn, lead concentrate 50 % Pb / 8 % Zn, zinc concentrate 2 % Pb / 55 % Zn,
    tailing 0.2 % Pb / 0.5 % Zn -> yields 5.28401 %, 9.36459 %, 85.3514 %; recoveries Pb to
    the lead concentrate 88.0668 %, Pb to the zinc concentrate 6.24306 %, Zn to the lead
    concentrate 7.04535 %, Zn to the zinc concentrate 85.842 %. Tolerance: half a unit of the
    sixth printed significant digit."""
    c1, c2, t = three_product((3.0, 6.0), (50.0, 8.0), (2.0, 55.0), (0.2, 0.5))
    assert (100 * c1, 100 * c2) == pytest.approx((5.28401, 9.36459), abs=5e-6)
    assert 100 * t == pytest.approx(85.3514, abs=5e-5)
    assert 100 * c1 * 50.0 / 3.0 == pytest.approx(88.0668, abs=5e-5)
    assert 100 * c2 * 2.0 / 3.0 == pytest.approx(6.24306, abs=5e-6)
    assert 100 * c1 * 8.0 / 6.0 == pytest.approx(7.04535, abs=5e-6)
    assert 100 * c2 * 55.0 / 6.0 == pytest.approx(85.842, abs=5e-4)
    # the page's closure check, per 100 t of feed: 300 t Pb-% and 600 t Zn-% in the products
    assert 100 * (c1 * 50.0 + c2 * 2.0 + t * 0.2) == pytest.approx(300.0, rel=1e-12)
    assert 100 * (c1 * 8.0 + c2 * 55.0 + t * 0.5) == pytest.approx(600.0, rel=1e-12)


def test_three_product_formula_cu_zn_solution_on_scribd():
    """A worked Cu-Zn solution uploaded to Scribd ("Mining", document 701846579, part a):
    3000 t/d of feed at 2.3 % Cu and 15 % Zn; copper concentrate 22 % Cu, 4.3 % Zn; zinc
    concentrate 1 % Cu, 51.8 % Zn; tailing 0.2 % Cu, 1 % Zn -> C = 259.2 t/d, Z = 810 t/d,
    T = 1930.8 t/d, recoveries 82.64 % Cu and 93.24 % Zn. The solution prints C truncated to
    0.1 t/d (the balance gives 259.27) and computes the recoveries from its rounded C and Z, so
    the tolerances are 0.1 t/d on the tonnages and 0.05 points on the recoveries."""
    c1, c2, t = three_product((2.3, 15.0), (22.0, 4.3), (1.0, 51.8), (0.2, 1.0))
    feed = 3000.0
    assert (feed * c1, feed * c2, feed * t) == pytest.approx((259.2, 810.0, 1930.8), abs=0.1)
    assert 100 * c1 * 22.0 / 2.3 == pytest.approx(82.64, abs=0.05)
    assert 100 * c2 * 51.8 / 15.0 == pytest.approx(93.24, abs=0.05)


def test_balance_formulas_refuse_inconsistent_assays():
    with pytest.raises(InputError, match="inconsistent"):
        two_product(12.0, 10.0, 0.2)  # the feed richer than the concentrate
    with pytest.raises(InputError, match="told apart"):
        two_product(1.0, 0.2, 0.2)
    with pytest.raises(InputError, match="told apart"):
        three_product((3.0, 6.0), (50.0, 8.0), (100.0, 16.0), (0.0, 0.0))
    with pytest.raises(InputError, match="mass fraction"):
        dilution(0.0)


# ------------------------------------------------------------------ circulating load from % solids

# goldmetallurgy.com, "Determination of Circulating Load"
# (http://www.goldmetallurgy.com/determination-circulating-load): a closed ball mill -
# hydrocyclone circuit surveyed by % solids (dilution L/S): fresh feed 94 % (0.0638), ball
# mill discharge 70 % (0.4286), hydrocyclone feed 58 % (0.7241), overflow 35 % (1.8571),
# underflow 78.7 % (0.2709); circulating load (o - f)/(f - u) = 2.5.
GOLDMET = {"fresh": 94.0, "mill_discharge": 70.0, "cyclone_feed": 58.0, "overflow": 35.0, "underflow": 78.7}


def test_circulating_load_from_dilutions_goldmetallurgy():
    """The page's dilutions, printed to four decimals, give its circulating load 2.5 (to
    4e-5). From the % solids themselves the underflow's dilution is 0.27065, not the printed
    0.2709 (that is 78.69 % solids): the % solids give 2.4984, which rounds to the printed 2.5
    (one decimal: tolerance 0.05)."""
    assert circulating_load(0.7241, 0.2709, 1.8571) == pytest.approx(2.5, abs=4e-5)
    d = {k: dilution(v / 100) for k, v in GOLDMET.items()}
    assert [round(d[k], 4) for k in ("fresh", "mill_discharge", "cyclone_feed", "overflow")] == \
        [0.0638, 0.4286, 0.7241, 1.8571]
    assert circulating_load(d["cyclone_feed"], d["underflow"], d["overflow"]) == pytest.approx(2.5, abs=0.05)


def test_closed_circuit_water_balance_reproduces_goldmetallurgy_survey():
    """The goldmetallurgy.com survey above as a millflow flowsheet: 100 t/h of new feed at
    94 % solids, a cyclone that returns 2.5/3.5 of its feed solids at every size (the
    published circulating load; a Plitt curve with d50c far above the grid, so only its
    bypass classifies) with an underflow at 78.7 % solids, and the mill and sump water that
    bring the mill discharge to 70 % and the cyclone feed to 58 % (computed below from those
    published % solids). What millflow's water balance must then give is the overflow: the
    published 35 % solids.

    Tolerances: the set % solids are matched to 1e-9 (a linear solve); the overflow's % solids
    to 0.05 points, because the survey prints the underflow to 0.1 % (78.7 +- 0.05 moves the
    overflow by +-0.025 points) and the overflow itself only to the unit (35)."""
    new_feed, load = 100.0, 2.5  # t/h, underflow / new feed
    w = {k: dilution(v / 100) for k, v in GOLDMET.items()}
    mill_solids = new_feed * (1 + load)
    mill_water = mill_solids * w["mill_discharge"] - (new_feed * w["fresh"] + new_feed * load * w["underflow"])
    sump_water = mill_solids * (w["cyclone_feed"] - w["mill_discharge"])
    fs = mf.Flowsheet.from_dict({
        "grid": {"top_um": 4000, "bottom_um": 20, "n": 24},
        "slurry": {"solids_density_t_m3": 2.7},
        "materials": {"ore": {"rate": {"form": "power", "A_per_min": 0.5, "alpha": 1.0, "x0_um": 1000},
                              "breakage": {"form": "normalized", "phi": 0.5, "gamma": 0.8, "beta": 3.5}}},
        "units": {
            "fresh_feed": {"type": "feed", "solids_tph": new_feed, "solids_content_pct": GOLDMET["fresh"],
                           "psd": {"form": "ggs", "xmax_um": 4000, "m": 0.8}},
            "chute": {"type": "mixer"},
            "ball_mill": {"type": "mill", "material": "ore", "tau_min": 5, "add_water_tph": mill_water},
            "sump": {"type": "tank", "add_water_tph": sump_water},
            "cyclones": {"type": "hydrocyclone", "curve": "plitt", "d50c_um": 1e9, "m": 3.0,
                         "bypass": load / (1 + load), "coarse_solids_content_pct": GOLDMET["underflow"]},
            "overflow_product": {"type": "product"}},
        "streams": {
            "fresh": {"from": "fresh_feed", "to": "chute"},
            "mill_feed": {"from": "chute", "to": "ball_mill"},
            "mill_discharge": {"from": "ball_mill", "to": "sump"},
            "cyclone_feed": {"from": "sump", "to": "cyclones"},
            "underflow": {"from": "cyclones.underflow", "to": "chute"},
            "overflow": {"from": "cyclones.overflow", "to": "overflow_product"}}})
    sol = solve(fs)
    props = stream_properties(sol)
    pct = {name: 100 * p["solids_content"] for name, p in props.items()}

    assert circulating_loads(sol)["underflow"] == pytest.approx(load, rel=1e-9)
    for name in ("fresh", "mill_discharge", "cyclone_feed", "underflow"):
        assert pct[name] == pytest.approx(GOLDMET[name], rel=1e-9), name
    assert pct["overflow"] == pytest.approx(GOLDMET["overflow"], abs=0.05)
    # and the survey formula, applied to millflow's solved streams, returns its circulating load
    dil = {name: p["water_kg_s"] / p["solids_kg_s"] for name, p in props.items()}
    assert circulating_load(dil["cyclone_feed"], dil["underflow"], dil["overflow"]) == pytest.approx(
        circulating_loads(sol)["underflow"], rel=1e-9)
    # at steady state all the water fed or added leaves with the overflow [t/h]
    assert math.isclose(3.6 * props["overflow"]["water_kg_s"], new_feed * w["fresh"] + mill_water + sump_water,
                        rel_tol=1e-9)
