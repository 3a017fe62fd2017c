"""Reading flowsheet files (TOML) into a :class:`~millflow.flowsheet.graph.Flowsheet`.

Units of measure are part of every dimensional key name (``feed_tph``, ``tau_min``,
``d50c_um``) and are converted to SI here, at the edge, and nowhere else. A
dimensional key written without a suffix (``tau = 5``) is an error naming the key and
the suffixes it accepts; unknown keys, unknown unit types, missing or negative
parameters, and streams that dangle or connect an outlet twice are errors naming the
key or stream. The format is described in docs/flowsheets.md.
"""
from __future__ import annotations

import inspect
import math
import tomllib
from pathlib import Path

import numpy as np

from millflow.breakage import AustinRate, NonNormalizedBreakage, NormalizedBreakage, PowerLawRate
from millflow.breakage.energy import EnergySpecificRate, from_lab
from millflow.classifiers import CURVES
from millflow.errors import GridError, InputError, MillflowError
from millflow.flowsheet import graph
from millflow.flowsheet.graph import Stream
from millflow.flowsheet.water import Slurry
from millflow.flowsheet.units import (TRANSPORTS, UNIT_TYPES, Classifier, Feed, MillUnit, Mixer,
                                      Product, Splitter, build_transport)
from millflow.grid import SCHEMES, SizeGrid
from rtd import names as rtd_names
from millflow.inputs import UNITS, quantity, read_json, read_text, suffixes
from millflow.psd import from_distribution, from_sieves, gates_gaudin_schuhmann, rosin_rammler

__all__ = ["Flowsheet", "load", "loads", "from_dict", "with_units", "unit_from_table", "DIMENSIONS"]


class Flowsheet(graph.Flowsheet):
    """A flowsheet (:class:`millflow.flowsheet.graph.Flowsheet`) with its readers:
    ``Flowsheet.from_dict(data)`` (the document a TOML file would hold, as a dict) and
    ``Flowsheet.load(path)``."""

    @classmethod
    def from_dict(cls, data: dict, *, source: str = "<dict>", base_dir=None) -> Flowsheet:
        return from_dict(data, source=source, base_dir=base_dir)

    @classmethod
    def load(cls, path) -> Flowsheet:
        return load(path)

#: Accepted unit suffixes per dimension, with the factor to SI (the one table:
#: :data:`millflow.inputs.UNITS`, shared with fit configs and plant files).
DIMENSIONS = UNITS


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


# ------------------------------------------------------------------------ grid
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


# ------------------------------------------------------------------------ PSD
def _named_file(name: str, base: Path | None, folder_file: str | None = None) -> Path:
    """A file a flowsheet names, relative to the flowsheet's folder (``base``; the current
    folder without one); a folder stands for its ``folder_file`` (a fit's --out folder)."""
    p = Path(name) if Path(name).is_absolute() else (base or Path.cwd()) / name
    return p / folder_file if folder_file and p.is_dir() else p


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
    size_cols = [c for c in cols if c.startswith("size_") and c[5:] in UNITS["length"]]
    if len(size_cols) != 1:
        raise InputError(f"{path}: expected one size column with its unit (size_um, size_mm or size_m); "
                         f"columns: {', '.join(cols)}")
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
    for col in (size_cols[0], kinds[0]):
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
    size = out[size_cols[0]] * UNITS["length"][size_cols[0][5:]]
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


# ------------------------------------------------------------------ breakage
def _rate(t: _Table):
    if any(k.startswith("A_E_") for k in t.data):
        return _energy_rate(t)
    form = t.plain("form", kind=str)
    if form == "power":
        A = t.quantity("A", "rate", allow_zero=True)
        alpha = t.plain("alpha", kind=float)
        x0 = t.quantity("x0", "length", 1e-3)
        t.finish("form, A_per_min, alpha, x0_um")
        return _wrap(t.where, PowerLawRate, A, alpha, x0)
    if form == "austin":
        A = t.quantity("A", "rate", allow_zero=True)
        alpha = t.plain("alpha", kind=float)
        mu = t.quantity("mu", "length")
        Lam = t.plain("Lambda", kind=float)
        x0 = t.quantity("x0", "length", 1e-3)
        xi = t.plain("xi", 0.0, kind=float)
        eta = t.plain("eta", 0.0, kind=float)
        xb = t.quantity("x_b", "length", None)
        xb0 = t.quantity("x_b0", "length", None)
        t.finish("form, A_per_min, alpha, mu_um, Lambda, x0_um, and for ball size: x_b_mm (ball), x_b0_mm "
                 "(reference ball), xi, eta")
        return _wrap(t.where, AustinRate, A, alpha, mu, Lam, xi=xi, x_b=xb, x_b0=xb0, eta=eta, x0=x0)
    raise InputError(f"{t.where}.form = {form!r}: unknown rate form; valid: austin, power")


def _energy_rate(t: _Table) -> EnergySpecificRate:
    """A rate table given per energy (``A_E_t_per_kWh``): S^E of S = S^E P / H (Herbst-Fuerstenau)."""
    A = t.quantity("A_E", "energy_rate", allow_zero=True)
    key = next(k for k in t.data if k.startswith("A_E_"))
    rest = {k: v for k, v in t.data.items() if k != key}
    if any(k.startswith("A_") for k in rest):
        raise InputError(f"{t.where}: {key} and {next(k for k in rest if k.startswith('A_'))} both give A; "
                         "keep one (A_E_<unit> per energy, or A_<unit> per time)")
    rest["A_per_s"] = A  # S^E [kg/J] carried through the same rate form
    inner = _rate(_Table(rest, t.where))
    t.used.update(t.data)
    return EnergySpecificRate(inner, source=f"{t.where}.{key}")


def _per_energy(t: _Table, rate):
    """``per_energy = {lab_power_kW, lab_holdup_kg}``: a time rate measured in a lab mill carried
    per energy, S^E = S_lab H_lab / P_lab."""
    P = t.quantity("lab_power", "power")
    H = t.quantity("lab_holdup", "mass")
    t.finish("lab_power_kW, lab_holdup_kg")
    if rate is None:
        raise InputError(f"{t.where}: the material has no rate to carry per energy")
    if getattr(rate, "basis", "time") == "energy":
        raise InputError(f"{t.where}: the rate is already per energy (A_E_...); remove per_energy")
    return from_lab(rate, P, H)


def _breakage_table(t: _Table, base: Path | None, grid: SizeGrid | None):
    """A user's b_ij or B_ij matrix from a CSV file (N x N numbers, no header, class 1 first)."""
    from millflow.breakage import TabulatedBreakage

    name = t.plain("file", kind=str)
    kind = t.plain("matrix", kind=str)
    t.finish("form, file, matrix (\"b\" or \"B\")")
    if kind not in ("b", "B"):
        raise InputError(f"{t.where}.matrix = {kind!r}: expected \"b\" (fractional, eq. 2) or \"B\" (cumulative)")
    p = _named_file(name, base)
    if not p.is_file():
        raise InputError(f"{t.where}.file: {p} not found")
    try:
        M = np.loadtxt(p, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise InputError(f"{p}: not a CSV matrix of numbers ({exc})") from None
    if M.shape[0] != M.shape[1]:
        raise InputError(f"{p}: a {M.shape[0]} x {M.shape[1]} matrix; expected square (N x N)")
    if grid is not None and M.shape[0] != grid.n:
        raise InputError(f"{p}: a {M.shape[0]} x {M.shape[0]} matrix but the grid has {grid.n} classes; give the "
                         "matrix on the flowsheet's grid")
    return _wrap(str(p), TabulatedBreakage, **{kind: M})


def _breakage(t: _Table, base: Path | None = None, grid: SizeGrid | None = None):
    form = t.plain("form", kind=str)
    if form == "table":
        return _breakage_table(t, base, grid)
    if form == "normalized":
        args = [t.plain(k, kind=float) for k in ("phi", "gamma", "beta")]
        t.finish("form, phi, gamma, beta")
        return _wrap(t.where, NormalizedBreakage, *args)
    if form == "non_normalized":
        args = [t.plain(k, kind=float) for k in ("phi0", "gamma", "beta", "theta")]
        xmax = t.quantity("x_max", "length", None)
        t.finish("form, phi0, gamma, beta, theta, x_max_um")
        return _wrap(t.where, NonNormalizedBreakage, *args, xmax)
    raise InputError(f"{t.where}.form = {form!r}: unknown breakage form; valid: non_normalized, normalized, table")


# --------------------------------------------------------------- curves
_SIZE_PARAMS = {"d50", "d50c"}


def _curve_params(t: _Table, curve: str, skip=()) -> dict:
    if curve not in CURVES:
        raise InputError(f"{t.where}.curve = {curve!r}: unknown efficiency curve; valid: {', '.join(sorted(CURVES))}")
    sig = inspect.signature(CURVES[curve])
    params = {}
    for name, p in list(sig.parameters.items())[1:]:
        required = p.default is inspect.Parameter.empty
        if name in _SIZE_PARAMS:
            params[name] = t.quantity(name, "length", ... if required else None)
        else:
            v = t.plain(name, ... if required else None, kind=float)
            if v is not None and v < 0:
                raise InputError(f"{t.where}.{name} = {v!r}: expected a value >= 0")
            if v is not None:
                params[name] = v
        if params.get(name, 0) is None:
            params.pop(name)
    names = ", ".join(("curve",) + tuple(skip) + tuple(
        f"{n}_um" if n in _SIZE_PARAMS else n for n in list(sig.parameters)[1:]))
    t.finish(names)
    _wrap(t.where, CURVES[curve], np.array([1e-3, 1e-4]), **params)  # validate once
    return params


# --------------------------------------------------------------- units
def _kinetics(t: _Table) -> dict:
    """A mill's [kinetics] table: aggregation, population-dependent rates, slowing-down by the fines.

    aggregation = "constant" (sum, product, shear) with aggregation_beta0_per_s = ... (per time)
    or aggregation_beta0_E_t_per_kWh = ... (per energy: beta0 = beta0^E P / H, with the mill's
    power), x_ref_um = ... (the kernel's reference size); cushion_lambda = -1.0 with
    fines_um = ... and cushion_w = 1.0 (S_i (1 + w F)^lambda); kappa_fines = "hyperbolic"
    ("exponential") with kappa_s = ... and fines_um (S_i kappa(F)).
    """
    from millflow.flowsheet.units import KAPPA_FINES
    from millflow.nonlinear import KERNELS

    out = {}
    kern = t.plain("aggregation", None, kind=str)
    if kern is not None:
        if kern not in KERNELS:
            raise InputError(f"{t.where}.aggregation = {kern!r}: unknown kernel; valid: {', '.join(sorted(KERNELS))}")
        out["aggregation_kernel"] = kern
        if any(k.startswith("aggregation_beta0_E_") for k in t.data):
            if any(k.startswith("aggregation_beta0_") and not k.startswith("aggregation_beta0_E_") for k in t.data):
                raise InputError(f"{t.where}: aggregation_beta0 given per time and per energy; keep one "
                                 "(aggregation_beta0_<unit> per time, or aggregation_beta0_E_<unit> per energy)")
            out["aggregation_beta0_E"] = t.quantity("aggregation_beta0_E", "energy_rate", allow_zero=True)
        else:
            out["aggregation_beta0"] = t.quantity("aggregation_beta0", "rate", allow_zero=True)
        out["x_ref_m"] = t.quantity("x_ref", "length")
    lam = t.plain("cushion_lambda", None, kind=float)
    if lam is not None:
        out["cushion_lambda"] = lam
        w = t.plain("cushion_w", 1.0, kind=float)
        if not (math.isfinite(w) and w > 0):
            raise InputError(f"{t.where}.cushion_w = {w!r}: expected an interaction strength > 0")
        out["cushion_w"] = w
    slow = t.plain("kappa_fines", None, kind=str)
    if slow is not None:
        if slow not in KAPPA_FINES:
            raise InputError(f"{t.where}.kappa_fines = {slow!r}: unknown form; valid: {', '.join(KAPPA_FINES)}")
        s = t.plain("kappa_s", kind=float)
        if not (math.isfinite(s) and s >= 0):
            raise InputError(f"{t.where}.kappa_s = {s!r}: expected a slowing-down strength >= 0")
        out["kappa_fines"], out["kappa_s"] = slow, s
    if lam is not None or slow is not None:
        out["fines_m"] = t.quantity("fines", "length")
    t.finish("aggregation, aggregation_beta0_per_s (or aggregation_beta0_E_t_per_kWh), x_ref_um, cushion_lambda, "
             "cushion_w, kappa_fines, kappa_s, fines_um")
    if not out:
        raise InputError(f"{t.where}: empty; give aggregation (with aggregation_beta0_<unit>, x_ref_<unit>), "
                         "cushion_lambda (with fines_<unit>) and/or kappa_fines (with kappa_s, fines_<unit>)")
    return out


def _fitted_material(m: _Table, base: Path | None) -> dict:
    """A material's rate and breakage from a ``millflow fit --json`` result: the estimate (eqs. 5-7),
    A at the process values the flowsheet states (eq. 10, keys as the fit's process columns)."""
    from millflow.scaleup.fitted import load_fit

    name = m.plain("fit", kind=str)
    process = m.plain("process", {})
    if not isinstance(process, dict):
        raise InputError(f"{m.where}.process = {process!r}: expected a table of the fit's process values")
    m.finish("fit, process, per_energy")
    p = _named_file(name, base, folder_file="fit.json")
    if not p.is_file():
        raise InputError(f"{m.where}.fit: {p} not found")
    fitted = load_fit(p)
    cols = fitted.spec.get("rate_process", [])
    extra = sorted(set(process) - set(cols))
    if extra:
        raise InputError(f"{m.where}.process.{extra[0]}: not a process variable of the fit (its eq. 10 uses "
                         f"{cols or 'none'})")
    for k, v in process.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise InputError(f"{m.where}.process.{k} = {v!r}: expected a number")
    proc = fitted.check_process(process, f"{m.where}.process")
    # the fit's own translator decodes its vector (millflow.scaleup.fitted: FittedRate, FittedDistribution)
    return {"rate": fitted.rate_model(process=proc), "breakage": fitted.distribution_model()}


def _transport_table(tr: _Table, extra: tuple = ()) -> tuple[str, dict]:
    """(canonical model name, parameters) of a transport table (rtd.names: names and aliases)."""
    raw = tr.plain("model", kind=str)
    try:
        model = rtd_names.canonical_name(raw)
    except ValueError:
        raise InputError(f"{tr.where}.model = {raw!r}: unknown transport model; valid: "
                         f"{', '.join(sorted(TRANSPORTS))}, series (aliases: {', '.join(rtd_names.ALIASES)})") from None
    entry = rtd_names.TRANSPORTS[model]
    tparams = {}
    for k in entry.required:
        tparams[k] = tr.plain(k, kind=float)
        if tparams[k] <= 0:
            raise InputError(f"{tr.where}.{k} = {tparams[k]!r}: expected > 0")
    for k in entry.optional:
        if k in tr.data:
            tparams[k] = tr.plain(k, kind=float)
    keys = ["model", *entry.required, *entry.optional, *extra]
    if model == "axial_dispersion_open":  # where the discharge is taken (millflow.mill.axial_open)
        from millflow.mill.axial_open import DISCHARGES

        discharge = tr.plain("discharge", None, kind=str)
        if discharge is not None:
            if discharge not in DISCHARGES:
                raise InputError(f"{tr.where}.discharge = {discharge!r}: expected one of "
                                 f"{', '.join(map(repr, DISCHARGES))}")
            tparams["discharge"] = discharge
        keys.append("discharge")
    for k in extra:
        tr.used.add(k)
    tr.finish(", ".join(keys))
    return model, tparams


def _transport_part(data, where: str) -> tuple:
    """(model, parameters, tau_fraction) of one part of a series transport."""
    t = _Table(data, where)
    frac = t.plain("tau_fraction", kind=float)
    if not 0.0 < frac <= 1.0:
        raise InputError(f"{where}.tau_fraction = {frac!r}: expected a fraction in (0, 1]")
    if t.data.get("model") == "series":
        raise InputError(f"{where}.model: a series inside a series; list its parts in the outer one")
    model, params = _transport_table(t, extra=("tau_fraction",))
    if "discharge" in params:
        raise InputError(f"{where}.discharge: a part of a series has the open density's (sampled) discharge; "
                         "a flux discharge needs the open vessel as the whole mill")
    return model, params, frac


def _rtd_fit(tr: _Table, base: Path | None, classified: bool, kinetic: bool = False):
    """Transport from a ``millflow fit-rtd --json`` result (or its --out folder's fit.json):
    the model and its shape parameters, and tau converted from the fit's time unit to s.
    A tanks-in-series fit with real n and discharge classification (which needs whole
    cells) or non-linear kinetics (solved tank by tank) uses the nearest whole n, said in
    the mill's method."""

    name = tr.plain("rtd_fit", kind=str)
    tr.finish("rtd_fit (a 'millflow fit-rtd --json' result; nothing else with it)")
    p = _named_file(name, base, folder_file="fit.json")
    if not p.is_file():
        raise InputError(f"{tr.where}.rtd_fit: {p} not found")
    d = read_json(p, "fit-rtd result")
    if not isinstance(d, dict) or not isinstance(d.get("params"), dict) or "model" not in d:
        raise InputError(f"{p}: not a 'millflow fit-rtd --json' result (needs 'model' and 'params')")
    try:
        model = rtd_names.canonical_name(d["model"])
    except (ValueError, TypeError):
        raise InputError(f"{p}: model = {d['model']!r}: not a transport model; valid: "
                         f"{', '.join(sorted(TRANSPORTS))}") from None
    unit = d.get("time_unit")
    if not isinstance(unit, str) or unit not in UNITS["time"]:
        raise InputError(f"{p}: time_unit = {unit!r}; expected one of {', '.join(UNITS['time'])} (a fitted tau "
                         "without its unit cannot be used)")
    values = {}
    for k, v in d["params"].items():
        val = v.get("value") if isinstance(v, dict) else None
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise InputError(f"{p}: params.{k}.value = {val!r}; expected a finite number")
        values[k] = float(val)
    if "tau" not in values or not values["tau"] > 0:
        raise InputError(f"{p}: params.tau missing or not > 0")
    entry = rtd_names.TRANSPORTS[model]
    params = {k: values[k] for k in entry.required + entry.optional if k in values}
    missing = [k for k in entry.required if k not in params]
    if missing:
        raise InputError(f"{p}: params {missing} missing for model {model!r}")
    note = f"transport from {p.name} ({model}, fitted in {unit})"
    if model == "tanks_in_series" and (classified or kinetic) and params["n"] != round(params["n"]):
        whole = max(1, round(params["n"]))
        why = ("discharge classification needs whole cells" if classified
               else "non-linear kinetics are solved tank by tank")
        note += f"; fitted n = {params['n']:.4g} in {p.name} -> {whole} tanks (nearest whole n: {why})"
        params["n"] = float(whole)
    return model, params, values["tau"] * UNITS["time"][unit], note


def _mill(name: str, t: _Table, materials: dict, slurry=None, base: Path | None = None,
          grid: SizeGrid | None = None) -> MillUnit:
    """A mill table: breakage from its material (or its own), transport, tau or hold-up."""
    mat_name = t.plain("material", None, kind=str)
    mat = {}
    if mat_name is not None:
        if mat_name not in materials:
            raise InputError(f"units.{name}.material = {mat_name!r}: unknown material; defined: "
                             f"{', '.join(materials) or 'none (add a [materials.NAME] table)'}")
        mat = materials[mat_name]
    rate = _rate(t.sub("rate")) if "rate" in t.data else mat.get("rate")
    brk = _breakage(t.sub("breakage"), base, grid) if "breakage" in t.data else mat.get("breakage")
    if rate is None or brk is None:
        missing = "rate" if rate is None else "breakage"
        raise InputError(f"units.{name}: missing parameter {missing!r} (give it in the mill or in its material)")
    tr = t.sub("transport", None)
    model, tparams = "perfect_mixing", {}
    fitted_tau, rtd_note = None, None
    if tr is not None and "rtd_fit" in tr.data:
        model, tparams, fitted_tau, rtd_note = _rtd_fit(tr, base, "classification" in t.data, "kinetics" in t.data)
    elif tr is not None and tr.data.get("model") == "series":
        tr.plain("model")
        parts = tr.plain("parts")
        tr.finish("model = \"series\", parts = [{model = ..., tau_fraction = ..., ...}, ...]")
        if not isinstance(parts, list) or len(parts) < 2:
            raise InputError(f"{tr.where}.parts: expected a list of at least two transport tables")
        model, tparams = "series", {"parts": [_transport_part(p, f"{tr.where}.parts[{k}]")
                                              for k, p in enumerate(parts)]}
        total = math.fsum(p[2] for p in tparams["parts"])
        if abs(total - 1.0) > 1e-12:
            raise InputError(f"{tr.where}.parts: tau_fraction values sum to {total:.12g}; expected 1 (each part's "
                             "share of the mill's mean residence time)")
    elif tr is not None:
        model, tparams = _transport_table(tr)
    design = None
    from millflow.scaleup.flowsheet import ScaledRate, design_from_table, is_design
    if is_design(t.data):  # a mill by dimensions and operation: hold-up, power (and rate) computed
        design = design_from_table(f"units.{name}", t.data, slurry)
        t.used.update(design["keys"])
        if design["rate_factor"] != 1.0:
            if getattr(rate, "basis", "time") == "energy":
                raise InputError(f"units.{name}.lab: the rate is per energy (S = S^E P/H in every mill); "
                                 "a lab table scales rates per time only: remove one")
            rate = ScaledRate(rate, design["rate_factor"])
    tau = _plausible(t, "tau", "time", t.quantity("tau", "time", None))
    holdup = _plausible(t, "holdup", "mass", t.quantity("holdup", "mass", None))
    slurry_volume = _plausible(t, "slurry_volume", "volume", t.quantity("slurry_volume", "volume", None))
    if fitted_tau is not None and tau is None and holdup is None and slurry_volume is None and design is None:
        tau = fitted_tau  # the tracer fit's tau, converted from its time unit
        rtd_note += f"; tau = {tau / 60:.6g} min from the fit"
    elif fitted_tau is not None:
        rtd_note += "; shape only (tau from this mill's tau, hold-up or dimensions)"
    filling = t.plain("slurry_filling", None, kind=float)
    if filling is not None:
        if design is None:
            raise InputError(f"units.{name}.slurry_filling: needs the mill's dimensions (diameter_m, length_m, ...); "
                             "or give slurry_volume_m3")
        if not 0.0 < filling < 1.0:
            raise InputError(f"units.{name}.slurry_filling = {filling!r}: expected the fraction of the mill volume "
                             "held as slurry, in (0, 1)")
        if slurry_volume is not None:
            raise InputError(f"units.{name}: give one of slurry_filling or slurry_volume_m3")
        slurry_volume = filling * design["design"].volume_m3
    if slurry_volume is not None and slurry is None:
        raise InputError(f"units.{name}: a mill given by its slurry hold-up needs the solids density; add "
                         "[slurry] solids_density_t_m3 = ...")
    if design is not None and tau is None and holdup is None and slurry_volume is None:
        holdup = design["holdup_kg"]
    if tau is None and holdup is None and slurry_volume is None:
        raise InputError(f"units.{name}: missing parameter tau_<unit> (time: {_suffixes('time')}), "
                         f"holdup_<unit> (mass: {_suffixes('mass')}) or slurry_volume_<unit> "
                         f"(volume: {_suffixes('volume')})")
    # (power_model of a mill by dimensions is not a power with an unknown unit)
    given = design is None or any(k.startswith("power_") and k != "power_model" for k in t.data)
    power = _plausible(t, "power", "power", t.quantity("power", "power", None, allow_zero=True)) if given else None
    if design is not None and power is None:
        power = design["power_W"]
    cls = None
    if "classification" in t.data:
        ct = t.sub("classification")
        curve = ct.plain("curve", kind=str)
        where = ct.plain("where", None)
        if where is not None and not (isinstance(where, str) or (isinstance(where, list) and where and all(
                isinstance(k, int) and not isinstance(k, bool) and k >= 1 for k in where))):
            raise InputError(f"{ct.where}.where = {where!r}: expected \"discharge\", \"cells\", \"axis\" or a "
                             "list of cell numbers (1 = first, at least one)")
        cls = {"curve": curve, **_curve_params(ct, curve, skip=("where",))}
        if where is not None:
            cls["where"] = where
    kin = _kinetics(t.sub("kinetics")) if "kinetics" in t.data else None
    t.finish("type, material, rate, breakage, transport, tau_min, holdup_t, slurry_volume_m3, power_kW, "
             "classification, kinetics, add_water_tph, or by dimensions: diameter_m, length_m, ball_filling, "
             "critical_speed_fraction, ball_size_mm, slurry_filling, ... "
             "(docs/scaleup.md)")
    unit = _wrap(f"units.{name}", MillUnit, name, rate, brk, model, tparams, tau, holdup, cls, power, kin,
                 slurry_volume, slurry, rtd_note)
    _wrap(f"units.{name}", build_transport, model, tau or 1.0, tparams)
    return unit


_CYCLONE_SIZES = (("diameter", True), ("inlet_diameter", True), ("vortex_finder", True), ("apex", True),
                  ("free_vortex_height", True), ("cylinder_length", False))
#: No hydrocyclone dimension is below 1 mm (the smallest cyclones are ~10 mm across).
CYCLONE_MIN_SIZE_M = 1e-3
_CALIBRATION = {"plitt": ("F1", "F2", "F3", "F4", "density_exponent"),
                "nageswararao": ("K_D0", "K_Q0", "K_V1", "K_W1", "alpha")}


def _predicted_cyclone(name: str, t: _Table, slurry):
    """A hydrocyclone cluster predicted by Plitt's or Nageswararao's model (millflow.cyclones)."""
    from millflow.cyclones import CycloneGeometry, NageswararaoConstants, PlittCalibration
    from millflow.flowsheet.cyclone import CYCLONE_MODELS, PredictedCyclone

    model = t.plain("model", kind=str)
    if model not in CYCLONE_MODELS:
        raise InputError(f"units.{name}.model = {model!r}: unknown hydrocyclone model; valid: "
                         f"{', '.join(CYCLONE_MODELS)} (or a fixed curve: curve = \"plitt\" with d50c_um, m, bypass)")
    sizes = {f"{k}_m": t.quantity(k, "length", ... if required else None) for k, required in _CYCLONE_SIZES}
    for k, _ in _CYCLONE_SIZES:
        if sizes[f"{k}_m"] is not None and sizes[f"{k}_m"] < CYCLONE_MIN_SIZE_M:
            key = _user_key(t, k, "length")
            raise InputError(f"{t._at(key)} = {t.data[key]!r}: a hydrocyclone dimension below 1 mm is implausible "
                             "(industrial cyclones are 10..2500 mm across); a unit slip (m for mm)?")
    angle = t.plain("cone_angle_deg", None, kind=float)
    count = t.plain("cyclones", 1, kind=float)
    if count != int(count) or count < 1:
        raise InputError(f"units.{name}.cyclones = {count!r}: expected a whole number >= 1 (cyclones in the cluster)")
    viscosity = t.quantity("viscosity", "viscosity", 1.0e-3)
    cal = {k: t.plain(k, kind=float) for k in _CALIBRATION[model] if k in t.data}
    t.finish("type, model, cyclones, diameter_mm, inlet_diameter_mm, vortex_finder_mm, apex_mm, "
             "free_vortex_height_mm, cylinder_length_mm, cone_angle_deg, viscosity_mPa_s, add_water_tph, "
             + ", ".join(_CALIBRATION[model]))
    if slurry is not None and slurry.solids_density <= slurry.water_density:
        raise InputError(f"units.{name}: a hydrocyclone separates solids denser than the liquid; [slurry] gives "
                         f"solids {slurry.solids_density / 1e3:g} t/m3, water {slurry.water_density / 1e3:g} t/m3")
    geometry = _wrap(f"units.{name}", CycloneGeometry, **{k: v for k, v in sizes.items() if v is not None},
                     cone_angle_deg=angle)
    calibration = _wrap(f"units.{name}", PlittCalibration if model == "plitt" else NageswararaoConstants, **cal)
    return _wrap(f"units.{name}", PredictedCyclone, name, model, geometry, int(count), slurry, calibration,
                 viscosity)


#: Below this % solids a ``..._pct`` key is most likely a fraction written as percent
#: (0.96 meant 96 %): real mill and classifier slurries carry a few % solids at least.
PLAUSIBLE_MIN_PCT_SOLIDS = 2.0


def _warn_pct_slip(t: _Table, base: str) -> None:
    """One-line warning at a % solids key whose value looks like a fraction (unit slip)."""
    v = t.data.get(f"{base}_pct")
    if isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < PLAUSIBLE_MIN_PCT_SOLIDS:
        _warn_once(f"{t.where}.{base}_pct = {v!r}: {v:g} % solids by mass is implausibly dilute; if a fraction "
                   f"was meant write {base}_pct = {v * 100:g} (or {base}_frac = {v!r})")


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


def _classifier_water(t: _Table) -> dict | None:
    """Where a classifier's feed water goes: water_to_coarse (R_f) or coarse_solids_content_pct."""
    split = t.plain("water_to_coarse", None, kind=float)
    content = t.quantity("coarse_solids_content", "fraction", None)
    _warn_pct_slip(t, "coarse_solids_content")
    if split is not None and content is not None:
        raise InputError(f"{t.where}: give one of water_to_coarse or coarse_solids_content_pct, not both")
    if split is not None:
        if not 0.0 <= split < 1.0:
            raise InputError(f"{t.where}.water_to_coarse = {split!r}: expected a fraction in [0, 1)")
        return {"to_coarse": split}
    if content is not None:
        if not content < 1.0:
            raise InputError(f"{t.where}.coarse_solids_content: {content * 100:.6g} % solids; expected a value in "
                             "(0, 100) %")
        return {"coarse_solids_content": content}
    return None


def _unit(name: str, t: _Table, grid: SizeGrid, materials: dict, slurry=None, base: Path | None = None):
    utype = t.plain("type", kind=str)
    if utype not in UNIT_TYPES:
        raise InputError(f"units.{name}.type = {utype!r}: unknown unit type; valid: {', '.join(sorted(UNIT_TYPES))}")
    if utype == "feed":
        solids = _plausible(t, "solids", "mass_flow", t.quantity("solids", "mass_flow"))
        psd = _feed_psd(t.sub("psd"), grid, base)
        t.plain("material", None)
        water = _feed_water(t, solids)
        t.finish("type, solids_tph, psd, material, water_tph or solids_content_pct")
        return Feed(name, solids, psd, water)
    if utype == "mill":
        return _mill(name, t, materials, slurry, base, grid)
    if utype in ("hydrocyclone", "screen", "air_separator", "dynamic_classifier"):
        kind = "air_separator" if utype == "dynamic_classifier" else utype
        default = {"hydrocyclone": None, "screen": "screen", "air_separator": "tromp"}[kind]
        if kind == "hydrocyclone" and "model" in t.data:
            return _predicted_cyclone(name, t, slurry)
        curve = t.plain("curve", default, kind=str)
        if curve is None:
            raise InputError(f"units.{name}: missing parameter 'curve' (whiten or plitt for a hydrocyclone), or "
                             "model = \"plitt\" or \"nageswararao\" with the cyclone's dimensions")
        water = _classifier_water(t)
        return Classifier(name, kind, curve, _curve_params(t, curve, skip=("type", "water_to_coarse",
                                                                             "coarse_solids_content_pct",
                                                                             "add_water_tph")), water)
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
    materials = {}
    mt = top.sub("materials", None)
    if mt is not None:
        for mname in mt.data:
            m = mt.sub(mname)
            per_energy = m.sub("per_energy", None)
            if "fit" in m.data:
                materials[mname] = _fitted_material(m, base)
                if per_energy is not None:
                    materials[mname]["rate"] = _per_energy(per_energy, materials[mname]["rate"])
                continue
            materials[mname] = {}
            if "rate" in m.data:
                materials[mname]["rate"] = _rate(m.sub("rate"))
            if "breakage" in m.data:
                materials[mname]["breakage"] = _breakage(m.sub("breakage"), base, grid)
            if per_energy is not None:
                materials[mname]["rate"] = _per_energy(per_energy, materials[mname].get("rate"))
            m.finish("rate, breakage, per_energy (or fit = \"fit.json\" with process = {...})")
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
    """(unit, water added to its feed [kg/s] or None) built from its ``table`` (as in the
    document) on the grid, materials and slurry of ``fs``. A mill whose rate and breakage
    come out the very objects of the mill of that name in ``fs`` keeps its class-averaged
    forms on the grid: they depend on neither tau, power nor transport."""
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
    """``fs`` with the units named in ``tables`` (unit name -> its table, as in the document)
    built again from those tables (:func:`unit_from_table`); grid, materials, streams and
    the other units are the very objects of ``fs`` (a sweep's case that changes keys of
    some units). ``built`` (name -> (unit, water added)) gives units built already."""
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
    """Flowsheet from TOML text."""
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
    """Flowsheet from a TOML file."""
    import hashlib

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: flowsheet file not found")
    fs = loads(read_text(p, "flowsheet file"), source=str(p))
    fs.meta["input_sha256"] = hashlib.sha256(p.read_bytes()).hexdigest()  # once, not per summary
    return fs
