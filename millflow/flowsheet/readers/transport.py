"""A mill's ``transport`` table: a named model (:mod:`rtd.names`), a series of parts, or a
``millflow fit-rtd --json`` result (tau converted from the fit's time unit)."""
from __future__ import annotations

import math
from pathlib import Path

from millflow.errors import InputError
from millflow.flowsheet.readers.tables import _named_file, _Table
from millflow.flowsheet.units import TRANSPORTS
from millflow.inputs import UNITS, read_json
from millflow.mill.transport import is_axial_dispersion, is_tanks
from rtd import names as rtd_names


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
    if is_axial_dispersion(model, open_vessel=True):  # where the discharge is taken (millflow.mill.axial_open)
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
    if is_tanks(model) and (classified or kinetic) and params["n"] != round(params["n"]):
        whole = max(1, round(params["n"]))
        why = ("discharge classification needs whole cells" if classified
               else "non-linear kinetics are solved tank by tank")
        note += f"; fitted n = {params['n']:.4g} in {p.name} -> {whole} tanks (nearest whole n: {why})"
        params["n"] = float(whole)
    return model, params, values["tau"] * UNITS["time"][unit], note
