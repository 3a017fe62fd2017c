"""The ``[grid]`` table of a flowsheet: a :class:`~millflow.grid.SizeGrid` and its scheme."""
from __future__ import annotations

from millflow.errors import InputError
from millflow.flowsheet.readers.tables import _Table, _wrap
from millflow.grid import SCHEMES, SizeGrid


def _grid(t: _Table) -> SizeGrid:
    scheme = t.plain("scheme", "class_average", kind=str)
    if scheme not in SCHEMES:
        raise InputError(f"grid.scheme = {scheme!r}: expected one of {', '.join(SCHEMES)}")
    return _grid_edges(t).with_scheme(scheme)


def _grid_edges(t: _Table) -> SizeGrid:
    if "edges_um" in t.data or "edges_mm" in t.data or "edges_m" in t.data:
        edges = t.quantity("edges", "length", array=True)
        t.finish("edges_um, scheme")
        return _wrap("grid.edges", SizeGrid.from_edges, edges)
    top = t.quantity("top", "length")
    bottom = t.quantity("bottom", "length")
    n = t.plain("n", None, kind=float)
    ratio = t.plain("ratio", None, kind=float)
    t.finish("top_um, bottom_um, and n or ratio (or edges_um), scheme")
    if (n is None) == (ratio is None):
        raise InputError("grid: give exactly one of n (number of classes) or ratio (e.g. 1.189207 = 2^(1/4))")
    if n is not None:
        if n != int(n) or n < 2:
            raise InputError(f"grid.n = {n!r}: expected an integer >= 2")
        if bottom >= top:
            raise InputError(f"grid.bottom = {bottom!r} m must be below grid.top = {top!r} m")
        return _wrap("grid", SizeGrid.geometric, top, (top / bottom) ** (1.0 / (int(n) - 1)), int(n))
    return _wrap("grid", SizeGrid.between, top, bottom, ratio)
