"""Mill units: material or own breakage, transport, residence time or hold-up (or the
mill's dimensions, docs/scaleup.md), power, classification inside the mill, non-linear kinetics."""
from __future__ import annotations

import math
from pathlib import Path

from millflow.errors import InputError
from millflow.flowsheet.readers.classifiers import _curve_params
from millflow.flowsheet.readers.materials import _breakage, _rate
from millflow.flowsheet.readers.tables import _plausible, _suffixes, _Table, _wrap
from millflow.flowsheet.readers.transport import _rtd_fit, _transport_part, _transport_table
from millflow.flowsheet.units import MillUnit, build_transport
from millflow.grid import SizeGrid


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


def _breakage_of(name: str, t: _Table, materials: dict, base: Path | None, grid: SizeGrid | None):
    """(rate, breakage) of a mill: its own ``rate``/``breakage`` tables, else its material's."""
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
    return rate, brk


def _transport(t: _Table, base: Path | None):
    """(model, parameters, fitted tau [s] or None, note or None) of a mill's ``transport``
    table (perfect mixing without one)."""
    tr = t.sub("transport", None)
    if tr is None:
        return "perfect_mixing", {}, None, None
    if "rtd_fit" in tr.data:
        return _rtd_fit(tr, base, "classification" in t.data, "kinetics" in t.data)
    if tr.data.get("model") == "series":
        tr.plain("model")
        parts = tr.plain("parts")
        tr.finish("model = \"series\", parts = [{model = ..., tau_fraction = ..., ...}, ...]")
        if not isinstance(parts, list) or len(parts) < 2:
            raise InputError(f"{tr.where}.parts: expected a list of at least two transport tables")
        tparams = {"parts": [_transport_part(p, f"{tr.where}.parts[{k}]") for k, p in enumerate(parts)]}
        total = math.fsum(p[2] for p in tparams["parts"])
        if abs(total - 1.0) > 1e-12:
            raise InputError(f"{tr.where}.parts: tau_fraction values sum to {total:.12g}; expected 1 (each part's "
                             "share of the mill's mean residence time)")
        return "series", tparams, None, None
    model, tparams = _transport_table(tr)
    return model, tparams, None, None


def _design(name: str, t: _Table, slurry, rate):
    """(design or None, rate): a mill by dimensions and operation (hold-up, power and a lab
    rate scaled by :mod:`millflow.scaleup.flowsheet`), its keys marked used."""
    from millflow.scaleup.flowsheet import ScaledRate, design_from_table, is_design

    if not is_design(t.data):
        return None, rate
    design = design_from_table(f"units.{name}", t.data, slurry)
    t.used.update(design["keys"])
    if design["rate_factor"] != 1.0:
        if getattr(rate, "basis", "time") == "energy":
            raise InputError(f"units.{name}.lab: the rate is per energy (S = S^E P/H in every mill); "
                             "a lab table scales rates per time only: remove one")
        rate = ScaledRate(rate, design["rate_factor"])
    return design, rate


def _residence(name: str, t: _Table, design, slurry, fitted_tau, rtd_note):
    """(tau [s], hold-up [kg], slurry volume [m3], note): what fixes a mill's residence time,
    from the mill's keys, its dimensions or a tracer fit's tau."""
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
    return tau, holdup, slurry_volume, rtd_note


def _power(t: _Table, design):
    """A mill's power [W]: its ``power_<unit>`` key, else its dimensions' power model, else None."""
    # (power_model of a mill by dimensions is not a power with an unknown unit)
    given = design is None or any(k.startswith("power_") and k != "power_model" for k in t.data)
    power = _plausible(t, "power", "power", t.quantity("power", "power", None, allow_zero=True)) if given else None
    if design is not None and power is None:
        power = design["power_W"]
    return power


def _mill_classification(t: _Table):
    """Classification inside the mill (``classification`` table: curve, parameters, where) or None."""
    if "classification" not in t.data:
        return None
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
    return cls


def _mill(name: str, t: _Table, materials: dict, slurry=None, base: Path | None = None,
          grid: SizeGrid | None = None) -> MillUnit:
    """A mill table: breakage from its material (or its own), transport, tau or hold-up."""
    rate, brk = _breakage_of(name, t, materials, base, grid)
    model, tparams, fitted_tau, rtd_note = _transport(t, base)
    design, rate = _design(name, t, slurry, rate)
    tau, holdup, slurry_volume, rtd_note = _residence(name, t, design, slurry, fitted_tau, rtd_note)
    power = _power(t, design)
    cls = _mill_classification(t)
    kin = _kinetics(t.sub("kinetics")) if "kinetics" in t.data else None
    t.finish("type, material, rate, breakage, transport, tau_min, holdup_t, slurry_volume_m3, power_kW, "
             "classification, kinetics, add_water_tph, or by dimensions: diameter_m, length_m, ball_filling, "
             "critical_speed_fraction, ball_size_mm, slurry_filling, ... "
             "(docs/scaleup.md)")
    unit = _wrap(f"units.{name}", MillUnit, name, rate, brk, model, tparams, tau, holdup, cls, power, kin,
                 slurry_volume, slurry, rtd_note)
    _wrap(f"units.{name}", build_transport, model, tau or 1.0, tparams)
    return unit
