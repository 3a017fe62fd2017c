"""A flowsheet document's tables: values by name, units converted through :mod:`millflow.inputs`.

:class:`_Table` hands out plain values (``plain``) and unit-suffixed ones in SI
(``quantity``, through :func:`millflow.inputs.quantity`, the one reader of unit-suffixed
keys), tracks which keys were used and names the first unknown key. The helpers here turn
library errors into one line naming the key (``_wrap``), refuse values outside a plausible
range (``PLAUSIBLE``: a unit slip) and warn once per file.
"""
from __future__ import annotations

import math
from pathlib import Path

from millflow.errors import InputError, MillflowError
from millflow.inputs import UNITS, quantity, suffixes


def _suffixes(dim: str) -> str:
    return suffixes(dim)


class _Table:
    """A TOML table with its dotted location, handing out values by name and tracking use."""

    def __init__(self, data, where: str):
        if not isinstance(data, dict):
            raise InputError(f"{where}: expected a table {{...}}, got {data!r}")
        self.data, self.where, self.used = data, where, set()

    def _at(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def plain(self, key, default=..., *, kind=None):
        if key not in self.data:
            bad = [k for k in self.data if k.startswith(key + "_")]
            if bad:
                raise InputError(f"{self._at(bad[0])}: {key!r} is dimensionless; write it as {key} = ...")
            if default is ...:
                raise InputError(f"{self.where or 'top level'}: missing parameter {key!r}")
            return default
        self.used.add(key)
        v = self.data[key]
        if kind is float:
            return _number(v, self._at(key))
        if kind is str and not isinstance(v, str):
            raise InputError(f"{self._at(key)} = {v!r}: expected a string")
        return v

    def quantity(self, base: str, dim: str, default=..., *, positive=True, allow_zero=False, array=False):
        """Value of ``base_<suffix>`` in SI (:func:`millflow.inputs.quantity`, the one reader
        of unit-suffixed keys); error if written without a unit or missing."""
        return quantity(self.data, base, dim, self.where, default, positive=positive, allow_zero=allow_zero,
                        array=array, used=self.used)

    def sub(self, key, default=...):
        if key not in self.data:
            if default is ...:
                raise InputError(f"{self.where or 'top level'}: missing table {key!r}")
            return default
        self.used.add(key)
        return _Table(self.data[key], self._at(key))

    def finish(self, valid: str = "") -> None:
        extra = [k for k in self.data if k not in self.used]
        if extra:
            hint = f"; valid keys: {valid}" if valid else ""
            raise InputError(f"{self._at(extra[0])}: unknown key{hint}")


def _number(v, where: str, array_ok: bool = False):
    if isinstance(v, bool):
        raise InputError(f"{where} = {v!r}: expected a number")
    if isinstance(v, (int, float)):
        if not math.isfinite(v):
            raise InputError(f"{where} = {v!r}: expected a finite number")
        return float(v)
    if array_ok and isinstance(v, list) and all(isinstance(e, (int, float)) and not isinstance(e, bool) for e in v):
        return [float(e) for e in v]
    raise InputError(f"{where} = {v!r}: expected a number{' or a list of numbers' if array_ok else ''}")


def _wrap(where: str, fun, *args, **kw):
    try:
        return fun(*args, **kw)
    except MillflowError as exc:
        raise type(exc)(f"{where}: {exc}") from exc
    except (ValueError, TypeError) as exc:  # e.g. rtd.ParameterError
        raise InputError(f"{where}: {exc}") from exc


#: Plausible ranges of a unit's extensive keys, in SI: outside them a value is a unit slip or
#: a typo, and the numbers downstream overflow (rates S = S^E P / H at H = 1e-306 t are
#: infinite) or lose their meaning (a hold-up of 1e306 t). (base, dimension) -> (low, high, SI unit).
PLAUSIBLE = {
    ("holdup", "mass"): (1e-6, 1e10, "kg"),          # 1 mg .. 10 Mt
    ("tau", "time"): (1e-6, 1e9, "s"),                # 1 us .. 30 years
    ("power", "power"): (0.0, 1e10, "W"),             # .. 10 GW
    ("solids", "mass_flow"): (1e-9, 1e9, "kg/s"),     # 3.6e-6 kg/h .. 3.6e6 t/h
    ("slurry_volume", "volume"): (1e-9, 1e6, "m3"),   # 1 mm3 .. 1e6 m3
}


def _user_key(t: _Table, base: str, dim: str) -> str | None:
    """The key the file wrote for ``base`` (e.g. holdup_t), or None."""
    found = [k for k in t.data if k.startswith(base + "_") and k[len(base) + 1:] in UNITS[dim]]
    return found[0] if found else None


def _plausible(t: _Table, base: str, dim: str, value):
    """``value`` (SI) if inside :data:`PLAUSIBLE`, else an InputError naming the key and the
    range in the unit the file used."""
    if value is None:
        return value
    lo, hi, si = PLAUSIBLE[(base, dim)]
    if lo <= value <= hi:
        return value
    key = _user_key(t, base, dim)
    unit = key[len(base) + 1:]
    factor = UNITS[dim][unit]
    raise InputError(f"{t._at(key)} = {t.data[key]!r}: outside the plausible range {lo / factor:.3g}.."
                     f"{hi / factor:.3g} {unit.replace('_', '/')} ({lo:.3g}..{hi:.3g} {si}); a unit slip?")


#: Warnings already given for this file: the grid check parses the document again and would
#: repeat each one (cleared by :func:`load` and :func:`loads`).
_WARNED: set = set()


def _warn_once(message: str) -> None:
    import warnings

    if message not in _WARNED:
        _WARNED.add(message)
        warnings.warn(message, UserWarning, stacklevel=3)


#: Below this % solids a ``..._pct`` key is most likely a fraction written as percent
#: (0.96 meant 96 %): real mill and classifier slurries carry a few % solids at least.
PLAUSIBLE_MIN_PCT_SOLIDS = 2.0


def _warn_pct_slip(t: _Table, base: str) -> None:
    """One-line warning at a % solids key whose value looks like a fraction (unit slip)."""
    v = t.data.get(f"{base}_pct")
    if isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < PLAUSIBLE_MIN_PCT_SOLIDS:
        _warn_once(f"{t.where}.{base}_pct = {v!r}: {v:g} % solids by mass is implausibly dilute; if a fraction "
                   f"was meant write {base}_pct = {v * 100:g} (or {base}_frac = {v!r})")


def _named_file(name: str, base: Path | None, folder_file: str | None = None) -> Path:
    """A file a flowsheet names, relative to the flowsheet's folder (``base``; the current
    folder without one); a folder stands for its ``folder_file`` (a fit's --out folder)."""
    p = Path(name) if Path(name).is_absolute() else (base or Path.cwd()) / name
    return p / folder_file if folder_file and p.is_dir() else p
