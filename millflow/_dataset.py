"""xarray Datasets built straight from numpy arrays, without xarray's general constructor.

``xr.Dataset(data_vars, coords)`` accepts anything (tuples, lists, DataArrays, pandas
objects, dask arrays) and pays for it on every call: each value goes through
``as_compatible_data`` (whose duck-array checks import dask.array, about a second, the
first time when dask is installed), then merge, alignment and index creation. A steady
mill at N = 50 spent about 0.1 ms there, more than its solve; a flowsheet's results.nc
paid the dask import. Results made here are numpy arrays of known dimensions, so
:func:`dataset` builds the same Dataset directly: a ``Variable`` per array (its fastpath:
no conversion), a pandas index per dimension coordinate (built from a ``pd.Index``,
without xarray's array probe), and the Dataset from those pieces by xarray's own
internal constructor ``Dataset._construct_direct`` (the one xarray's methods use to skip
validation). Where that constructor is missing (another xarray), the public constructor
builds the same Dataset from the same Variables: tests/millflow/test_dataset.py checks
that both give identical Datasets with consistent indexes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["dataset"]


def dataset(data_vars: dict, coords: dict | None = None, attrs: dict | None = None):
    """An ``xr.Dataset`` from numpy arrays, as ``xr.Dataset(data_vars, coords, attrs)``.

    Parameters
    ----------
    data_vars, coords : dict name -> (dims, values, attrs): ``dims`` a name or a tuple
        of names, ``values`` an array (numbers or strings) whose shape matches; a
        coordinate whose only dimension is its own name is a dimension coordinate and
        gets a pandas index, as in xarray.
    attrs : the Dataset's attributes.

    Sizes are checked (a dimension of two lengths raises ValueError, as in xarray); the
    values are not converted: object arrays and anything not a numpy array of numbers or
    strings go through the public constructor.
    """
    import xarray as xr

    coords = coords or {}
    variables, plain = {}, False
    for name, (dims, values, var_attrs) in {**coords, **data_vars}.items():
        dims = (dims,) if isinstance(dims, str) else tuple(dims)
        values = np.asarray(values)
        if values.dtype.kind not in "biufcU" or values.ndim != len(dims):
            plain = True  # objects, dates, a shape xarray must explain: the general path
        variables[name] = (dims, values, var_attrs)
    construct = _direct_constructor(xr)
    if plain or construct is None:
        return _public(xr, variables, coords, attrs)
    sizes: dict = {}
    built, indexes = {}, {}
    for name, (dims, values, var_attrs) in variables.items():
        for dim, n in zip(dims, values.shape):
            if sizes.setdefault(dim, n) != n:
                raise ValueError(f"{name}: dimension {dim!r} has length {n} here and {sizes[dim]} elsewhere")
        var = xr.Variable(dims, values, dict(var_attrs or {}), fastpath=True)
        if dims == (name,) and name in coords:
            index = _pandas_index(name, values)
            var = index.create_variables({name: var})[name]
            indexes[name] = index
        built[name] = var
    try:
        return construct(built, set(coords), dims=sizes, attrs=dict(attrs or {}), indexes=indexes)
    except TypeError:  # another signature: the public constructor
        return _public(xr, variables, coords, attrs)


def _direct_constructor(xr):
    """xarray's internal ``Dataset._construct_direct``, or None where it is missing."""
    return getattr(xr.Dataset, "_construct_direct", None)


#: Pandas indexes of recent dimension coordinates, by (name, dtype, values): a mill solved
#: again and again on one grid reuses its index (pandas indexes are immutable; xarray
#: shares them between Datasets the same way on every shallow copy).
_INDEXES: dict = {}
_INDEXES_KEPT = 64


def _pandas_index(name, values):
    key = (name, values.dtype.str, values.shape, values.tobytes()) if values.size <= 4096 else None
    index = _INDEXES.get(key) if key is not None else None
    if index is None:
        index = _new_pandas_index(name, values)
        if key is not None:
            if len(_INDEXES) >= _INDEXES_KEPT:
                _INDEXES.pop(next(iter(_INDEXES)))
            _INDEXES[key] = index
    return index


def _new_pandas_index(name, values):
    import pandas as pd
    from xarray.indexes import PandasIndex

    return PandasIndex(pd.Index(values, name=name), name, coord_dtype=values.dtype)


def _public(xr, variables, coords, attrs):
    """The same Dataset through ``xr.Dataset`` (the reference of :func:`dataset`)."""
    return xr.Dataset({k: v for k, v in variables.items() if k not in coords},
                      coords={k: v for k, v in variables.items() if k in coords}, attrs=dict(attrs or {}))
