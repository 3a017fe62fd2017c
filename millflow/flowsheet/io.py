"""Reading flowsheet files (TOML) into a :class:`~millflow.flowsheet.graph.Flowsheet`.

Units of measure are part of every dimensional key name (``feed_tph``, ``tau_min``,
``d50c_um``) and are converted to SI here, at the edge, and nowhere else. A
dimensional key written without a suffix (``tau = 5``) is an error naming the key and
the suffixes it accepts; unknown keys, unknown unit types, missing or negative
parameters, and streams that dangle or connect an outlet twice are errors naming the
key or stream. The format is described in docs/flowsheets.md.

This module puts the document together; each part is read by a module of
:mod:`millflow.flowsheet.readers` (``tables``, ``grid``, ``feeds``, ``materials``,
``transport``, ``mills``, ``classifiers``), whose names are importable from here too.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from millflow.errors import InputError, MillflowError
from millflow.flowsheet import graph
from millflow.flowsheet.graph import Stream
# the readers of the document's parts; their names stay importable from here
from millflow.flowsheet.readers.classifiers import (  # noqa: F401
    _CALIBRATION, _CYCLONE_SIZES, _SIZE_PARAMS, CYCLONE_MIN_SIZE_M, _classifier, _classifier_water, _curve_params,
    _predicted_cyclone)
from millflow.flowsheet.readers.feeds import _feed, _feed_psd, _feed_water, _inside_grid, _sieve_table  # noqa: F401
from millflow.flowsheet.readers.grid import _grid, _grid_edges  # noqa: F401
from millflow.flowsheet.readers.materials import (  # noqa: F401
    _breakage, _breakage_table, _energy_rate, _fitted_material, _materials, _per_energy, _rate)
from millflow.flowsheet.readers.mills import _kinetics, _mill  # noqa: F401
from millflow.flowsheet.readers.tables import (  # noqa: F401
    _WARNED, PLAUSIBLE, PLAUSIBLE_MIN_PCT_SOLIDS, _named_file, _number, _plausible, _suffixes, _Table, _user_key,
    _warn_once, _warn_pct_slip, _wrap)
from millflow.flowsheet.readers.transport import _rtd_fit, _transport_part, _transport_table  # noqa: F401
from millflow.flowsheet.units import UNIT_TYPES, Mixer, Product, Splitter
from millflow.flowsheet.water import Slurry
from millflow.grid import SizeGrid
from millflow.inputs import UNITS, read_text

__all__ = ["Flowsheet", "load", "loads", "from_dict", "with_units", "unit_from_table", "DIMENSIONS"]


class Flowsheet(graph.Flowsheet):
    """A flowsheet with its readers, ``from_dict`` and ``load``.

    A flowsheet (:class:`millflow.flowsheet.graph.Flowsheet`) with its readers:
    ``Flowsheet.from_dict(data)`` (the document a TOML file would hold, as a dict) and
    ``Flowsheet.load(path)``.
    """

    @classmethod
    def from_dict(cls, data: dict, *, source: str = "<dict>", base_dir=None) -> Flowsheet:
        """Build a flowsheet from the parsed document ``data`` (:func:`from_dict`)."""
        return from_dict(data, source=source, base_dir=base_dir)

    @classmethod
    def load(cls, path) -> Flowsheet:
        """Read a flowsheet file (:func:`load`)."""
        return load(path)

#: Accepted unit suffixes per dimension, with the factor to SI (the one table:
#: :data:`millflow.inputs.UNITS`, shared with fit configs and plant files).
DIMENSIONS = UNITS


def _unit(name: str, t: _Table, grid: SizeGrid, materials: dict, slurry=None, base: Path | None = None):
    utype = t.plain("type", kind=str)
    if utype not in UNIT_TYPES:
        raise InputError(f"units.{name}.type = {utype!r}: unknown unit type; valid: {', '.join(sorted(UNIT_TYPES))}")
    if utype == "feed":
        return _feed(name, t, grid, base)
    if utype == "mill":
        return _mill(name, t, materials, slurry, base, grid)
    if utype in ("hydrocyclone", "screen", "air_separator", "dynamic_classifier"):
        return _classifier(name, utype, t, slurry)
    if utype in ("mixer", "tank"):
        holdup = _plausible(t, "holdup", "mass", t.quantity("holdup", "mass", None))
        t.finish("type, holdup_t, add_water_tph")
        return Mixer(name, holdup)
    if utype == "splitter":
        ft = t.sub("fractions")
        fr = {k: ft.plain(k, kind=float) for k in list(ft.data)}
        for k, v in fr.items():
            if not 0 <= v <= 1:
                raise InputError(f"units.{name}.fractions.{k} = {v!r}: expected a fraction in [0, 1]")
        t.finish("type, fractions, add_water_tph")
        return _wrap(f"units.{name}", Splitter, name, fr)
    t.finish("type")
    return Product(name)


def from_dict(data: dict, *, source: str = "<dict>", base_dir=None) -> Flowsheet:
    """Build a Flowsheet from the parsed TOML document ``data`` (see docs/flowsheets.md).

    Files a flowsheet names (a feed PSD CSV, fit results) are read relative to ``base_dir``
    (default: the folder of ``source`` when it is a file, else the current folder).
    """
    base = Path(base_dir) if base_dir is not None else (
        Path(source).resolve().parent if source and not source.startswith("<") else None)
    top = _Table(data, "")
    title = top.plain("title", "", kind=str)
    grid = _grid(top.sub("grid"))
    passing = ()
    rep = top.sub("report", None)
    if rep is not None:
        passing = tuple(np.atleast_1d(rep.quantity("passing", "length", (), array=True)))
        rep.finish("passing_um")
    slurry = None
    sl = top.sub("slurry", None)
    if sl is not None:
        rho_s = sl.quantity("solids_density", "density")
        rho_w = sl.quantity("water_density", "density", 1000.0)
        sl.finish("solids_density_t_m3, water_density_kg_m3")
        slurry = Slurry(rho_s, rho_w)  # its errors name slurry.<key>
    materials = _materials(top.sub("materials", None), base, grid)
    units, water_added = {}, {}
    ut = top.sub("units")
    for uname in ut.data:
        u = ut.sub(uname)
        added = u.quantity("add_water", "mass_flow", None, allow_zero=True)
        units[uname] = _unit(uname, u, grid, materials, slurry, base)
        if added is not None:
            if units[uname].type in ("feed", "product"):
                raise InputError(f"units.{uname}.add_water: a {units[uname].type} takes no water addition "
                                 "(give a feed its water_tph)")
            water_added[uname] = added
    streams = {}
    st = top.sub("streams")
    for sname in st.data:
        s = st.sub(sname)
        src = s.plain("from", kind=str)
        dst = s.plain("to", kind=str)
        s.finish("from, to")
        uname, _, port = src.partition(".")
        if uname in units and not port:
            ports = units[uname].ports
            if len(ports) != 1:
                raise InputError(f"streams.{sname}.from = {src!r}: unit {uname!r} has outlets "
                                 f"{', '.join(ports) or 'none'}; write from = \"{uname}.<outlet>\"")
            port = ports[0]
        streams[sname] = Stream(sname, uname, port, dst)
    top.finish("title, grid, report, slurry, materials, units, streams")
    return Flowsheet(grid=grid, units=units, streams=streams, title=title, passing_sizes=passing,
                     source_file=source, slurry=slurry, water_added=water_added,
                     meta={"document": data, "base_dir": None if base is None else str(base), "materials": materials})


def unit_from_table(fs: Flowsheet, name: str, table: dict):
    """A unit built again from its table on the grid, materials and slurry of ``fs``.

    (unit, water added to its feed [kg/s] or None) built from its ``table`` (as in the
    document) on the grid, materials and slurry of ``fs``. A mill whose rate and breakage
    come out the very objects of the mill of that name in ``fs`` keeps its class-averaged
    forms on the grid: they depend on neither tau, power nor transport.
    """
    materials = fs.meta.get("materials")
    if materials is None:
        raise InputError("unit_from_table: the flowsheet was not built from a document (from_dict, load)")
    if name not in fs.units:
        raise InputError(f"units.{name}: no such unit in the flowsheet; units: {', '.join(fs.units)}")
    base = Path(fs.meta["base_dir"]) if fs.meta.get("base_dir") else None
    u = _Table(table, f"units.{name}")
    added = u.quantity("add_water", "mass_flow", None, allow_zero=True)
    new = _unit(name, u, fs.grid, materials, fs.slurry, base)
    if added is not None and new.type in ("feed", "product"):
        raise InputError(f"units.{name}.add_water: a {new.type} takes no water addition (give a feed its water_tph)")
    old = fs.units[name]
    kept = old.__dict__.get("_grid_forms") if new.type == "mill" == old.type else None
    if kept is not None and new.rate is old.rate and new.breakage is old.breakage:
        object.__setattr__(new, "_grid_forms", kept)  # the cache of MillUnit._on_grid: the same forms
    return new, added


def with_units(fs: Flowsheet, tables: dict, built: dict | None = None) -> Flowsheet:
    """The flowsheet ``fs`` with some units built again from new tables.

    ``fs`` with the units named in ``tables`` (unit name -> its table, as in the document)
    built again from those tables (:func:`unit_from_table`); grid, materials, streams and
    the other units are the very objects of ``fs`` (a sweep's case that changes keys of
    some units). ``built`` (name -> (unit, water added)) gives units built already.
    """
    units, water_added = dict(fs.units), dict(fs.water_added)
    for uname, table in tables.items():
        new, added = (built or {}).get(uname) or unit_from_table(fs, uname, table)
        if added is not None:
            water_added[uname] = added
        else:
            water_added.pop(uname, None)
        units[uname] = new
    document = dict(fs.meta.get("document") or {})
    document["units"] = {**document.get("units", {}), **tables}
    return Flowsheet(grid=fs.grid, units=units, streams=fs.streams, title=fs.title, passing_sizes=fs.passing_sizes,
                     source_file=fs.source_file, slurry=fs.slurry, water_added=water_added,
                     meta={**fs.meta, "document": document})


def loads(text: str, *, source: str = "<string>") -> Flowsheet:
    """Flowsheet from TOML text (the format of docs/flowsheets.md).

    Parameters
    ----------
    text : str
        The TOML document.
    source : str
        Name used in error messages (and, when it is a file name, the folder that files
        the flowsheet names are read from).

    Returns
    -------
    Flowsheet

    Raises
    ------
    InputError
        Invalid TOML, or a key, unit, value or stream that is wrong (one line naming it).
    GridError
        A size grid that does not cover the feed.

    Examples
    --------
    >>> fs = loads('''
    ... grid = {top_um = 1000, bottom_um = 100, n = 4}
    ... [units]
    ... feed = {type = "feed", solids_tph = 36, psd = {form = "ggs", xmax_um = 1000, m = 0.8}}
    ... out = {type = "product"}
    ... [streams]
    ... s = {from = "feed", to = "out"}
    ... ''')
    >>> fs.units["feed"].solids  # 36 t/h in SI [kg/s]
    10.0
    >>> loads("grid = {top = 1000}")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    millflow.errors.InputError: <string>: grid.top: units of measure missing; write top_<unit> with ...
    """
    _WARNED.clear()  # a new document: its warnings are new (the grid check's re-parse is not)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML ({exc})") from exc
    try:
        return from_dict(data, source=source)
    except MillflowError as exc:
        raise type(exc)(f"{source}: {exc}") from exc


def load(path) -> Flowsheet:
    """Flowsheet from a TOML file (the format of docs/flowsheets.md).

    Files the flowsheet names (a feed CSV, fit results) are read relative to its folder.

    Parameters
    ----------
    path : str or path-like
        The flowsheet file (UTF-8 TOML).

    Returns
    -------
    Flowsheet
        With ``meta["input_sha256"]``, the SHA-256 of the file as read.

    Raises
    ------
    InputError
        A missing or unreadable file, invalid TOML, or a wrong key, unit, value or stream
        (one line naming it).
    GridError
        A size grid that does not cover the feed.
    """
    import hashlib

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: flowsheet file not found")
    fs = loads(read_text(p, "flowsheet file"), source=str(p))
    fs.meta["input_sha256"] = hashlib.sha256(p.read_bytes()).hexdigest()  # once, not per summary
    return fs
