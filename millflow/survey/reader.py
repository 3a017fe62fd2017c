"""Reading a survey file (TOML): measurements per stream on a flowsheet's topology.

A survey names a flowsheet file (``flowsheet = "circuit.toml"``, read by
:func:`millflow.flowsheet.load`) and gives, per stream named as that file names it,
any of: solids flow (``solids_tph``), water (``water_tph``) or % solids by mass
(``solids_content_pct``), and a sieve analysis (``psd``: inline ``size_um`` with
``passing_pct`` or ``retained_pct``, or ``file = "x.csv"`` with the columns of a feed
CSV: docs/flowsheets.md). Every value has a standard deviation: given beside it
(``solids_sd_tph``, ``water_sd_tph``, ``solids_content_sd_pct``; 0 means exact) or
from the error model stated once in ``[errors]``:

- flows: SD = relative SD x value (``solids_rel_sd_pct``, ``water_rel_sd_pct``);
- % solids: an absolute SD (``solids_content_sd_pct``, in percentage points);
- the mass fraction p of a sieve class: SD = psd_sd x 2 sqrt(p (1 - p)) + psd_floor
  (``psd_sd_pct`` is the SD at p = 50 %, ``psd_floor_pct`` the floor; a stream may
  override both). The sqrt(p(1-p)) growth is that of a sampling (multinomial) error.

Water added at units (``[water_additions.<unit>] water_tph``, with ``water_sd_tph``)
is measured where given and unknown elsewhere. Units of measure are part of every key
(:func:`millflow.inputs.quantity`). Every error is one line naming the key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from millflow.errors import InputError, MillflowError
from millflow.inputs import check_keys, quantity, read_toml, unit_keys

__all__ = ["ErrorModel", "PSDMeasurement", "StreamMeasurement", "Survey", "read_survey", "survey_from_dict",
           "class_fractions"]


@dataclass(frozen=True)
class ErrorModel:
    """The error model stated once for a survey (all fractions [-]).

    solids_rel, water_rel : relative SD of solids and water flows.
    solids_content_sd : absolute SD of the solids mass fraction of a slurry.
    psd_sd, psd_floor : SD of a class mass fraction p is ``psd_sd * 2 sqrt(p(1-p)) + psd_floor``.
    """

    solids_rel: float = 0.05
    water_rel: float = 0.05
    solids_content_sd: float = 0.01
    psd_sd: float = 0.01
    psd_floor: float = 0.001

    def __post_init__(self):
        for k in ("solids_rel", "water_rel", "solids_content_sd", "psd_sd", "psd_floor"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"errors.{k} = {v!r}: expected a finite value >= 0")
        if self.psd_sd == 0 and self.psd_floor == 0:
            raise InputError("errors: psd_sd and psd_floor are both 0; sieve fractions are never exact")

    def fraction_sd(self, p, psd_sd=None, psd_floor=None) -> np.ndarray:
        """SD of class mass fractions ``p`` [-] (p clipped to [0, 1] inside the square root)."""
        q = np.clip(np.asarray(p, float), 0.0, 1.0)
        a = self.psd_sd if psd_sd is None else psd_sd
        f = self.psd_floor if psd_floor is None else psd_floor
        return a * 2.0 * np.sqrt(q * (1.0 - q)) + f


@dataclass(frozen=True)
class PSDMeasurement:
    """A sieve analysis with the SD of each class mass fraction.

    A sieve analysis: sieve sizes [m] (descending) and cumulative passing [-] at each,
    with the SD of each class mass fraction (classes: above the coarsest sieve, between
    sieves, the pan; ``len(sizes) + 1``).
    """

    sizes: np.ndarray
    passing: np.ndarray
    sd: np.ndarray
    sd_rule: tuple | None = None    # (psd_sd, psd_floor) of the error model; None: SDs given

    @property
    def fractions(self) -> np.ndarray:
        """Class mass fractions (above the top sieve, between sieves, pan)."""
        return class_fractions(self.passing)


def class_fractions(passing) -> np.ndarray:
    """Class mass fractions (above the top sieve, between sieves, pan) from cumulative passing."""
    p = np.asarray(passing, float)
    return -np.diff(np.concatenate([[1.0], p, [0.0]]))


@dataclass(frozen=True)
class StreamMeasurement:
    """What was measured on one stream (SI: kg/s, fractions); None where not measured."""

    name: str
    solids: float | None = None
    solids_sd: float | None = None
    water: float | None = None
    water_sd: float | None = None
    solids_content: float | None = None
    solids_content_sd: float | None = None
    psd: PSDMeasurement | None = None
    solids_rel: float | None = None     # relative SD of the error model (None: the SD is given)
    water_rel: float | None = None


@dataclass(frozen=True, eq=False)
class Survey:
    """A survey: the flowsheet, measurements per stream, water additions and error model.

    A survey: the flowsheet it samples, measurements per stream, water additions
    (unit -> (value [kg/s] or None, SD)), the error model and where it came from.
    """

    flowsheet: object
    streams: dict
    water_additions: dict = field(default_factory=dict)
    errors: ErrorModel = field(default_factory=ErrorModel)
    title: str = ""
    source: str = "<survey>"
    fit: dict | None = None     # the [fit] table (millflow.survey.fit.read_fit_table), if any

    @property
    def wet(self) -> bool:
        """True when any water quantity is measured (the water balance is then reconciled)."""
        return any(m.water is not None or m.solids_content is not None for m in self.streams.values()) or any(
            v is not None for v, _ in self.water_additions.values())


# ---------------------------------------------------------------------- reading
def _sieves_inline(t: dict, where: str):
    size = np.atleast_1d(quantity(t, "size", "length", where, array=True, allow_zero=True))
    has_p = any(k in t for k in unit_keys("passing", "fraction"))
    has_r = any(k in t for k in unit_keys("retained", "fraction"))
    if has_p == has_r:
        raise InputError(f"{where}: give one of passing_pct or retained_pct (or _frac) with size_um")
    if has_p:
        passing = np.atleast_1d(quantity(t, "passing", "fraction", where, array=True, allow_zero=True))
        if size.shape != passing.shape:
            raise InputError(f"{where}: {size.size} sizes but {passing.size} passing values")
        if np.any(size <= 0):
            raise InputError(f"{where}.size: sizes must be > 0 for cumulative passing")
        return size, passing
    ret = np.atleast_1d(quantity(t, "retained", "fraction", where, array=True, allow_zero=True))
    if size.shape != ret.shape:
        raise InputError(f"{where}: {size.size} sizes but {ret.size} retained values")
    total = math.fsum(ret)
    if abs(total - 1.0) > 1e-6:
        raise InputError(f"{where}.retained: sums to {100 * total:.6g} %; expected 100 % (every sieve and the "
                         "pan, size 0; millflow does not renormalise measured data)")
    order = np.argsort(-size)
    size, ret = size[order], ret[order]
    passing = np.where(np.abs(1.0 - np.cumsum(ret)) <= 1e-6, 0.0, 1.0 - np.cumsum(ret))
    keep = size > 0
    return size[keep], passing[keep]


def _psd(t, where: str, base: Path, errors: ErrorModel, sd_over: tuple) -> PSDMeasurement:
    from millflow.flowsheet.io import _named_file, _sieve_table

    if not isinstance(t, dict):
        raise InputError(f"{where}: expected a table {{size_um = [...], passing_pct = [...]}} or {{file = ...}}")
    if "file" in t:
        check_keys(t, {"file"}, where)
        if not isinstance(t["file"], str):
            raise InputError(f"{where}.file = {t['file']!r}: expected a file name")
        size, passing = _sieve_table(_named_file(t["file"], base), where)
    else:
        check_keys(t, unit_keys("size", "length") | unit_keys("passing", "fraction")
                   | unit_keys("retained", "fraction"), where)
        size, passing = _sieves_inline(t, where)
    if size.size < 1:
        raise InputError(f"{where}: no sieve sizes")
    order = np.argsort(-size)
    size, passing = size[order], passing[order]
    if np.any(np.diff(size) >= -1e-9 * size[:-1]):
        k = int(np.flatnonzero(np.diff(size) >= -1e-9 * size[:-1])[0])
        raise InputError(f"{where}: sieve {size[k] * 1e6:.6g} um appears twice")
    if np.any(passing > 1 + 1e-9) or np.any(passing < 0):
        raise InputError(f"{where}: passing must lie in [0, 100] %")
    if np.any(np.diff(passing) > 1e-9):
        k = int(np.flatnonzero(np.diff(passing) > 1e-9)[0])
        raise InputError(f"{where}: passing rises from {100 * passing[k]:.6g} % at {size[k] * 1e6:.6g} um to "
                         f"{100 * passing[k + 1]:.6g} % at the finer {size[k + 1] * 1e6:.6g} um; expected it to "
                         "fall with size")
    passing = np.minimum(passing, 1.0)
    a = errors.psd_sd if sd_over[0] is None else sd_over[0]
    floor = errors.psd_floor if sd_over[1] is None else sd_over[1]
    if a == 0 and floor == 0:
        raise InputError(f"{where}: psd_sd and psd_floor are both 0; sieve fractions are never exact")
    return PSDMeasurement(size, passing, errors.fraction_sd(class_fractions(passing), a, floor), (a, floor))


def _stream(name: str, t, errors: ErrorModel, base: Path) -> StreamMeasurement:
    where = f"streams.{name}"
    if not isinstance(t, dict):
        raise InputError(f"{where}: expected a table of measurements")
    allowed = {"psd", "psd_sd_pct", "psd_sd_frac", "psd_floor_pct", "psd_floor_frac"}
    for base_key, dim in (("solids", "mass_flow"), ("solids_sd", "mass_flow"), ("water", "mass_flow"),
                          ("water_sd", "mass_flow"), ("solids_content", "fraction"),
                          ("solids_content_sd", "fraction")):
        allowed |= unit_keys(base_key, dim)
    check_keys(t, allowed, where)
    solids = quantity(_only(t, "solids", "mass_flow"), "solids", "mass_flow", where, None, allow_zero=True)
    water = quantity(_only(t, "water", "mass_flow"), "water", "mass_flow", where, None, allow_zero=True)
    content = quantity(t, "solids_content", "fraction", where, None)
    if water is not None and content is not None:
        raise InputError(f"{where}: give one of water_tph or solids_content_pct, not both")
    if content is not None and content > 1:
        raise InputError(f"{where}.solids_content: {100 * content:.6g} %; expected a value in (0, 100] %")

    def sd_of(key, value, default):
        sd = quantity(t, key, "mass_flow" if key != "solids_content_sd" else "fraction", where, None,
                      allow_zero=True)
        if sd is not None and value is None:
            raise InputError(f"{where}: {key}_<unit> is given but the value it belongs to is not")
        return None if value is None else (default if sd is None else sd)

    psd_sd = quantity(t, "psd_sd", "fraction", where, None, allow_zero=True)
    psd_floor = quantity(t, "psd_floor", "fraction", where, None, allow_zero=True)
    psd = _psd(t["psd"], f"{where}.psd", base, errors, (psd_sd, psd_floor)) if "psd" in t else None
    m = StreamMeasurement(
        name, solids, sd_of("solids_sd", solids, None if solids is None else errors.solids_rel * solids),
        water, sd_of("water_sd", water, None if water is None else errors.water_rel * water),
        content, sd_of("solids_content_sd", content, errors.solids_content_sd), psd,
        errors.solids_rel if solids is not None and not _given(t, "solids_sd") else None,
        errors.water_rel if water is not None and not _given(t, "water_sd") else None)
    if m.solids_content is not None and m.solids_content_sd == 0:
        raise InputError(f"{where}.solids_content_sd: 0; only flows may be exact (give an SD > 0)")
    return m


def _only(t: dict, base: str, dim: str) -> dict:
    """The keys of ``t`` that spell ``base``.

    The keys of ``t`` that spell ``base`` (solids_tph, not solids_content_pct or solids_sd_tph);
    check_keys has already refused every other spelling.
    """
    return {k: v for k, v in t.items() if k == base or k in unit_keys(base, dim)}


def _given(t: dict, base: str) -> bool:
    return any(k in t for k in unit_keys(base, "mass_flow"))


def _errors(t: dict) -> ErrorModel:
    where = "errors"
    allowed = set()
    for k in ("solids_rel_sd", "water_rel_sd", "solids_content_sd", "psd_sd", "psd_floor"):
        allowed |= unit_keys(k, "fraction")
    check_keys(t, allowed, where)
    d = ErrorModel()
    return ErrorModel(
        quantity(t, "solids_rel_sd", "fraction", where, d.solids_rel, allow_zero=True),
        quantity(t, "water_rel_sd", "fraction", where, d.water_rel, allow_zero=True),
        quantity(t, "solids_content_sd", "fraction", where, d.solids_content_sd, allow_zero=True),
        quantity(t, "psd_sd", "fraction", where, d.psd_sd, allow_zero=True),
        quantity(t, "psd_floor", "fraction", where, d.psd_floor, allow_zero=True))


def survey_from_dict(data: dict, *, source: str = "<dict>", base_dir=None, flowsheet=None) -> Survey:
    """A :class:`Survey` from the parsed TOML document (see the module docstring).

    ``flowsheet``: an already-loaded Flowsheet (then the document needs no ``flowsheet`` key).
    """
    from millflow.flowsheet import load
    from millflow.flowsheet.io import _named_file

    base = Path(base_dir) if base_dir is not None else (
        Path(source).resolve().parent if not source.startswith("<") else Path.cwd())
    check_keys(data, {"title", "flowsheet", "errors", "streams", "water_additions", "fit"}, "survey")
    title = data.get("title", "")
    if not isinstance(title, str):
        raise InputError(f"title = {title!r}: expected a string")
    if flowsheet is None:
        name = data.get("flowsheet")
        if not isinstance(name, str):
            raise InputError("survey: missing key 'flowsheet' (the flowsheet file whose streams were sampled)"
                             if name is None else f"flowsheet = {name!r}: expected a file name")
        try:
            flowsheet = load(_named_file(name, base))
        except MillflowError as exc:
            raise type(exc)(f"flowsheet {name}: {exc}") from exc
    errors = _errors(data.get("errors", {}) if isinstance(data.get("errors", {}), dict) else
                     _bad_table("errors", data["errors"]))
    st = data.get("streams")
    if not isinstance(st, dict) or not st:
        raise InputError("survey: missing table [streams.<name>] (the measurements, per stream of the flowsheet)")
    streams = {}
    for name, t in st.items():
        if name not in flowsheet.streams:
            raise InputError(f"streams.{name}: not a stream of the flowsheet {flowsheet.source_file or ''}; "
                             f"streams: {', '.join(flowsheet.stream_names)}")
        streams[name] = _stream(name, t, errors, base)
    additions = {u: (None, None) for u in flowsheet.water_added}
    wt = data.get("water_additions", {})
    if not isinstance(wt, dict):
        _bad_table("water_additions", wt)
    for unit, t in wt.items():
        where = f"water_additions.{unit}"
        if unit not in flowsheet.units or flowsheet.units[unit].type in ("feed", "product"):
            ok = [u for u, x in flowsheet.units.items() if x.type not in ("feed", "product")]
            raise InputError(f"{where}: not a unit that takes water; units: {', '.join(ok)}")
        if not isinstance(t, dict):
            _bad_table(where, t)
        check_keys(t, unit_keys("water", "mass_flow") | unit_keys("water_sd", "mass_flow"), where)
        v = quantity(t, "water", "mass_flow", where, None, allow_zero=True)
        sd = quantity(t, "water_sd", "mass_flow", where, None, allow_zero=True)
        if v is None and sd is not None:
            raise InputError(f"{where}: water_sd is given without water_tph")
        additions[unit] = (v, None if v is None else (errors.water_rel * v if sd is None else sd))
    fit = None
    if "fit" in data:
        from millflow.survey.fit import read_fit_table

        names, bounds, options = read_fit_table(data["fit"])
        doc = flowsheet.meta.get("document", {})
        from millflow.survey.fit import _get

        for n in names:
            _get(doc, n)  # a key the flowsheet does not hold is named now, not after the balance
        fit = {"names": names, "bounds": bounds, **options}
    return Survey(flowsheet, streams, additions, errors, title, source, fit)


def _bad_table(key, v):
    raise InputError(f"{key}: expected a table [{key}], got {v!r}")


def read_survey(path) -> Survey:
    """Read a survey file (TOML); the flowsheet it names is read relative to it."""
    p = Path(path)
    data = read_toml(p, "survey file")
    try:
        return survey_from_dict(data, source=str(p))
    except MillflowError as exc:
        raise type(exc)(f"{p}: {exc}") from exc
