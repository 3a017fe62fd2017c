"""The parts of a steady mill's Dataset shared by the linear and the non-linear mill: the
``size`` coordinates, mass fractions, samples at named locations, and the note on the grid
part of the error (:func:`millflow.mill.steady_mill`)."""
from __future__ import annotations

import numpy as np
import xarray as xr

from millflow.errors import InputError

__all__ = []


def _size_coords(n: int, x) -> dict:
    """Coordinates of the ``size`` dimension.

    Coordinates of the ``size`` dimension. ``size`` means one thing in every millflow
    Dataset: the upper class sizes [m] (:meth:`millflow.grid.SizeGrid.size_coord`);
    ``size_class`` is the class number (1 = coarsest). Without ``x`` the dimension has
    class numbers only. ``x`` holds the sizes under their old name.
    """
    coords = {"size_class": ("size", np.arange(1, n + 1), {"long_name": "size class (1 = coarsest)"})}
    if x is not None:
        xs = np.asarray(x, dtype=float) if not hasattr(x, "upper_m") else x.upper_m
        if xs.shape != (n,):
            raise InputError(f"x has shape {xs.shape}; expected ({n},) upper class sizes [m]")
        attrs = {"units": "m", "long_name": "upper size of class (Austin convention)"}
        coords["size"] = ("size", xs, attrs)
        coords["x"] = ("size", xs, dict(attrs))
    return coords


def _fractions(a: np.ndarray, axis: int = -1) -> np.ndarray:
    if a.ndim == 1:  # the common case, without the broadcasting machinery (a Dataset per call)
        total = a.sum()
        return a / total if total > 0 else np.zeros(a.shape)
    total = a.sum(axis=axis, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, a / np.where(total > 0, total, 1.0), 0.0)


def _samples(ds: xr.Dataset, locations) -> xr.DataArray:
    """Mass fractions at named sampling locations.

    Mass fractions at named sampling locations: 'discharge', 'feed', 'holdup',
    'cell:K' (1-based), 'z:0.5' (needs ``positions`` containing 0.5).
    """
    if isinstance(locations, dict):
        names, specs = list(locations), list(locations.values())
    else:
        names = specs = [str(s) for s in locations]
    rows = []
    for name, spec in zip(names, specs):
        if spec == "discharge":
            rows.append(ds["product_fraction"].values)
        elif spec == "feed":
            rows.append(_fractions(ds["feed"].values))
        elif spec == "holdup":
            rows.append(ds["holdup_fraction"].values)
        elif spec.startswith("cell:") and "cell_holdup" in ds:
            k = int(spec[5:])
            if not 1 <= k <= ds.sizes["cell"]:
                raise InputError(f"location {name!r}: cell {k} does not exist; expected 1..{ds.sizes['cell']}")
            rows.append(_fractions(ds["cell_holdup"].values[k - 1]))
        elif spec.startswith("z:") and "profile" in ds:
            z = float(spec[2:])
            hit = np.flatnonzero(np.isclose(ds["position"].values, z, atol=1e-12))
            if not hit.size:
                raise InputError(f"location {name!r}: z = {z} is not among positions")
            rows.append(_fractions(ds["profile"].values[hit[0]]))
        else:
            raise InputError(f"location {name!r} = {spec!r}; expected 'discharge', 'feed', 'holdup', "
                             "'cell:K' (cell transports) or 'z:Y' (axial transports with positions)")
    return xr.DataArray(np.array(rows), dims=("location", "size"), coords={"location": names},
                        attrs={"units": "1", "long_name": "mass fraction at the sampling location"})


#: Why a mill solved from S_i and b_ij has no size-grid error of its own.
_GRID_NOTE = ("none: S_i and b_ij given per class are the discrete model itself; continuous forms put on a "
              "grid carry the grid error their caller estimates (flowsheet grid check, batch.grind)")
