"""Synthetic problems with known parameters: batch data from a stated truth, a closed circuit.

The synthetic truths the fit is tested and benchmarked against (the ``fit`` and
``scaleup`` benchmark suites and the tests of :mod:`millflow.fitting` and
:mod:`millflow.scaleup` use the same problems). Data are made by the library's own
forward model (eq. 4 batch grinding with eq. 5 rates and eq. 6 breakage) on a stated
grid, with seeded Gaussian noise on cumulative passing. The closed-circuit ball mill
(:func:`closed_circuit_case`, :func:`shipped_circuit_case`) is the circuit the flowsheet
solver is tested on and the ``flowsheet`` and ``sweep`` suites time. Nothing is read
from files.

>>> model, params, truth = make_batch_problem(n_times=2, n_sieves=6, n_grid=11, noise=0.0)
>>> model.n_data, sorted(truth) == sorted(params)
(12, True)
"""
from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd

__all__ = ["TRUTH", "BOUNDS", "make_batch_problem", "synthetic_lab_fit", "CLOSED_CIRCUIT_TOML",
           "closed_circuit_case", "shipped_circuit_case"]

#: Parameters of the synthetic batch problems (ln_A0 is ln of A [1/s] at x0 = 1 mm).
TRUTH = {"ln_A0": np.log(1.0 / 60.0), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}
#: Bounds that separate the two branches of eq. 6 (gamma < beta), so the truth is unique.
BOUNDS = {"ln_mu": (-3.0, 6.0), "Lambda": (1.0, 6.0), "ln_A0": (-9.0, 0.0), "alpha": (0.2, 2.5), "phi": (0.0, 1.0),
          "gamma": (0.1, 2.0), "beta": (2.2, 8.0)}


def make_batch_problem(n_times: int = 8, n_sieves: int = 30, n_grid: int = 60, noise: float = 0.01,
                       seed: int = 0, truth: dict | None = None, rate: str = "power", bounds: dict | None = None):
    """Synthetic batch data from known parameters; returns (model, params, truth).

    Sieves: root-2 series down from 4 mm; the numerical grid has the same top and a
    finer ratio chosen so that it has ``n_grid`` classes over the same range (the
    sieve sizes are then generally not grid edges: the model is interpolated, as with
    real data). Feed: all mass in the top sieve interval. Times: geometric 0.5 to
    ``0.5 * 2^(n_times-1)`` min. Noise: N(0, noise^2) added to cumulative passing.
    """
    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.models import ForwardModel, ModelSpec, Parameter
    from millflow.grid import SizeGrid

    truth = dict(TRUTH if truth is None else truth)
    sieves = 4e-3 * 2 ** (-0.5 * np.arange(n_sieves))
    times = 30.0 * 2.0 ** np.arange(n_times)
    ratio = (sieves[0] / sieves[-1]) ** (1.0 / (n_grid - 1))
    grid = SizeGrid.geometric(sieves[0], ratio, n_grid)
    feed = pd.DataFrame({"condition": "c1", "location": "feed", "time_s": 0.0, "size_m": sieves[:2],
                         "passing": [1.0, 0.0]})
    rows = []
    for t in times:
        rows.append(pd.DataFrame({"condition": "c1", "location": "mill", "time_s": t, "size_m": sieves,
                                  "passing": np.linspace(1, 0, n_sieves)}))
    placeholder = psd_data_from_frames(pd.concat([feed] + rows, ignore_index=True))
    spec = ModelSpec(mode="batch", rate=rate, breakage="normalized", x0_m=1e-3)
    model = ForwardModel(spec, placeholder, grid)
    theta = np.array([truth[n] for n in model.param_names])
    clean = model.predict(theta)
    rng = np.random.default_rng(seed)
    noisy = clean + noise * rng.standard_normal(clean.size)
    rows = [feed] + [r.assign(passing=noisy[k * n_sieves:(k + 1) * n_sieves]) for k, r in enumerate(rows)]
    data = psd_data_from_frames(pd.concat(rows, ignore_index=True), strict=False)
    model = ForwardModel(spec, data, grid)
    bounds = {**BOUNDS, **(bounds or {})}
    params = {n: Parameter(n, truth[n], *bounds[n]) for n in model.param_names}
    return model, params, truth



def synthetic_lab_fit(theta: dict, grid, noise: float, rng, label: str = "synthetic lab fit", as_dict: bool = False):
    """A local eq. 9 fit to synthetic batch tests made from known parameters.

    A local eq. 9 fit to synthetic batch tests (1, 3, 9 min, 12 root-2 sieves from
    4 mm, feed in the top three sieve intervals) made from ``theta`` (eq. 5 rates, eq. 6
    breakage) on ``grid`` with Gaussian noise of sd ``noise`` on cumulative passing.
    Returns (the fit as :func:`millflow.scaleup.fit_from_dict` reads it, the model); with
    ``as_dict`` the fit's JSON dict (as ``millflow fit --json`` prints it) instead of the first.
    """
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.estimate import fit
    from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
    from millflow.scaleup import fit_from_dict

    sieves = 4.0 * 2 ** (-0.5 * np.arange(12))
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "time_min": 0.0, "size_mm": sieves[:4],
                          "passing": [1.0, 2 / 3, 1 / 3, 0.0]})]
    for t in (1.0, 3.0, 9.0):
        rows.append(pd.DataFrame({"condition": "lab", "location": "mill", "time_min": t, "size_mm": sieves,
                                  "passing": np.linspace(1, 0, 12)}))
    spec = ModelSpec(mode="batch", breakage="normalized")
    model = ForwardModel(spec, psd_data_from_frames(pd.concat(rows), strict=False), grid)
    y = model.predict(np.array([theta[n] for n in model.param_names])) + rng.normal(0.0, noise, model.n_data)
    k = 0
    for r in rows[1:]:
        r["passing"] = y[k:k + 12]
        k += 12
    model = ForwardModel(spec, psd_data_from_frames(pd.concat(rows), strict=False), grid)
    params = default_parameters(spec, {n: {"value": float(v)} for n, v in theta.items()})
    res = fit(model, params, global_search=False, starts=1, grid_check=False, quiet=True)
    return (res.to_dict() if as_dict else fit_from_dict(res.to_dict(), label)), model


#: The closed-circuit ball mill of flowsheets/closed_circuit_ball_mill.toml in its per-time form
#: (rates per time, tau_min = 3.5: a linear circuit), written out so that nothing is read from
#: files; grid and cells are set by :func:`closed_circuit_case`.
CLOSED_CIRCUIT_TOML = """
title = "Closed-circuit ball mill with hydrocyclones (benchmark)"
[grid]
top_um = 8000
bottom_um = 2
n = 100
[materials.ore]
rate = {form = "power", A_per_min = 0.9, alpha = 1.0, x0_um = 1000}
breakage = {form = "normalized", phi = 0.55, gamma = 0.8, beta = 3.5}
[units.fresh_feed]
type = "feed"
solids_tph = 250
[units.fresh_feed.psd]
form = "sieves"
size_um = [6700, 4750, 3350, 2360, 1700, 1180, 850, 600, 425, 300, 212, 150, 106, 75, 53]
passing_pct = [100, 93, 80, 66, 54, 44, 36, 29, 24, 19.5, 16, 13, 10.5, 8.5, 7]
[units.chute]
type = "mixer"
[units.ball_mill]
type = "mill"
material = "ore"
tau_min = 3.5
transport = {model = "tanks_in_series", n = 10}
power_kW = 3800
[units.cyclones]
type = "hydrocyclone"
curve = "whiten"
d50c_um = 140
alpha = 3.0
beta = 0.0
bypass = 0.30
[units.overflow_product]
type = "product"
[streams]
fresh = {from = "fresh_feed", to = "chute"}
mill_feed = {from = "chute", to = "ball_mill"}
mill_discharge = {from = "ball_mill", to = "cyclones"}
underflow = {from = "cyclones.underflow", to = "chute"}
overflow = {from = "cyclones.overflow", to = "overflow_product"}
"""


def closed_circuit_case(n: int = 100, cells: int = 10):
    """The closed-circuit ball mill of :data:`CLOSED_CIRCUIT_TOML` as a flowsheet.

    Parameters
    ----------
    n : int
        Classes of the geometric grid from 8 mm down to 2 um.
    cells : int
        Tanks in series of the mill's transport.

    Returns
    -------
    millflow.flowsheet.Flowsheet
        A linear circuit (rates per time, tau = 3.5 min): one sparse solve.

    Examples
    --------
    >>> fs = closed_circuit_case(20, cells=3)
    >>> fs.grid.n, sorted(fs.units)
    (20, ['ball_mill', 'chute', 'cyclones', 'fresh_feed', 'overflow_product'])
    """
    from millflow.flowsheet import from_dict

    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": n}
    data["units"]["ball_mill"]["transport"] = {"model": "tanks_in_series", "n": cells}
    return from_dict(data, source=f"closed_circuit_ball_mill (N = {n}, {cells} cells)")


def shipped_circuit_case(n: int = 100, cells: int = 10):
    """The shipped example's circuit as the file drives it, on ``n`` classes.

    Rates per energy (S = S^E P / H, Herbst and Fuerstenau), the mill given by its hold-up
    (tau = H / F): non-linear in the mill's throughput, so the solve tears the circuit on it.

    Parameters
    ----------
    n : int
        Classes of the geometric grid from 8 mm down to 2 um.
    cells : int
        Tanks in series of the mill's transport.

    Returns
    -------
    millflow.flowsheet.Flowsheet
    """
    from millflow.flowsheet import from_dict

    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": n}
    data["materials"]["ore"]["rate"] = {"form": "power", "A_E_t_per_kWh": 0.675, "alpha": 1.0, "x0_um": 1000}
    mill = data["units"]["ball_mill"]
    del mill["tau_min"]
    mill["holdup_t"] = 47.5
    mill["transport"] = {"model": "tanks_in_series", "n": cells}
    return from_dict(data, source=f"closed_circuit_ball_mill, energy and hold-up (N = {n}, {cells} cells)")
