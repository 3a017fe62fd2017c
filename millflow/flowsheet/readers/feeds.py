"""Feed units: the feed PSD (sieves, a CSV file, Rosin-Rammler, Gates-Gaudin-Schuhmann) and its water.

A sieve table is read in the unit its size column names (``size_um``, ``size_mm``,
``size_m``) and the passing column's unit (``_pct`` or ``_frac``); measured data are never
renormalised. A PSD size below the grid's finest size is refused (a unit slip).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from millflow.errors import GridError, InputError
from millflow.flowsheet.readers.tables import _named_file, _plausible, _Table, _user_key, _warn_pct_slip
from millflow.flowsheet.units import Feed
from millflow.grid import SizeGrid
from millflow.inputs import unit_column
from millflow.psd import from_distribution, from_sieves, gates_gaudin_schuhmann, rosin_rammler


def _sieve_table(path: Path, where: str):
    """Sizes [m] (descending) and cumulative passing [-] from a feed CSV: a size column with its
    unit (size_um, size_mm, size_m) and one of passing_pct/_frac (cumulative passing),
    cum_retained_pct/_frac (cumulative retained) or retained_pct/_frac (mass on each sieve,
    a pan row with size 0 holding the rest; the column must sum to 100 % / 1)."""
    from millflow.inputs import read_csv

    if not path.is_file():
        raise InputError(f"{where}.file: {path} not found (or not a file)")
    df = read_csv(path, "feed PSD file")
    cols = [c.strip() for c in df.columns]
    df.columns = cols
    size_col, size_factor = unit_column(cols, "size", "length", str(path))  # size_um, size_mm, ...
    kinds = [c for c in cols if c.rsplit("_", 1)[0] in ("passing", "cum_retained", "retained")
             and c.rsplit("_", 1)[-1] in ("pct", "frac")]
    if len(kinds) != 1:
        raise InputError(f"{path}: expected one of passing_pct, cum_retained_pct or retained_pct (or _frac); "
                         f"columns: {', '.join(cols)}")
    kind, unit = kinds[0].rsplit("_", 1)
    scale = 0.01 if unit == "pct" else 1.0
    if len(df) < 2:
        raise InputError(f"{path}: {len(df)} data row(s); expected at least two sieves")
    out = {}
    for col in (size_col, kinds[0]):
        vals = []
        for row, v in enumerate(df[col].tolist(), start=2):
            try:
                fv = float(v)
            except (TypeError, ValueError):
                fv = float("nan")
            if not math.isfinite(fv) or fv < 0:
                raise InputError(f"{path}: row {row}, column {col} = {v!r}; expected a finite number >= 0")
            vals.append(fv)
        out[col] = np.array(vals)
    size = out[size_col] * size_factor
    val = out[kinds[0]] * scale
    if kind == "retained":
        total = math.fsum(val)
        if abs(total - 1.0) > 1e-6:
            raise InputError(f"{path}: {kinds[0]} sums to {total / scale:.6g} {'%' if unit == 'pct' else ''}; "
                             f"expected {1 / scale:g} (the mass on every sieve and the pan; millflow does not "
                             "renormalise measured data)")
        order = np.argsort(-size)
        size, val = size[order], val[order]
        passing = 1.0 - np.cumsum(val)
        keep = size > 0  # the pan row (size 0) is the remainder, not a sieve
        # the sum is checked to 1e-6 above: a remainder within that is the data's rounding, not mass
        passing = np.where(np.abs(passing) <= 1e-6, 0.0, passing)
        return size[keep], passing[keep]
    if np.any(size <= 0):
        raise InputError(f"{path}: sizes must be > 0 for cumulative data")
    passing = 1.0 - val if kind == "cum_retained" else val
    return size, passing


def _feed_psd(t: _Table, grid: SizeGrid, base: Path | None = None) -> np.ndarray:
    form = t.plain("form", kind=str)
    if form in ("sieves", "csv"):
        if form == "csv":
            name = t.plain("file", kind=str)
            path = _named_file(name, base)
            size, passing = _sieve_table(path, t.where)
        else:
            size = t.quantity("size", "length", array=True)
            if "passing_pct" in t.data or "passing_frac" in t.data:
                passing = t.quantity("passing", "fraction", allow_zero=True, array=True)
            else:
                passing = t.quantity("passing", "fraction", array=True)  # raises the "units missing" error
        tail = t.plain("tail", "sink", kind=str)
        points = t.plain("tail_points", 3, kind=float)
        if tail not in ("sink", "rosin_rammler", "ggs"):
            raise InputError(f"{t.where}.tail = {tail!r}: expected sink (mass below the finest sieve goes to the "
                             "grid's sink), rosin_rammler or ggs (fitted to the finest sieves, extrapolated)")
        t.finish("form, size_um, passing_pct (or file), tail, tail_points")
        size, passing = np.atleast_1d(size), np.atleast_1d(passing)
        if size.shape != passing.shape:
            raise InputError(f"{t.where}: {size.size} sizes but {passing.size} passing values")
        order = np.argsort(-size)
        size, passing = size[order], passing[order]
        if passing[0] < 1 - 1e-9:
            raise GridError(f"{t.where}: the coarsest sieve ({size[0] * 1e6:.6g} um) passes only "
                            f"{passing[0] * 100:.6g} %; add a sieve that passes 100 %")
        try:
            return from_sieves(size, passing, grid, tail=None if tail == "sink" else tail, tail_points=points)
        except GridError as exc:
            if size[0] <= grid.x[0] * (1 + 1e-12):  # the grid does cover it: say what is wrong instead
                raise GridError(f"{t.where}: {exc}") from exc
            raise GridError(f"{t.where}: the size grid does not cover the feed (grid.top = {grid.x[0] * 1e6:.6g} um, "
                            f"coarsest sieve {size[0] * 1e6:.6g} um): {exc}") from exc
    if form in ("rosin_rammler", "ggs"):
        if form == "rosin_rammler":
            x63 = t.quantity("x63", "length")
            n = t.plain("n", kind=float)
            t.finish("form, x63_um, n")
            if n <= 0:
                raise InputError(f"{t.where}.n = {n!r}: expected > 0")
            _inside_grid(t, "x63", x63, grid, "63 %")

            def cdf(x):
                return rosin_rammler(x, x63, n)
        else:
            xmax = t.quantity("xmax", "length")
            m = t.plain("m", kind=float)
            t.finish("form, xmax_um, m")
            if m <= 0:
                raise InputError(f"{t.where}.m = {m!r}: expected > 0")
            _inside_grid(t, "xmax", xmax, grid, "all")

            def cdf(x):
                return gates_gaudin_schuhmann(x, xmax, m)
        try:  # at most 0.01 % above the top edge is lumped into class 1 (psd.from_distribution)
            return from_distribution(grid, cdf, where=t.where)
        except GridError as exc:
            raise GridError(str(exc).replace("does not cover the PSD", "does not cover the feed")) from exc
    raise InputError(f"{t.where}.form = {form!r}: unknown feed PSD form; valid: ggs, rosin_rammler, sieves")


def _inside_grid(t: _Table, base: str, size: float, grid: SizeGrid, share: str) -> None:
    """Refuse a feed PSD size below the grid's finest size: ``share`` of the feed would sit in
    the sink class and pass through every unit unground, silently (x63_um = 0.8 meant mm?)."""
    bottom = float(grid.x[-1])
    if size < bottom:
        key = _user_key(t, base, "length")
        raise InputError(f"{t._at(key)} = {t.data[key]!r}: below the size grid's finest size ({bottom * 1e6:.4g} um), "
                         f"so at least {share} of the feed would be in the sink class; expected a size inside the grid "
                         f"({bottom * 1e6:.4g}..{grid.x[0] * 1e6:.4g} um); a unit slip?")


def _feed_water(t: _Table, solids: float) -> float:
    """Water of a feed [kg/s]: water_<mass flow> or solids_content_<fraction> (% solids by mass)."""
    water = t.quantity("water", "mass_flow", None, allow_zero=True)
    content = t.quantity("solids_content", "fraction", None)
    _warn_pct_slip(t, "solids_content")
    if water is not None and content is not None:
        raise InputError(f"{t.where}: give one of water_tph or solids_content_pct, not both")
    if content is not None:
        if not content <= 1.0:
            raise InputError(f"{t.where}.solids_content: {content * 100:.6g} % solids; expected a value in (0, 100] %")
        return solids * (1.0 - content) / content
    return 0.0 if water is None else water


def _feed(name: str, t: _Table, grid: SizeGrid, base: Path | None = None) -> Feed:
    """A feed unit: solids flow, PSD and water."""
    solids = _plausible(t, "solids", "mass_flow", t.quantity("solids", "mass_flow"))
    psd = _feed_psd(t.sub("psd"), grid, base)
    t.plain("material", None)
    water = _feed_water(t, solids)
    t.finish("type, solids_tph, psd, material, water_tph or solids_content_pct")
    return Feed(name, solids, psd, water)
