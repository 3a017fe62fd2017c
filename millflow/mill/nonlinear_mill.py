"""The generic mill entry points with non-linear kinetics: :func:`millflow.mill.steady_mill`,
:class:`millflow.mill.Mill` and :func:`millflow.mill.transient_mill` take a
:class:`millflow.nonlinear.Kinetics` in place of the rates S (with b = None: the kinetics
carry their own b) and dispatch here, to the solvers of :mod:`millflow.mill.nonlinear`
(steady) and :mod:`millflow.mill.nonlinear_transient` (dynamics).

The Dataset is the linear mill's (``product``, ``holdup``, ``cell_holdup``, ``profile``,
``sample``, the same attributes) plus ``overflow_mass`` and ``holdup_overflow`` (the
aggregation overflow above the top class, leaving with the product), ``kinetics`` and the
Newton ``residual``. The feed is used as given (non-linear rates depend on the amount
of material: give flows per unit nominal feed rate); ``tol`` and ``error_estimate`` are
relative to its total, as for the linear mill.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from millflow.errors import InputError

__all__ = ["is_kinetics", "steady_dataset", "check_no_b"]


def is_kinetics(obj) -> bool:
    """True for a :class:`millflow.nonlinear.Kinetics` (without importing the module when
    nothing has built one: then nothing can be one)."""
    mod = sys.modules.get("millflow.nonlinear.kinetics")
    return mod is not None and isinstance(obj, mod.Kinetics)


def check_no_b(kin, b, where: str):
    """The Kinetics carries b: a second one is refused, not silently ignored."""
    if b is not None and not (np.shape(b) == kin.b.shape and np.array_equal(np.asarray(b, float), kin.b)):
        raise InputError(f"{where}: S is a Kinetics object, which carries its own b; expected b=None")


def steady_dataset(kin, b, feed, transport, d=None, *, where=None, dispersion=None, discharge=None, method=None,
                   x=None, positions=None, locations=None, tol: float = 1e-8, on_inaccuracy: str = "raise"):
    """:func:`millflow.mill.steady_mill` for non-linear kinetics (module docstring)."""
    import xarray as xr

    from millflow.mill import nonlinear as nl
    from millflow.mill.accuracy import check_accuracy
    from millflow.mill.scene import _check_feed
    from millflow.mill.dataset import _GRID_NOTE, _fractions, _samples, _size_coords

    start = time.perf_counter()
    check_no_b(kin, b, "steady_mill")
    if method is not None:
        raise InputError(f"method = {method!r}: a mill with non-linear kinetics has one solver per transport "
                         "(millflow.mill.nonlinear); expected method=None")
    feed = _check_feed(feed, kin.n)
    if feed.ndim != 1:
        raise InputError(f"feed has shape {feed.shape}; expected ({kin.n},) (non-linear kinetics: one feed at a time)")
    if positions is not None:
        pos = np.atleast_1d(np.asarray(positions, dtype=float))
        if pos.ndim != 1 or np.any(~np.isfinite(pos)) or np.any((pos < 0) | (pos > 1)):
            raise InputError(f"positions = {positions!r}; expected fractions of the mill length in [0, 1]")
    r = nl.solve_transport(kin, feed, transport, d, where=where, dispersion=dispersion, discharge=discharge, tol=tol,
                           holdup=True, positions=positions)
    total = float(np.abs(feed).sum())
    scale = total if 0 < total < np.inf else 1.0
    check_accuracy("steady_mill", r.method, r.mass_balance_error / scale, r.error_estimate / scale, tol, on_inaccuracy)
    if positions is not None and "profile" not in r.info:
        raise InputError(f"positions are given but transport {transport!r} has no axis; expected rtd.PlugFlow or "
                         "rtd.AxialDispersion (use locations 'cell:K' for cells)")
    product, holdup = r.product, np.asarray(r.info["holdup"], float)
    data = {
        "feed": ("size", feed, {"units": "feed units", "long_name": "feed flow"}),
        "product": ("size", product, {"units": "feed units", "long_name": "product (discharge) flow"}),
        "product_fraction": ("size", _fractions(product), {"units": "1", "long_name": "product mass fraction"}),
        "holdup": ("size", holdup, {"units": "s", "long_name": "hold-up per unit feed rate"}),
        "holdup_fraction": ("size", _fractions(holdup), {"units": "1", "long_name": "hold-up mass fraction"}),
    }
    coords = _size_coords(kin.n, x)
    cells = r.info.get("cell_holdup", r.info.get("cells"))
    if cells is not None:
        data["cell_holdup"] = (("cell", "size"), np.asarray(cells, float),
                               {"units": "s", "long_name": "hold-up of each cell per unit feed rate"})
        coords["cell"] = ("cell", np.arange(1, len(cells) + 1), {"long_name": "cell (1 = feed end)"})
    if positions is not None:
        coords["position"] = ("position", pos, {"units": "1", "long_name": "y / L"})
        prof = np.asarray(r.info["profile"], float)
        data["profile"] = (("position", "size"), prof,
                           {"units": "s", "long_name": "hold-up density per unit feed rate and fractional length"})
        data["profile_fraction"] = (("position", "size"), _fractions(prof),
                                    {"units": "1", "long_name": "local hold-up mass fraction"})
    ds = xr.Dataset(data, coords=coords)
    from millflow.mill.scene import _scene

    sc = _scene(kin.S, kin.b, transport, d, where, dispersion, discharge=discharge)
    ds.attrs.update(
        method=f"non-linear kinetics: {r.method}",
        kinetics=kin.describe(),
        error_estimate=float(r.error_estimate),
        solver_error_estimate=float(r.error_estimate),
        grid_error_estimate=0.0,
        grid_error_method=_GRID_NOTE,
        runtime_s=float(time.perf_counter() - start),
        mass_balance_error=float(r.mass_balance_error),
        overflow_mass=float(r.overflow_mass),
        holdup_overflow=float(r.info.get("holdup_overflow", 0.0)),
        residual=float(r.residual),
        holdup_error_estimate=float(r.info.get("holdup_error_estimate", r.error_estimate * float(transport.mean))),
        iterations=int(r.iterations),
        transport=repr(transport),
        classification="none" if sc.d is None else f"d* at {sc.where}",
        tau_s=float(transport.mean),
    )
    for key in ("control_volumes", "order", "parts"):
        if key in r.info:
            ds.attrs[key] = r.info[key]
    if locations is not None:
        ds["sample"] = _samples(ds, locations)
    return ds
