"""Mode "mill" (any rtd transport inside the fit) and a fixed B from the TOML config."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from millflow.breakage import b_from_B, normalized_B
from millflow.breakage.averaged import breakage_on_grid
from millflow.errors import InputError
from millflow.fitting.config import load_config
from millflow.fitting.data import psd_data_from_frames
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
from millflow.grid import SizeGrid

GRID = SizeGrid.geometric(4e-3, 2 ** 0.5, 16)
X = GRID.x


def _data(conds, locs, process, values=None):
    """Feed all in the top class; every sample measured at every grid edge. ``values``:
    (condition, location) -> cumulative passing (placeholder curve if absent)."""
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_m": X[:2], "passing": [1.0, 0.0]})]
    for c in conds:
        for loc in locs:
            v = np.linspace(1, 0, X.size) if values is None else values[(c, loc)]
            rows.append(pd.DataFrame({"condition": c, "location": loc, "size_m": X, "passing": v}))
    return psd_data_from_frames(pd.concat(rows, ignore_index=True), process, strict=False)


def _synthetic(model, theta, noise=0.0, seed=0):
    """Measured values of ``model`` at ``theta`` (+ noise), keyed like :func:`_data`."""
    y = model.predict(theta)
    y = y + noise * np.random.default_rng(seed).standard_normal(y.size)
    s = model.group_slices
    return {(model.conditions[c], loc): y[s[g]:s[g + 1]] for g, (c, loc, _) in enumerate(model.groups)}


PROC = pd.DataFrame({"condition": ["c1", "c2", "c3"], "tau_s": [60.0, 120.0, 240.0], "screen_mm": [1.0, 2.0, 1.5]})


@pytest.mark.parametrize("cls", [None, "screen"])
def test_mill_mode_equals_well_mixed_and_tanks(cls):
    theta = np.array([[-3.5, 1.0, 0.4, 0.8, 3.0, 0.0, 1.5], [-3.0, 0.7, 0.5, 1.0, 4.0, 0.2, 1.0]])
    theta = theta if cls else theta[:, :5]
    d = _data(["c1", "c2"], ["product", "holdup"], PROC)
    wm = ForwardModel(ModelSpec(mode="well_mixed", classification=cls, tau_column="tau_s"), d, GRID)
    mm = ForwardModel(ModelSpec(mode="mill", transport="perfect_mixing", classification=cls,
                                tau_column="tau_s"), d, GRID)
    np.testing.assert_allclose(mm.predict_grid(theta), wm.predict_grid(theta), rtol=0, atol=1e-10)
    d = _data(["c1", "c2"], ["product"], PROC)
    wm = ForwardModel(ModelSpec(mode="well_mixed", n_tanks=3, classification=cls, tau_column="tau_s"), d, GRID)
    # well_mixed n_tanks classifies at every tank outlet: where = "cells"
    mm = ForwardModel(ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 3},
                                where="cells" if cls else None, classification=cls, tau_column="tau_s"), d, GRID)
    np.testing.assert_allclose(mm.predict_grid(theta), wm.predict_grid(theta), rtol=0, atol=1e-10)
    np.testing.assert_allclose(mm.predict(theta), wm.predict(theta), rtol=0, atol=1e-10)


def test_the_modes_name_their_transport():
    """The fit's modes plug_flow and well_mixed stand for a transport of the mill layer."""
    from millflow.mill.transport import mode_transport
    assert mode_transport("plug_flow") == ("plug_flow", {}, "axis")
    assert mode_transport("well_mixed") == ("perfect_mixing", {}, "cells")
    assert mode_transport("well_mixed", 3) == ("tanks_in_series", {"n": 3}, "cells")
    assert mode_transport("mill", 1, "tis", {"n": 2}, None) == ("tanks_in_series", {"n": 2}, None)
    with pytest.raises(InputError, match="mode 'batch'"):
        mode_transport("batch")


def test_plug_flow_mode_classifies_along_the_axis_as_mode_mill():
    """Mode plug_flow with classification is plug flow with d* in the velocity (rates S/d*),
    the same as mode "mill" with plug flow: the classification is used, not dropped (the
    same batch solve in the contact time: 1e-12 on mass fractions <= 1)."""
    theta = np.array([[-3.5, 1.0, 0.4, 0.8, 3.0, 0.0, 1.5], [-3.0, 0.7, 0.5, 1.0, 4.0, 0.2, 1.0]])
    d = _data(["c1", "c2"], ["product"], PROC)
    pf = ForwardModel(ModelSpec(mode="plug_flow", classification="screen", tau_column="tau_s"), d, GRID)
    mm = ForwardModel(ModelSpec(mode="mill", transport="plug_flow", classification="screen", tau_column="tau_s"),
                      d, GRID)
    plain = ForwardModel(ModelSpec(mode="plug_flow", tau_column="tau_s"), d, GRID)
    np.testing.assert_allclose(pf.predict_grid(theta), mm.predict_grid(theta), rtol=0, atol=1e-12)
    assert np.abs(pf.predict_grid(theta) - plain.predict_grid(theta[:, :5])).max() > 1e-3


def test_well_mixed_tanks_predict_holdup_and_cell_samples():
    """Mode well_mixed with n_tanks = 3 reads hold-up and cell:K samples like mode "mill"
    with three tanks classified at every outlet (the same eq. 3 chain: 1e-12)."""
    theta = np.array([[-3.5, 1.0, 0.4, 0.8, 3.0, 0.0, 1.5], [-3.0, 0.7, 0.5, 1.0, 4.0, 0.2, 1.0]])
    d = _data(["c1", "c2"], ["product", "holdup", "cell:2"], PROC)
    wm = ForwardModel(ModelSpec(mode="well_mixed", n_tanks=3, classification="screen", tau_column="tau_s"), d, GRID)
    mm = ForwardModel(ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 3}, where="cells",
                                classification="screen", tau_column="tau_s"), d, GRID)
    np.testing.assert_allclose(wm.predict_grid(theta), mm.predict_grid(theta), rtol=0, atol=1e-12)
    with pytest.raises(InputError, match="cell:4"):
        ForwardModel(ModelSpec(mode="well_mixed", n_tanks=3, tau_column="tau_s"), _data(["c1"], ["cell:4"], PROC),
                     GRID)


def test_mill_mode_cell_samples():
    """Without classification the last of n tanks holds what it discharges: cell:n = product.
    Locations are spelled as steady_mill reads them (cell:K); the old cell_K is an alias."""
    d = _data(["c1"], ["cell:1", "cell_3", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 3},
                               tau_column="tau_s"), d, GRID)
    M = m.predict_grid(np.array([-3.5, 1.0, 0.4, 0.8, 3.0]))[0]
    g = {loc: k for k, (_, loc, _) in enumerate(m.groups)}
    assert set(g) == {"cell:1", "cell:3", "product"}
    np.testing.assert_allclose(M[g["cell:3"]], M[g["product"]], atol=1e-12)
    assert M[g["cell:1"]][0] > M[g["cell:3"]][0]  # coarser near the feed end
    with pytest.raises(InputError, match="cell:4.*'product', 'holdup' or 'cell:K' \\(K = 1..3\\)"):
        ForwardModel(m.spec, _data(["c1"], ["cell:4"], PROC), GRID)
    with pytest.raises(InputError, match="predicts 'product', 'holdup' or 'z:Y' \\(0 <= Y <= 1\\)$"):
        ForwardModel(ModelSpec(mode="mill", transport="axial_dispersion", transport_params={"pe": 5}),
                     _data(["c1"], ["cell:1"], PROC), GRID)


def test_mill_mode_axial_samples_match_steady_mill():
    """Samples at axial positions z:Y are predicted by steady_mill's profile (issue 15 §3)."""
    import rtd
    from millflow.breakage import NormalizedBreakage, PowerLawRate
    from millflow.mill import steady_mill
    d = _data(["c1"], ["z:0.5", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="plug_flow", tau_column="tau_s"), d, GRID)
    theta = np.array([-3.5, 1.0, 0.4, 0.8, 3.0])
    M = m.predict_grid(theta)[0]
    g = {loc: k for k, (_, loc, _) in enumerate(m.groups)}
    tau = float(m._proc["tau_s"][0])
    S, b, _ = breakage_on_grid(PowerLawRate(np.exp(-3.5), 1.0), NormalizedBreakage(0.4, 0.8, 3.0), m.grid)
    ds = steady_mill(S, b, m._feeds[0], rtd.PlugFlow(tau), positions=[0.5], locations=["z:0.5"])
    np.testing.assert_allclose(M[g["z:0.5"]], ds["sample"].values[0], rtol=0, atol=1e-12)  # same solver
    assert M[g["z:0.5"]][0] > M[g["product"]][0]  # coarser halfway along


def test_mill_mode_names_are_validated():
    # one table of transport names (rtd.names): aliases are accepted and made canonical
    assert ModelSpec(mode="mill", transport="cstr").transport == "perfect_mixing"
    assert ModelSpec(mode="mill", transport="tis", transport_params={"n": 3}).transport == "tanks_in_series"
    with pytest.raises(InputError, match="'perfect_mixing', 'plug_flow', 'tanks_in_series', 'recirculating_cells', "
                                         "'axial_dispersion'"):
        ModelSpec(mode="mill", transport="tanks")
    with pytest.raises(InputError, match="unknown \\['pe'\\]; missing \\['n'\\]"):
        ModelSpec(mode="mill", transport="recirculating_cells", transport_params={"pe": 3})
    with pytest.raises(InputError, match="n = 0"):
        ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 0})
    with pytest.raises(InputError, match="need mode = 'mill'"):
        ModelSpec(mode="well_mixed", transport="plug_flow")


def test_mill_mode_axial_dispersion_fit_separates_breakage_and_classification():
    """Axial dispersion (Pe 5) with classification along the axis, three residence times,
    product and hold-up samples: rate, breakage and classification recovered."""
    spec = ModelSpec(mode="mill", transport="axial_dispersion", transport_params={"pe": 5.0}, breakage="single",
                     classification="screen_power", tau_column="tau_s")
    truth = {"ln_A0": -4.5, "alpha": 1.0, "gamma": 0.9, "n_screen": 1.0}
    conds, locs = ["c1", "c2", "c3"], ["product", "holdup"]
    m0 = ForwardModel(spec, _data(conds, locs, PROC), GRID)
    theta = np.array([truth[n] for n in m0.param_names])
    model = ForwardModel(spec, _data(conds, locs, PROC, _synthetic(m0, theta, noise=0.01, seed=1)), GRID)
    params = default_parameters(spec, {n: {"value": truth[n] + 0.3} for n in model.param_names})
    res = fit(model, params, global_search=False, starts=1, grid_check=False)
    for n in model.param_names:
        se = res.stats["params"][n]["se"]
        assert abs(res.params[n].value - truth[n]) < 4 * se, (n, res.params[n].value, se)
        assert se < 0.05
    assert res.ssr < 1.5 * model.n_data * 0.01 ** 2


def _write_config(tmp_path, b_name="B.csv", b_kind="B"):
    (tmp_path / "fit.toml").write_text(f"""
[data]
psd = "psd.csv"
process = "process.csv"
[grid]
ratio = {2 ** 0.5!r}
top_mm = 4.0
bottom_mm = {float(X[-1]) * 1e3!r}
[model]
mode = "mill"
transport = "tanks_in_series"
tau_column = "tau_s"
b_matrix_csv = "{b_name}"
b_kind = "{b_kind}"
[model.transport_params]
n = 2
[optimizer]
global = false
starts = 1
""")
    return tmp_path / "fit.toml"


def test_b_matrix_csv_config_round_trip(tmp_path):
    truth = {"ln_A0": -4.0, "alpha": 1.2, "phi": 0.4, "gamma": 0.8, "beta": 3.0}
    B = normalized_B(X, truth["phi"], truth["gamma"], truth["beta"])
    # the data come from the discrete model the config describes: this b matrix as given
    gen = ForwardModel(ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 2},
                                 tau_column="tau_s", breakage="fixed", b_matrix=b_from_B(B)),
                       _data(["c1", "c2"], ["product"], PROC), GRID)
    vals = _synthetic(gen, np.array([truth[n] for n in gen.param_names if n in ("ln_A0", "alpha")]))
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_m": X[:2], "passing": [1.0, 0.0]})]
    rows += [pd.DataFrame({"condition": c, "location": loc, "size_m": X, "passing": v}) for (c, loc), v in vals.items()]
    pd.concat(rows).to_csv(tmp_path / "psd.csv", index=False)
    PROC.to_csv(tmp_path / "process.csv", index=False)
    np.savetxt(tmp_path / "B.csv", B, delimiter=",")
    np.savetxt(tmp_path / "b.csv", b_from_B(B), delimiter=",")

    cfg = load_config(_write_config(tmp_path))
    assert cfg.spec.breakage == "fixed" and cfg.spec.param_names == ("ln_A0", "alpha")
    np.testing.assert_allclose(cfg.spec.b_matrix, b_from_B(B), atol=1e-15)
    np.testing.assert_allclose(cfg.grid.x, X, rtol=1e-12)
    model = ForwardModel(cfg.spec, cfg.data, cfg.grid)
    params = default_parameters(cfg.spec, {"ln_A0": {"value": -3.0}, "alpha": {"value": 0.5}})
    res = fit(model, params, global_search=False, starts=1, grid_check=False)
    assert res.params["ln_A0"].value == pytest.approx(truth["ln_A0"], abs=1e-6)
    assert res.params["alpha"].value == pytest.approx(truth["alpha"], abs=1e-6)
    assert res.ssr < 1e-16

    cfg_b = load_config(_write_config(tmp_path, "b.csv", "b"))
    np.testing.assert_allclose(cfg_b.spec.b_matrix, cfg.spec.b_matrix, atol=1e-15)

    np.savetxt(tmp_path / "small.csv", B[:-1, :-1], delimiter=",")
    with pytest.raises(InputError, match="small.csv: shape 15 x 15 does not match .* 16 classes"):
        load_config(_write_config(tmp_path, "small.csv"))
    np.savetxt(tmp_path / "notb.csv", B, delimiter=",")
    with pytest.raises(InputError, match="notb.csv.*sums to"):
        load_config(_write_config(tmp_path, "notb.csv", "b"))  # a cumulative B given as b


@pytest.mark.parametrize("where", [None, "cells"])
def test_mill_mode_chain_is_vectorised_and_equals_the_mill(where):
    """Issue 15 §3: mode "mill" with a chain of cells (tanks in series) is evaluated for
    the whole population at once (eq. 3 per cell); it equals one Mill/steady_mill per
    member and condition (the general path) to rounding: both are forward substitutions
    of the same triangular systems (1e-12 on mass fractions <= 1)."""
    d = _data(["c1", "c2"], ["cell:1", "cell:2", "holdup", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 3},
                               classification="screen", where=where, tau_column="tau_s"), d, GRID)
    assert m.mill_door().chain_cells == 3
    rng = np.random.default_rng(3)
    theta = np.column_stack([rng.uniform(-6, -3, 4), rng.uniform(0.5, 1.5, 4), rng.uniform(0.2, 0.8, 4),
                             rng.uniform(0.5, 1.2, 4), rng.uniform(2.5, 5, 4), rng.uniform(-1, 0.5, 4),
                             rng.uniform(0.5, 2.5, 4)])
    fast = m.predict_grid(theta)
    p = m._unpack(theta)
    slow = np.empty_like(fast)
    tau, extra = m.transport_values(p)
    m.mill_door(extra).samples_by_member(m.rates(p), m.frac_b(p, 4), m._feeds, m.discharge(p, 4), tau, m.groups, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)


@pytest.mark.parametrize("where", [None, "cells"])
def test_mill_mode_recirculating_cells_vectorised_equals_the_mill(where):
    """Recirculating cells (not a chain) with fitted tau and r: the population path
    (a batched n x n solve per class) equals one steady_mill per member and condition
    to rounding (the same block equations; 1e-12 on mass fractions <= 1)."""
    d = _data(["c1", "c2"], ["cell:1", "cell:3", "holdup", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="recirculating_cells", transport_params={"n": 4},
                               transport_fit=("tau", "r"), classification="screen", where=where,
                               tau_column="tau_s"), d, GRID)
    rng = np.random.default_rng(5)
    theta = np.column_stack([rng.uniform(-6, -3, 4), rng.uniform(0.5, 1.5, 4), rng.uniform(0.2, 0.8, 4),
                             rng.uniform(0.5, 1.2, 4), rng.uniform(2.5, 5, 4), rng.uniform(-1, 0.5, 4),
                             rng.uniform(0.5, 2.5, 4), rng.uniform(4.0, 6.0, 4), rng.uniform(0.0, 3.0, 4)])
    fast = m.predict_grid(theta)
    p = m._unpack(theta)
    slow = np.empty_like(fast)
    tau, extra = m.transport_values(p)
    m.mill_door(extra).samples_by_member(m.rates(p), m.frac_b(p, 4), m._feeds, m.discharge(p, 4), tau, m.groups, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)
    theta[1, -1] = -1.0  # r < 0: outside rtd's domain, that member only
    got = m.predict_grid(theta)
    assert np.isnan(got[1]).all() and np.isfinite(got[[0, 2, 3]]).all()


def test_mill_mode_fits_peclet_number_and_reads_axial_samples():
    """transport_fit = ("tau", "pe") for axial dispersion: parameters ln_tau and ln_pe,
    no fixed pe needed; the prediction at z:Y is steady_mill's profile with that
    AxialDispersion (the same solver, so equal to rounding of the interpolation)."""
    import rtd
    from millflow.breakage import NormalizedBreakage, PowerLawRate
    from millflow.mill import steady_mill
    d = _data(["c1"], ["z:0.5", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="axial_dispersion", transport_fit=("tau", "pe")), d, GRID)
    assert m.param_names[-2:] == ("ln_tau", "ln_pe")
    theta = np.array([-5.0, 1.0, 0.4, 0.8, 3.0, np.log(300.0), np.log(6.0)])
    M = m.predict_grid(theta)[0]
    g = {loc: k for k, (_, loc, _) in enumerate(m.groups)}
    S, b, _ = breakage_on_grid(PowerLawRate(np.exp(-5.0), 1.0), NormalizedBreakage(0.4, 0.8, 3.0), m.grid)
    ds = steady_mill(S, b, m._feeds[0], rtd.AxialDispersion(300.0, 6.0), positions=[0.5], locations=["z:0.5"])
    np.testing.assert_allclose(M[g["z:0.5"]], ds["sample"].values[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(M[g["product"]], ds["product"].values, rtol=0, atol=1e-12)  # the same solve


@pytest.mark.parametrize("cls", [None, "screen"])
def test_mill_mode_plug_flow_vectorised_equals_the_mill(cls):
    """Plug flow with product and z:Y samples is evaluated for the population at once
    (batch solve in the contact time); it equals one steady_mill per member to rounding
    (the same eigenbasis; 1e-12 on mass fractions <= 1)."""
    d = _data(["c1", "c2"], ["z:0.25", "z:0.5", "product"], PROC)
    m = ForwardModel(ModelSpec(mode="mill", transport="plug_flow", classification=cls, tau_column="tau_s"), d, GRID)
    rng = np.random.default_rng(7)
    cols = [rng.uniform(-6, -3, 4), rng.uniform(0.0, 1.5, 4), rng.uniform(0.2, 0.8, 4), rng.uniform(0.5, 1.2, 4),
            rng.uniform(2.5, 5, 4)] + ([rng.uniform(-1, 0.5, 4), rng.uniform(0.5, 2.5, 4)] if cls else [])
    theta = np.column_stack(cols)
    fast = m.predict_grid(theta)
    p = m._unpack(theta)
    slow = np.empty_like(fast)
    tau, extra = m.transport_values(p)
    d_star = m.discharge(p, 4) if cls else None
    m.mill_door(extra).samples_by_member(m.rates(p), m.frac_b(p, 4), m._feeds, d_star, tau, m.groups, slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-12)


def test_screen_hard_cut_keeps_the_product_below_the_opening():
    """Issue 15 §2 (physics tried on the knife mill): classification "screen_power_cut" is
    "screen_power" with classes whose lower edge is at or above the opening held back
    (d* = 1e-12): the product carries at most ~1e-10 of its mass above the opening, while
    below it the two forms agree (the cut changes only what the held classes break into)."""
    d = _data(["c1", "c2"], ["product"], PROC)
    spec = dict(mode="well_mixed", breakage="single", classification="screen_power", tau_column="tau_s")
    plain = ForwardModel(ModelSpec(**spec), d, GRID)
    cut = ForwardModel(ModelSpec(**{**spec, "classification": "screen_power_cut"}), d, GRID)
    assert plain.param_names == cut.param_names
    theta = np.array([[-4.0, 1.0, 0.8, 1.0]])
    p_plain, p_cut = plain.predict_grid(theta)[0], cut.predict_grid(theta)[0]
    lower = np.r_[X[1:], 0.0]
    for g, opening_mm in enumerate((1.0, 2.0)):
        above = lower >= opening_mm * 1e-3
        assert above.any() and p_plain[g][above].sum() > 1e-3  # the smooth screen lets some through
        assert p_cut[g][above].sum() < 1e-10
        np.testing.assert_allclose(p_cut[g].sum(), 1.0, rtol=1e-12)  # mass conserved
