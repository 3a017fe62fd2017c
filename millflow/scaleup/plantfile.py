"""Read a plant file (TOML) for ``millflow scaleup``: the lab mill the fit comes from, the
plant mill by dimensions and operation, its transport, an optional closing classifier and
the fresh feed. Dimensional keys carry their unit in the name (``diameter_m``,
``ball_size_mm``, ``d50c_um``, ``feed_tph``); a dimensional key without its unit is an
error that names the expected key. See docs/scaleup.md for the layout.
"""
from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np

from millflow.errors import GridError, InputError
from millflow.inputs import read_text
from millflow.grid import SizeGrid
from millflow.psd import from_sieves
from millflow.scaleup.fitted import FittedBreakage
from millflow.scaleup.plant import Circuit, MillDesign
from rtd import names as _rtd_names
from rtd.base import RTDError
from millflow.scaleup.predict import ScaleUp
from millflow.scaleup.scaling import AUSTIN_DEFAULTS

__all__ = ["load_plant"]

_MILL_KEYS = {"diameter_m", "length_m", "ball_filling", "critical_speed_fraction", "ball_size_mm", "powder_filling",
              "solid_density_kg_m3", "ball_density_kg_m3", "bed_porosity", "power_model", "power_kW", "holdup_kg",
              "drive_efficiency"}
_TOP = {"title", "scaling", "lab", "mill", "transport", "classifier", "feed", "search", "austin", "grid"}


def _unit_hint(key: str, allowed) -> str | None:
    """The allowed key that is ``key`` plus a unit suffix, if any."""
    for a in allowed:
        if a.startswith(key + "_") and a.rsplit("_", 1)[-1] in ("m", "mm", "um", "tph", "kW", "kg", "m3", "s", "min"):
            return a
        if a.startswith(key + "_kg") or a.startswith(key + "_t"):
            return a
    return None


def _check_keys(table: dict, allowed, where: str, src: str):
    for k in table:
        if k in allowed:
            continue
        hint = _unit_hint(k, allowed)
        if hint:
            raise InputError(f"{src}: {where}.{k}: units missing from the key; expected {hint!r}")
        raise InputError(f"{src}: {where}.{k}: unknown key; expected one of {sorted(allowed)}")


def _mill(table, where, src) -> MillDesign:
    if not isinstance(table, dict):
        raise InputError(f"{src}: [{where}] table missing")
    t = dict(table)
    t.pop("process", None)
    _check_keys(t, _MILL_KEYS, where, src)
    missing = [k for k in ("diameter_m", "length_m", "ball_filling", "critical_speed_fraction", "ball_size_mm")
               if k not in t]
    if missing:
        raise InputError(f"{src}: [{where}] missing keys {missing}")
    try:
        return MillDesign(**t, name=f"{src}: {where}")
    except TypeError as exc:
        raise InputError(f"{src}: [{where}]: {exc}") from None


def _transport_entry(name, where):
    try:
        return _rtd_names.transport(name)
    except RTDError as exc:
        raise InputError(f"{where}: {exc}") from None


def _aspect_correlation(corr, entry, mill: MillDesign, src):
    """A shape parameter from a correlation the user states in L/D: value = c (L/D)^e.

    millflow ships no default: published ball-mill RTD correlations (reviewed by Austin,
    Klimpel & Luckie 1984, ch. 8; Cho & Austin, Powder Technol. 124 (2002) 112) hold for
    the mills they were measured on, so the plant file names its source."""
    if not isinstance(corr, dict):
        raise InputError(f"{src}: transport.from_aspect_ratio: expected a table with parameter, coefficient, "
                         "exponent and source")
    _check_keys(corr, {"parameter", "coefficient", "exponent", "source"}, "transport.from_aspect_ratio", src)
    missing = [k for k in ("parameter", "coefficient", "exponent", "source") if k not in corr]
    if missing:
        raise InputError(f"{src}: transport.from_aspect_ratio: missing {missing} "
                         f"(value = coefficient * (L/D)^exponent, "
                         "source names where the correlation comes from)")
    name = corr["parameter"]
    if name not in entry.required + entry.optional:
        raise InputError(f"{src}: transport.from_aspect_ratio.parameter = {name!r}: not a parameter of "
                         f"{entry.name!r}; expected one of {list(entry.required + entry.optional)}")
    c, e = corr["coefficient"], corr["exponent"]
    for key, v in (("coefficient", c), ("exponent", e)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{src}: transport.from_aspect_ratio.{key} = {v!r}: expected a finite number")
    if not isinstance(corr["source"], str) or not corr["source"].strip():
        raise InputError(f"{src}: transport.from_aspect_ratio.source: expected the correlation's source as text")
    ratio = mill.length_m / mill.diameter_m
    return name, float(c) * ratio ** float(e), f"{name} = {c} (L/D)^{e} at L/D = {ratio:.4g} ({corr['source']})"


def _transport(table, src, base: Path, mill: MillDesign | None = None):
    t = dict(table or {"model": "tanks_in_series", "n": 3})
    if "rtd_fit" in t:
        p = base / t.pop("rtd_fit")
        try:
            d = json.loads(p.read_text(encoding="utf-8-sig"))
        except FileNotFoundError:
            raise InputError(f"{src}: transport.rtd_fit {str(p)!r}: file not found") from None
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"{p}: not a fit-rtd JSON result ({exc})") from None
        if t:
            raise InputError(f"{src}: [transport] with rtd_fit takes no other keys, got {sorted(t)}")
        entry = _transport_entry(d.get("model"), f"{p}: model")
        params = {k: v["value"] for k, v in d.get("params", {}).items() if k != "tau"}
        return entry.name, params, f"fit-rtd result {p.name} (shape only; tau = H/F at the plant)"
    entry = _transport_entry(t.pop("model", None), f"{src}: transport.model")
    allowed = entry.required + entry.optional
    note = "given"
    if "from_aspect_ratio" in t:
        name, value, note = _aspect_correlation(t.pop("from_aspect_ratio"), entry, mill, src)
        if name in t:
            raise InputError(f"{src}: transport.{name} given and also computed by from_aspect_ratio: give one")
        t[name] = value
    for k in t:
        if k not in allowed:
            raise InputError(f"{src}: transport.{k}: not a parameter of {entry.name!r}; expected {list(allowed)} "
                             "(tau comes from the hold-up and the flow)")
    return entry.name, t, note


def _classifier(table, src):
    if table is None:
        return None
    out = {}
    for k, v in table.items():
        if k == "curve":
            out[k] = v
        elif k.endswith("_um"):
            out[k[:-3]] = float(v) * 1e-6
        elif k in ("d50", "d50c"):
            raise InputError(f"{src}: classifier.{k}: units missing from the key; expected {k + '_um'!r}")
        else:
            out[k] = v
    if "curve" not in out:
        raise InputError(f"{src}: [classifier] needs curve (e.g. 'plitt') and its parameters")
    return out


def _feed(table, grid_x, src):
    if not isinstance(table, dict):
        raise InputError(f"{src}: [feed] table missing")
    _check_keys(table, {"feed_tph", "size_um", "passing"}, "feed", src)
    for k in ("feed_tph", "size_um", "passing"):
        if k not in table:
            raise InputError(f"{src}: feed.{k} missing")
    size = np.asarray(table["size_um"], float) * 1e-6
    P = np.asarray(table["passing"], float)
    if size.shape != P.shape:
        raise InputError(f"{src}: feed.size_um has {size.size} values, feed.passing {P.size}")
    if np.any(P > 1):
        raise InputError(f"{src}: feed.passing = {float(P.max())!r}: expected fractions in [0, 1], not percent")
    try:
        f = from_sieves(size, P, grid_x)
    except GridError as exc:
        raise GridError(f"{src}: feed: {exc} (give a [grid] with top_um above the feed top size: the fitted "
                        "forms are evaluated exactly on any grid)") from None
    return f, float(table["feed_tph"])


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
    ml = "given" if "power_kW" in lab else lab.get("power_model", "austin")
    mp = "given" if "power_kW" in plant else plant.get("power_model", "austin")
    return {"lab": ml, "plant": mp, "mixed": ml != mp and "given" not in (ml, mp)}


def load_plant(path, fit: FittedBreakage, refine: int = 0) -> tuple[ScaleUp, dict]:
    """ScaleUp for the plant file at ``path`` and the fit; second value: notes (transport source,
    power models). ``refine``: halve the prediction grid's class width (in log size) this many
    times (the grid contribution to the band)."""
    path = Path(path)
    src = str(path)
    try:
        d = tomllib.loads(read_text(path, "plant file"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{src}: not valid TOML ({exc})") from None
    unknown = sorted(set(d) - _TOP)
    if unknown:
        raise InputError(f"{src}: unknown tables/keys {unknown}; expected {sorted(_TOP)}")
    models = _power_models(d)
    lab = _mill(d.get("lab"), "lab", src)
    plant = _mill(d.get("mill"), "mill", src)
    name, tparams, tsrc = _transport(d.get("transport"), src, path.parent, plant)
    clf = _classifier(d.get("classifier"), src)
    x = fit.x
    g = d.get("grid")
    if g is not None:
        _check_keys(g, {"top_um", "bottom_um", "ratio"}, "grid", src)
        x = SizeGrid.between(float(g["top_um"]) * 1e-6, float(g.get("bottom_um", fit.x[-1] * 1e6)) * 1e-6,
                             float(g.get("ratio", fit.x[0] / fit.x[1])) ** (0.5 ** refine)).x
    elif refine:
        x = SizeGrid.between(fit.x[0], fit.x[-1], (fit.x[0] / fit.x[1]) ** (0.5 ** refine)).x
    feed, tph = _feed(d.get("feed"), x, src)
    search = d.get("search", {})
    _check_keys(search, {"throughput_range_tph"}, "search", src)
    rng = search.get("throughput_range_tph", (None, None))
    austin = d.get("austin", {})
    _check_keys(austin, set(AUSTIN_DEFAULTS), "austin", src)
    circuit = Circuit(plant, name, tparams, clf)
    su = ScaleUp(fit, lab, d.get("lab", {}).get("process", {}), circuit, feed, tph,
                 scaling=d.get("scaling", "herbst_fuerstenau"), austin_overrides=austin, x=x,
                 throughput_range_tph=tuple(rng))
    return su, {"title": d.get("title", path.stem), "transport_source": tsrc, "transport": name,
                "transport_params": tparams, "power_models": models}
