"""Classifiers: efficiency curves (:data:`millflow.classifiers.CURVES`), hydrocyclones
predicted from their dimensions (Plitt, Nageswararao), and where a classifier's water goes."""
from __future__ import annotations

import inspect

import numpy as np

from millflow.classifiers import CURVES
from millflow.errors import InputError
from millflow.flowsheet.readers.tables import _Table, _user_key, _warn_pct_slip, _wrap
from millflow.flowsheet.units import Classifier


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


def _classifier(name: str, utype: str, t: _Table, slurry=None):
    """A hydrocyclone, screen or air separator: a fixed curve, or a predicted hydrocyclone."""
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
