"""Mills of a flowsheet file given by dimensions and operation.

A ``[units.NAME]`` mill table may carry ``diameter_m``, ``length_m``, ``ball_filling``,
``critical_speed_fraction``, ``ball_size_mm`` and optionally ``powder_filling``,
``solid_density_kg_m3``, ``ball_density_kg_m3``, ``bed_porosity``, ``power_model``,
``drive_efficiency`` instead of ``tau_*`` and ``power_*``: the hold-up (so tau = H / F,
solved with the circuit) and the net power then come from :class:`MillDesign`. With a
``[units.NAME.lab]`` table (the lab mill's dimensions, or its ``power_kW`` and
``holdup_kg``) the mill's rate is read as the lab's and scaled by Herbst-Fuerstenau,
S = S_lab (P/H) / (P_lab/H_lab).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from millflow.errors import InputError
from millflow.scaleup.plant import MillDesign

__all__ = ["DESIGN_KEYS", "ScaledRate", "is_design", "design_from_table"]

DESIGN_KEYS = ("diameter_m", "length_m", "ball_filling", "critical_speed_fraction", "ball_size_mm", "powder_filling",
               "solid_density_kg_m3", "ball_density_kg_m3", "bed_porosity", "power_model", "drive_efficiency")
_UNITLESS = {"diameter": "diameter_m", "length": "length_m", "ball_size": "ball_size_mm",
             "solid_density": "solid_density_kg_m3", "ball_density": "ball_density_kg_m3"}


@dataclass(frozen=True)
class ScaledRate:
    """rate(x) * factor: a lab rate carried to another mill (Herbst-Fuerstenau factor)."""

    rate: Callable
    factor: float

    def __call__(self, x):
        return self.factor * np.asarray(self.rate(x), float)


def is_design(data: dict) -> bool:
    return any(k in data for k in DESIGN_KEYS[:5]) or any(k in data for k in _UNITLESS)


def _design(where, data, keys, extra=()):
    for k in data:
        if k in _UNITLESS:
            raise InputError(f"{where}.{k}: units of measure missing; write {_UNITLESS[k]}")
    kw = {k: data[k] for k in keys if k in data}
    for k in extra:
        if k in data:
            kw[k] = data[k]
    for k, v in kw.items():
        if k != "power_model" and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise InputError(f"{where}.{k} = {v!r}: expected a number")
    missing = [k for k in DESIGN_KEYS[:5] if k not in kw]
    if missing:
        raise InputError(f"{where}: a mill given by dimensions needs {missing}")
    return MillDesign(**kw, name=where), kw


def design_from_table(where: str, data: dict) -> dict:
    """Hold-up [kg], net power [W], rate factor and the keys used, from a mill table."""
    mill, kw = _design(where, data, DESIGN_KEYS)
    used = set(kw)
    out = {"design": mill, "holdup_kg": mill.holdup(), "power_W": mill.power()["net_kW"] * 1e3,
           "power": mill.power(), "rate_factor": 1.0}
    lab = data.get("lab")
    if lab is not None:
        if not isinstance(lab, dict):
            raise InputError(f"{where}.lab: expected a table")
        unknown = sorted(set(lab) - set(DESIGN_KEYS) - {"power_kW", "holdup_kg"} - set(_UNITLESS))
        if unknown:
            raise InputError(f"{where}.lab.{unknown[0]}: unknown key; valid: {', '.join(DESIGN_KEYS)}, power_kW, "
                             "holdup_kg")
        if "power_kW" in lab and "holdup_kg" in lab:
            P_lab, H_lab = float(lab["power_kW"]), float(lab["holdup_kg"])
            if not (P_lab > 0 and H_lab > 0):
                raise InputError(f"{where}.lab: power_kW and holdup_kg must be > 0, got {P_lab!r}, {H_lab!r}")
        else:
            lm, _ = _design(f"{where}.lab", lab, DESIGN_KEYS, ("power_kW", "holdup_kg"))
            P_lab, H_lab = lm.power()["net_kW"], lm.holdup()
        out["rate_factor"] = (out["power_W"] / 1e3 / out["holdup_kg"]) / (P_lab / H_lab)
        used.add("lab")
    out["keys"] = used
    return out
