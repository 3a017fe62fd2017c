"""Read a plant file (TOML) for ``millflow scaleup``: the lab mill the fit comes from, the
plant mill by dimensions and operation, its transport, an optional closing classifier and
the fresh feed. Dimensional keys carry their unit in the name and are read through
:mod:`millflow.inputs` (the one reader of unit-suffixed keys, as flowsheet and fit files):
any unit of :data:`millflow.inputs.UNITS` is accepted and converted (``diameter_m``,
``diameter_ft``, ``ball_size_in``, ``d50c_um``, ``d50c_mm``, ``feed_tph``, ``feed_kg_s``,
``top_mm``); a dimensional key without a unit, or with an unknown one, is one error line
naming the key. See docs/scaleup.md for the layout.
"""
from __future__ import annotations

import inspect
import math
from pathlib import Path

import numpy as np

from millflow.errors import GridError, InputError
from millflow.grid import SizeGrid
from millflow.inputs import UNITS, check_keys, number, quantity, read_json, read_toml, string, unit_keys
from millflow.psd import from_sieves
from millflow.scaleup.fitted import FittedBreakage
from millflow.scaleup.flowsheet import check_design_keys, read_design
from millflow.scaleup.plant import Circuit, MillDesign
from millflow.scaleup.predict import ScaleUp
from millflow.scaleup.scaling import AUSTIN_DEFAULTS
from rtd import names as _rtd_names
from rtd.base import RTDError

__all__ = ["load_plant", "read_plant"]

_TOP = {"title", "scaling", "lab", "mill", "transport", "classifier", "feed", "search", "austin", "grid"}
#: Sizes among the parameters of the efficiency curves (read with a length unit).
_SIZE_PARAMS = {"d50", "d50c"}


def _mill(table, where, src) -> MillDesign:
    if not isinstance(table, dict):
        raise InputError(f"{src}: [{where}] table missing")
    t = {k: v for k, v in table.items() if k != "process"}
    mill, used = read_design(t, f"{src}: {where}", given=True, name=f"{src}: {where}")
    check_design_keys(t, used, f"{src}: {where}", given=True)
    return mill


def _transport_entry(name, where):
    try:
        return _rtd_names.transport(name)
    except (RTDError, TypeError, ValueError) as exc:
        raise InputError(f"{where}: {exc}") from None


def _aspect_correlation(corr, entry, mill: MillDesign, src):
    """A shape parameter from a correlation the user states in L/D: value = c (L/D)^e.

    millflow ships no default: published ball-mill RTD correlations (reviewed by Austin,
    Klimpel & Luckie 1984, ch. 8; Cho & Austin, Powder Technol. 124 (2002) 112) hold for
    the mills they were measured on, so the plant file names its source."""
    where = f"{src}: transport.from_aspect_ratio"
    if not isinstance(corr, dict):
        raise InputError(f"{where}: expected a table with parameter, coefficient, exponent and source")
    check_keys(corr, {"parameter", "coefficient", "exponent", "source"}, where)
    missing = [k for k in ("parameter", "coefficient", "exponent", "source") if k not in corr]
    if missing:
        raise InputError(f"{where}: missing {missing} (value = coefficient * (L/D)^exponent, "
                         "source names where the correlation comes from)")
    name = corr["parameter"]
    if name not in entry.required + entry.optional:
        raise InputError(f"{where}.parameter = {name!r}: not a parameter of {entry.name!r}; expected one of "
                         f"{list(entry.required + entry.optional)}")
    c, e = number(corr, "coefficient", where), number(corr, "exponent", where)
    source = string(corr, "source", where)
    if not source.strip():
        raise InputError(f"{where}.source: expected the correlation's source as text")
    ratio = mill.length_m / mill.diameter_m
    return name, c * ratio ** e, f"{name} = {c:g} (L/D)^{e:g} at L/D = {ratio:.4g} ({source})"


def _shape_value(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise InputError(f"{where} = {v!r}: expected a finite number")
    return float(v)


def _rtd_fit(name, src, base: Path):
    """Shape parameters (n, pe, ...) of a ``millflow fit-rtd --json`` result; tau is the plant's."""
    if not isinstance(name, str):
        raise InputError(f"{src}: transport.rtd_fit = {name!r}: expected a file name")
    p = base / name
    if p.is_dir():
        p = p / "fit.json"
    if not p.is_file():
        raise InputError(f"{src}: transport.rtd_fit {str(p)!r}: file not found")
    d = read_json(p, "fit-rtd result")
    if not isinstance(d, dict) or "model" not in d or not isinstance(d.get("params"), dict):
        raise InputError(f"{p}: not a 'millflow fit-rtd --json' result (expected a table with 'model' and "
                         "'params': name -> {value, ...})")
    entry = _transport_entry(d["model"], f"{p}: model")
    params = {}
    for k, v in d["params"].items():
        if k == "tau":
            continue
        if not isinstance(v, dict) or "value" not in v:
            raise InputError(f"{p}: params.{k} = {v!r}: expected a table with 'value' (as 'millflow fit-rtd "
                             "--json' writes it)")
        params[k] = _shape_value(v["value"], f"{p}: params.{k}.value")
    shape = {k: params[k] for k in entry.required + entry.optional if k in params}
    missing = [k for k in entry.required if k not in shape]
    if missing:
        raise InputError(f"{p}: params {missing} missing for model {entry.name!r}")
    try:
        _rtd_names.build(entry.name, 1.0, **shape)
    except (RTDError, TypeError, ValueError) as exc:
        raise InputError(f"{p}: {exc}") from None
    return entry.name, shape, f"fit-rtd result {p.name} (shape only; tau = H/F at the plant)"


def _transport(table, src, base: Path, mill: MillDesign | None = None):
    if table is None:
        table = {"model": "tanks_in_series", "n": 3}
    if not isinstance(table, dict):
        raise InputError(f"{src}: transport: expected a table [transport]")
    t = dict(table)
    if "rtd_fit" in t:
        name = t.pop("rtd_fit")
        if t:
            raise InputError(f"{src}: [transport] with rtd_fit takes no other keys, got {sorted(t)}")
        return _rtd_fit(name, src, base)
    entry = _transport_entry(t.pop("model", None), f"{src}: transport.model")
    allowed = entry.required + entry.optional
    note = "given"
    if "from_aspect_ratio" in t:
        name, value, note = _aspect_correlation(t.pop("from_aspect_ratio"), entry, mill, src)
        if name in t:
            raise InputError(f"{src}: transport.{name} given and also computed by from_aspect_ratio: give one")
        t[name] = value
    for k, v in t.items():
        if k not in allowed:
            raise InputError(f"{src}: transport.{k}: not a parameter of {entry.name!r}; expected {list(allowed)} "
                             "(tau comes from the hold-up and the flow)")
        t[k] = _shape_value(v, f"{src}: transport.{k}")
    return entry.name, t, note


def _classifier(table, src):
    if table is None:
        return None
    where = f"{src}: classifier"
    if not isinstance(table, dict):
        raise InputError(f"{where}: expected a table [classifier]")
    from millflow.classifiers import CURVES

    curve = string(table, "curve", where) if "curve" in table else None
    if curve is None:
        raise InputError(f"{where}: needs curve (e.g. 'plitt') and its parameters")
    if curve not in CURVES:
        raise InputError(f"{where}.curve = {curve!r}: unknown efficiency curve; valid: {', '.join(sorted(CURVES))}")
    out, used = {"curve": curve}, {"curve"}
    allowed = {"curve"}
    for name, par in list(inspect.signature(CURVES[curve]).parameters.items())[1:]:
        required = par.default is inspect.Parameter.empty
        if name in _SIZE_PARAMS:
            v = quantity(table, name, "length", where, ... if required else None, used=used)
            allowed |= unit_keys(name, "length")
        else:
            v = number(table, name, where, ... if required else None, lo=0.0)
            used.add(name)
            allowed.add(name)
        if v is not None:
            out[name] = v
    for k in table:
        if k not in allowed:
            names = ", ".join(f"{n}_<length: {', '.join(UNITS['length'])}>" if n in _SIZE_PARAMS else n
                              for n in list(inspect.signature(CURVES[curve]).parameters)[1:])
            raise InputError(f"{where}.{k}: unknown key for curve {curve!r}; expected curve, {names}")
    return out


def _feed(table, grid, src):
    where = f"{src}: feed"
    if not isinstance(table, dict):
        raise InputError(f"{src}: [feed] table missing")
    F = quantity(table, "feed", "mass_flow", where)  # a key without its unit is named first
    size = np.atleast_1d(quantity(table, "size", "length", where, array=True))
    check_keys(table, unit_keys("feed", "mass_flow") | unit_keys("size", "length") | {"passing"}, where)
    if "passing" not in table:
        raise InputError(f"{where}: missing key 'passing' (cumulative passing fractions at the sizes)")
    P = table["passing"]
    if not (isinstance(P, list) and all(isinstance(e, (int, float)) and not isinstance(e, bool) for e in P)):
        raise InputError(f"{where}.passing = {P!r}: expected a list of fractions")
    P = np.asarray(P, float)
    if size.shape != P.shape:
        raise InputError(f"{where}: {size.size} sizes but {P.size} passing values")
    if np.any(P > 1) or np.any(P < 0) or not np.all(np.isfinite(P)):
        raise InputError(f"{where}.passing: expected fractions in [0, 1] (not percent), got {P.tolist()}")
    try:
        f = from_sieves(size, P, grid)
    except GridError as exc:
        raise GridError(f"{where}: {exc} (give a [grid] with top_um above the feed top size: the fitted "
                        "forms are evaluated exactly on any grid)") from None
    return f, F * 3.6


def _power_models(d: dict) -> dict:
    """Lab and plant use the same power-model family unless both state theirs: one given, the
    other takes it. Returns {"lab", "plant", "mixed"} (mixed: a stated choice, flagged)."""
    lab, plant = d.get("lab"), d.get("mill")
    if not (isinstance(lab, dict) and isinstance(plant, dict)):
        return {}
    if "power_model" in plant and "power_model" not in lab:
        lab["power_model"] = plant["power_model"]
    elif "power_model" in lab and "power_model" not in plant:
        plant["power_model"] = lab["power_model"]

    def given(t):
        return any(k.startswith("power_") and k != "power_model" for k in t)
    ml = "given" if given(lab) else lab.get("power_model", "austin")
    mp = "given" if given(plant) else plant.get("power_model", "austin")
    return {"lab": ml, "plant": mp, "mixed": ml != mp and "given" not in (ml, mp)}


def _grid(d: dict, fit: FittedBreakage, src: str) -> SizeGrid:
    g = d.get("grid")
    if g is None:
        return SizeGrid(fit.x)
    where = f"{src}: grid"
    if not isinstance(g, dict):
        raise InputError(f"{where}: expected a table [grid]")
    top = quantity(g, "top", "length", where)
    bottom = quantity(g, "bottom", "length", where, float(fit.x[-1]))
    check_keys(g, unit_keys("top", "length") | unit_keys("bottom", "length") | {"ratio"}, where)
    ratio = number(g, "ratio", where, float(fit.x[0] / fit.x[1]), lo=1.0, lo_open=True)
    try:
        return SizeGrid.between(top, bottom, ratio)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


def read_plant(path, fit: FittedBreakage, grid: SizeGrid | None = None) -> tuple[ScaleUp, dict]:
    """ScaleUp for the plant file at ``path`` and the fit, on the plant file's grid or on
    ``grid``; second value: notes (title, transport source, power models, the file's grid)."""
    path = Path(path)
    src = str(path)
    d = read_toml(path, "plant file")
    unknown = sorted(set(d) - _TOP)
    if unknown:
        raise InputError(f"{src}: unknown tables/keys {unknown}; expected {sorted(_TOP)}")
    models = _power_models(d)
    lab = _mill(d.get("lab"), "lab", src)
    plant = _mill(d.get("mill"), "mill", src)
    name, tparams, tsrc = _transport(d.get("transport"), src, path.parent, plant)
    clf = _classifier(d.get("classifier"), src)
    base_grid = _grid(d, fit, src)
    grid = base_grid if grid is None else grid
    feed, tph = _feed(d.get("feed"), grid, src)
    search = d.get("search", {})
    if not isinstance(search, dict):
        raise InputError(f"{src}: search: expected a table [search]")
    rng = quantity(search, "throughput_range", "mass_flow", f"{src}: search", None, array=True)
    check_keys(search, unit_keys("throughput_range", "mass_flow"), f"{src}: search")
    if rng is not None:
        rng = np.atleast_1d(rng) * 3.6
        if rng.size != 2:
            raise InputError(f"{src}: search.throughput_range: expected [low, high], got {rng.size} values")
    austin = d.get("austin", {})
    if not isinstance(austin, dict):
        raise InputError(f"{src}: austin: expected a table [austin]")
    check_keys(austin, set(AUSTIN_DEFAULTS), f"{src}: austin")
    for k in austin:
        number(austin, k, f"{src}: austin")
    lab_process = (d.get("lab") or {}).get("process", {})
    if not isinstance(lab_process, dict):
        raise InputError(f"{src}: lab.process: expected a table of the fit's process values")
    for k in lab_process:
        number(lab_process, k, f"{src}: lab.process", lo=0.0, lo_open=True)
    scaling = string(d, "scaling", src, "herbst_fuerstenau")
    circuit = Circuit(plant, name, tparams, clf)
    su = ScaleUp(fit, lab, lab_process, circuit, feed, tph, scaling=scaling, austin_overrides=austin, x=grid,
                 throughput_range_tph=tuple(rng) if rng is not None else (None, None))
    return su, {"title": d.get("title", path.stem), "transport_source": tsrc, "transport": name,
                "transport_params": tparams, "power_models": models, "grid": base_grid}


def load_plant(path, fit: FittedBreakage, refine: int = 0) -> tuple[ScaleUp, dict]:
    """ScaleUp for the plant file at ``path`` and the fit; second value: notes (transport source,
    power models). ``refine``: split every class of the prediction grid into 2^refine in ln x
    (nested: every edge kept; the grid contribution to the band); a negative value merges
    pairs of classes instead (every second edge), when the class count allows."""
    su, notes = read_plant(path, fit)
    if not refine:
        return su, notes
    base = notes["grid"]
    if refine > 0:
        grid = base.refine(2 ** int(refine))
    else:
        grid = coarsened(base, 2 ** int(-refine))
    return read_plant(path, fit, grid)


def coarsened(grid: SizeGrid, k: int) -> SizeGrid:
    """Every k-th edge of ``grid`` (the sink edge kept): the grid ``grid`` refines k x in ln x.
    InputError when the classes above the sink do not divide by k."""
    x = grid.x
    if (x.size - 1) % k:
        raise InputError(f"a grid of {x.size} classes cannot be merged {k} classes at a time")
    return SizeGrid(x[::k], grid.scheme)
