"""millflow._dataset builds the Dataset xarray's public constructor builds, consistently."""
import numpy as np
import pytest
import xarray as xr

import rtd
from millflow import _dataset
from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid
from millflow.mill import steady_mill

try:  # xarray's own consistency check of a Dataset's variables, dims and indexes
    from xarray.testing import _assert_internal_invariants
except ImportError:  # pragma: no cover - another xarray
    _assert_internal_invariants = None


def _scene(n):
    g = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    S = power_law_rates(g.x, 0.05, 1.0, g.x[0])
    S[-1] = 0.0
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return g, S, b_from_B(normalized_B(g.x, 0.4, 0.8, 3.0)), feed


def _check(ds, ref):
    xr.testing.assert_identical(ds, ref)
    assert list(ds.data_vars) == list(ref.data_vars) and list(ds.coords) == list(ref.coords)
    assert set(ds.xindexes) == set(ref.xindexes)
    for name in ref.variables:
        assert ds[name].dtype == ref[name].dtype, name
    if _assert_internal_invariants is not None:
        _assert_internal_invariants(ds, True)


def test_matches_the_public_constructor():
    n = 7
    data = {"flow": (("stream", "size"), np.arange(3 * n, dtype=float).reshape(3, n), {"units": "kg/s"}),
            "label": ("stream", np.array(["a.out", "bb", "c"]), {}),
            "count": ("unit", np.array([1, 2]), {"long_name": "n"}),
            "scalar": ((), np.float64(2.5), {})}
    coords = {"stream": ("stream", np.array(["s1", "s2", "s3"]), {"long_name": "stream name"}),
              "size": ("size", np.geomspace(1e-2, 1e-4, n), {"units": "m"}),
              "size_class": ("size", np.arange(1, n + 1), {}),
              "unit": ("unit", np.array(["mill", "cyclone"]), {})}
    ds = _dataset.dataset(data, coords, {"title": "t", "x": 1.0})
    _check(ds, xr.Dataset(data, coords=coords, attrs={"title": "t", "x": 1.0}))
    assert ds.sel(stream="s2")["flow"].shape == (n,)  # the index works
    assert float(ds.sel(size=ds["size"][3])["flow"][0]) == 3.0


def test_index_is_reused_and_each_dataset_is_independent():
    coords = {"cell": ("cell", np.arange(1, 4), {"long_name": "cell"})}
    a = _dataset.dataset({"h": ("cell", np.ones(3), {})}, coords)
    b = _dataset.dataset({"h": ("cell", np.zeros(3), {})}, coords)
    assert a.xindexes["cell"] is b.xindexes["cell"]  # immutable, shared as xarray shares on copies
    a["h"].attrs["units"] = "s"
    a.attrs["k"] = 1
    assert "units" not in b["h"].attrs and "k" not in b.attrs
    np.testing.assert_array_equal(b["h"].values, 0.0)


def test_mismatched_lengths_raise():
    with pytest.raises(ValueError, match="dimension 'size'"):
        _dataset.dataset({"a": ("size", np.ones(3), {}), "b": ("size", np.ones(4), {})})


def test_without_the_direct_constructor_the_public_one_builds_the_same(monkeypatch):
    data = {"h": (("cell", "size"), np.ones((2, 3)), {"units": "s"})}
    coords = {"cell": ("cell", np.arange(1, 3), {}), "size_class": ("size", np.arange(1, 4), {})}
    fast = _dataset.dataset(data, coords, {"a": 1})
    monkeypatch.setattr(_dataset, "_direct_constructor", lambda xr: None)
    _check(fast, _dataset.dataset(data, coords, {"a": 1}))


def test_objects_take_the_public_path():
    ds = _dataset.dataset({"o": ("k", np.array([{"a": 1}, None], dtype=object), {})})
    assert ds["o"].dtype == object


@pytest.mark.parametrize("case", ["well_mixed", "cells_x", "plug_positions", "locations"])
def test_steady_mill_dataset_is_the_public_constructors(case, monkeypatch):
    g, S, b, feed = _scene(30)
    kw = {"well_mixed": dict(transport=rtd.PerfectMixing(600.0)),
          "cells_x": dict(transport=rtd.TanksInSeries(600.0, 3), x=g),
          "plug_positions": dict(transport=rtd.PlugFlow(600.0), x=g.x, positions=[0.0, 0.5, 1.0]),
          "locations": dict(transport=rtd.TanksInSeries(600.0, 2), x=g, locations=["discharge", "cell:1"])}[case]
    fast = steady_mill(S, b, feed, **kw)
    monkeypatch.setattr(_dataset, "_direct_constructor", lambda xr: None)  # as in an xarray without it
    plain = steady_mill(S, b, feed, **kw)
    for ds in (fast, plain):
        ds.attrs.pop("runtime_s")
    _check(fast, plain)
