"""Reading the user's files: one place for encodings, TOML syntax and CSV parsing errors.

Every reader returns the parsed content or raises :class:`~millflow.errors.InputError`
with one line naming the file and what is wrong:

- text is UTF-8, with or without a byte-order mark; anything else (Latin-1, UTF-16,
  binary) names the byte offset of the first byte that is not UTF-8 and says to save
  the file as UTF-8;
- TOML syntax errors keep tomllib's line and column;
- CSV files are read by pandas from the decoded text, so the same rules hold, and
  parser errors name the file.
"""
from __future__ import annotations

import codecs
import io
import json
import math
import tomllib
from pathlib import Path

import numpy as np

from millflow.errors import InputError

__all__ = ["read_text", "read_toml", "read_json", "read_csv", "read_matrix", "number", "integer", "boolean", "string",
           "table_of", "check_keys", "UNITS", "quantity", "unit_keys", "suffixes", "unit_column"]


def read_text(path, what: str = "file") -> str:
    """The file's text, decoded as UTF-8 (a leading byte-order mark is dropped)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{p}: {what} not found") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a folder; expected a {what}") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    if raw.startswith(codecs.BOM_UTF16_LE) or raw.startswith(codecs.BOM_UTF16_BE):
        raise InputError(f"{p}: the {what} is UTF-16 encoded; save it as UTF-8")
    nul = raw.find(b"\x00", 0, 4096)
    if nul >= 0:
        raise InputError(f"{p}: the {what} is binary (a NUL byte at offset {nul}); expected UTF-8 text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise InputError(f"{p}: byte {exc.start} (line {line}) is not UTF-8 (0x{raw[exc.start]:02x}); "
                         f"save the {what} as UTF-8") from None


def read_toml(path, what: str = "TOML file") -> dict:
    """The parsed TOML file (syntax errors name the file, line and column)."""
    text = read_text(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{Path(path)}: not valid TOML ({exc})") from None


def read_json(path, what: str = "JSON file"):
    """The parsed JSON file (syntax errors name the file, line and column)."""
    text = read_text(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{Path(path)}: not valid JSON ({exc.msg} at line {exc.lineno}, "
                         f"column {exc.colno})") from None


def read_matrix(path, what: str = "CSV matrix") -> np.ndarray:
    """A 2-D array of numbers from a CSV file without a header (lines starting with ``#``
    are comments); encodings as :func:`read_text`, anything else than numbers named."""
    text = read_text(path, what)
    try:
        return np.loadtxt(io.StringIO(text), delimiter=",", ndmin=2, dtype=float)
    except ValueError as exc:
        raise InputError(f"{Path(path)}: not a {what} of numbers: {' '.join(str(exc).split())}") from None


def read_csv(path, what: str = "CSV file", **kw):
    """A pandas DataFrame of the CSV file (encoding and parser errors name the file)."""
    import pandas as pd

    text = read_text(path, what)
    try:
        return pd.read_csv(io.StringIO(text), **kw)
    except pd.errors.EmptyDataError:
        raise InputError(f"{Path(path)}: the {what} is empty") from None
    except (pd.errors.ParserError, ValueError) as exc:
        msg = " ".join(str(exc).split())
        raise InputError(f"{Path(path)}: cannot read the {what}: {msg}") from None


# ------------------------------------------------------------------ typed values
def _show(v) -> str:
    """A value as the user wrote it (no numpy reprs)."""
    if hasattr(v, "item") and getattr(v, "ndim", 1) == 0:
        v = v.item()
    return repr(v)


def number(table: dict, key: str, where: str, default=..., *, lo=None, hi=None, lo_open=False,
           hi_open=False) -> float:
    """A finite number (int or float, not a boolean, string or list) within the bounds."""
    if key not in table:
        if default is ...:
            raise InputError(f"{where}: missing key {key!r}")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"{where}.{key} = {_show(v)}: expected a number")
    v = float(v)
    if not math.isfinite(v):
        raise InputError(f"{where}.{key} = {_show(v)}: expected a finite number")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise InputError(f"{where}.{key} = {_show(table[key])}: expected {'>' if lo_open else '>='} {lo:g}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise InputError(f"{where}.{key} = {_show(table[key])}: expected {'<' if hi_open else '<='} {hi:g}")
    return v


def integer(table: dict, key: str, where: str, default=..., *, lo=None, hi=None) -> int:
    """A whole number (an int, not 2.7, a boolean or a string) within the bounds."""
    if key not in table:
        if default is ...:
            raise InputError(f"{where}: missing key {key!r}")
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int):
        raise InputError(f"{where}.{key} = {_show(v)}: expected a whole number")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else (f"<= {hi}" if lo is None else f"between {lo} and {hi}")
        raise InputError(f"{where}.{key} = {v}: expected a whole number {rng}")
    return v


def boolean(table: dict, key: str, where: str, default=...) -> bool:
    """true or false (not "no", 0 or 1)."""
    if key not in table:
        if default is ...:
            raise InputError(f"{where}: missing key {key!r}")
        return default
    v = table[key]
    if not isinstance(v, bool):
        raise InputError(f"{where}.{key} = {_show(v)}: expected true or false")
    return v


def string(table: dict, key: str, where: str, default=..., *, choices=None) -> str:
    """A string, one of ``choices`` if given."""
    if key not in table:
        if default is ...:
            raise InputError(f"{where}: missing key {key!r}")
        return default
    v = table[key]
    if not isinstance(v, str):
        raise InputError(f"{where}.{key} = {_show(v)}: expected a string")
    if choices is not None and v not in choices:
        raise InputError(f"{where}.{key} = {v!r}: expected one of {', '.join(map(repr, choices))}")
    return v


def table_of(parent: dict, key: str, where: str) -> dict:
    """A sub-table (empty if absent); anything else than a table is named."""
    v = parent.get(key, {})
    if not isinstance(v, dict):
        raise InputError(f"{where}{key}: expected a table [{key}], got {_show(v)}")
    return v


def check_keys(table: dict, allowed, where: str) -> None:
    """Refuse keys that are not in ``allowed`` (misspelt or misplaced keys are never dropped)."""
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                         f"expected some of {', '.join(sorted(allowed))}")


# --------------------------------------------------------- unit-suffixed keys
#: Unit suffixes of keys per dimension, with the factor to SI: a key is written
#: ``<name>_<unit>`` (``tau_min``, ``top_mm``, ``feed_tph``) and read in SI.
UNITS = {
    "length": {"um": 1e-6, "mm": 1e-3, "m": 1.0, "in": 0.0254, "ft": 0.3048},
    "time": {"s": 1.0, "min": 60.0, "h": 3600.0},
    "mass_flow": {"tph": 1000.0 / 3600.0, "kg_s": 1.0},
    "mass": {"t": 1000.0, "kg": 1.0},
    "power": {"W": 1.0, "kW": 1e3, "MW": 1e6},
    "rate": {"per_s": 1.0, "per_min": 1.0 / 60.0, "per_h": 1.0 / 3600.0},
    # breakage per specific energy, S^E of S = S^E P / H (Herbst-Fuerstenau), SI kg/J
    "energy_rate": {"t_per_kWh": 1000.0 / 3.6e6, "kg_per_kWh": 1.0 / 3.6e6, "kg_per_J": 1.0},
    "fraction": {"pct": 0.01, "frac": 1.0},
    "density": {"kg_m3": 1.0, "t_m3": 1000.0},
    "volume": {"m3": 1.0, "L": 1e-3},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "bar": 1e5},
    "viscosity": {"Pa_s": 1.0, "mPa_s": 1e-3, "cP": 1e-3},
}


def suffixes(dim: str) -> str:
    return ", ".join(f"_{s}" for s in UNITS[dim])


def unit_keys(base: str, dim: str) -> set:
    """Every spelling of ``base`` with a unit of ``dim`` (for check_keys)."""
    return {f"{base}_{u}" for u in UNITS[dim]}


def quantity(table: dict, base: str, dim: str, where: str, default=..., *, positive: bool = True,
             allow_zero: bool = False, array: bool = False, used: set | None = None):
    """The value of ``base_<unit>`` in SI (one reader for flowsheet, fit and plant files).

    Refused, each with one line naming the key: the bare ``base`` (units of measure
    missing), two spellings at once, an unknown unit, a non-number (a list only where
    ``array``), a negative (or zero) value where ``positive``. ``used`` collects the key
    read (for tables that refuse unread keys).
    """
    units = UNITS[dim]
    prefix = base + "_"
    cut = len(prefix)
    found = [k for k in table if k.startswith(prefix) and k[cut:] in units]
    if base in table:
        at = f"{where}.{base}" if where else base
        raise InputError(f"{at}: units of measure missing; write {base}_<unit> with one of {suffixes(dim)} "
                         f"(e.g. {base}_{next(iter(units))})")
    if len(found) > 1:
        raise InputError(f"{where or 'top level'}: {', '.join(found)} give {base!r} twice; keep one")
    if not found:
        wrong = [k for k in table if k.startswith(prefix)]
        if wrong:
            raise InputError(f"{where + '.' if where else ''}{wrong[0]}: unknown unit {wrong[0][cut:]!r} "
                             f"for {base} ({dim}); expected one of {suffixes(dim)}")
        if default is ...:
            raise InputError(f"{where or 'top level'}: missing parameter {base}_<unit> ({dim}: {suffixes(dim)})")
        return default
    key = found[0]
    if used is not None:
        used.add(key)
    v = table[key]
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        # a single number (the common case) in Python floats: the same checks and the same
        # IEEE product as the array path below, without numpy's per-call overhead
        x = float(v)
        bad = None
        if not math.isfinite(x):
            bad = "expected finite numbers"
        elif positive and (x < 0 or (not allow_zero and x == 0)):
            bad = f"expected a value {'>= 0' if allow_zero else '> 0'}"
        else:
            out = x * units[key[cut:]]
            if math.isfinite(out) and (out != 0 or x == 0):
                return out
            bad = f"out of range (in SI units it {'overflows' if not math.isfinite(out) else 'underflows to 0'})"
        raise InputError(f"{where + '.' if where else ''}{key} = {_show(v)}: {bad}")
    ok_list = array and isinstance(v, list) and all(isinstance(e, (int, float)) and not isinstance(e, bool)
                                                    for e in v)
    if not ok_list:
        raise InputError(f"{where + '.' if where else ''}{key} = {_show(v)}: expected a number"
                         + (" or a list of numbers" if array else ""))
    arr = np.asarray(v, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{where + '.' if where else ''}{key} = {_show(v)}: expected finite numbers")
    if positive and (np.any(arr < 0) or (not allow_zero and np.any(arr == 0))):
        raise InputError(f"{where + '.' if where else ''}{key} = {_show(v)}: expected a value "
                         f"{'>= 0' if allow_zero else '> 0'}")
    with np.errstate(over="ignore", under="ignore"):
        out = arr * units[key[cut:]]
    lost = ~np.isfinite(out) | ((out == 0) & (arr != 0))
    if np.any(lost):  # the unit conversion overflowed (1e306 t) or underflowed to 0
        raise InputError(f"{where + '.' if where else ''}{key} = {_show(v)}: out of range (in SI units it "
                         f"{'overflows' if not np.all(np.isfinite(out)) else 'underflows to 0'})")
    return float(out) if out.ndim == 0 else out


def unit_column(columns, stem: str, dim: str, source: str, required: bool = True,
                extra: dict | None = None) -> tuple[str | None, float | None]:
    """(column, factor to SI) of the table column named ``<stem>_<unit>`` (``size_um``,
    ``time_min``): the column-name form of :func:`quantity`, for CSV files.

    Refused, each with one line naming the file and the column: the bare ``stem`` (units
    of measure missing), an unknown unit (``size_cm``), two spellings at once, and no such
    column where ``required``. ``extra`` adds unit spellings of this table only (a legacy
    ``micron``). Without the column and not ``required``: (None, None).
    """
    units = {**UNITS[dim], **(extra or {})}
    cols = [str(c).strip() for c in columns]
    hits = [c for c in cols if c.startswith(stem + "_") and c[len(stem) + 1:] in units]
    if stem in cols:
        raise InputError(f"{source}: column {stem!r}: units of measure missing; name it {stem}_<unit> with one "
                         f"of {suffixes(dim)} (e.g. {stem}_{next(iter(UNITS[dim]))})")
    if len(hits) > 1:
        raise InputError(f"{source}: columns {', '.join(hits)} give {stem!r} twice; keep one")
    if not hits:
        wrong = [c for c in cols if c.startswith(stem + "_")]
        if wrong:
            raise InputError(f"{source}: column {wrong[0]!r}: unknown unit {wrong[0][len(stem) + 1:]!r} for {stem} "
                             f"({dim}); expected one of {suffixes(dim)}")
        if required:
            raise InputError(f"{source}: no column {stem}_<unit> ({dim}: {suffixes(dim)}); columns are {cols}")
        return None, None
    return hits[0], units[hits[0][len(stem) + 1:]]
