"""Mills given by dimensions and operation: one reader for the plant file and for flowsheets.

A mill table (``[mill]`` and ``[lab]`` of a plant file, or a ``[units.NAME]`` mill of a
flowsheet file) may carry its dimensions and operation instead of ``tau_*`` and ``power_*``:

- ``diameter_<length>``, ``length_<length>``, ``ball_size_<length>`` (any length unit of
  :data:`millflow.inputs.UNITS`: um, mm, m, in, ft), ``ball_filling`` (J), ``critical_speed_fraction``
  (phi_c), and optionally ``powder_filling`` (U), ``solids_density_<density>`` (kg_m3 or t_m3;
  ``solid_density_<density>`` is its earlier spelling), ``ball_density_<density>``,
  ``bed_porosity``, ``power_model``, ``drive_efficiency``;
- a lab table, or the plant file's mills, may also give ``power_<power>`` and ``holdup_<mass>``
  (measured values replace the computed ones).

Every dimensional key is read by :func:`millflow.inputs.quantity` (the one reader of
unit-suffixed keys): a key without its unit, or with an unknown one, is one error line
naming the key. The hold-up (so tau = H / F, solved with the circuit) and the net power
then come from :class:`~millflow.scaleup.plant.MillDesign`. In a flowsheet a mill without
its own solids density takes the flowsheet's ``[slurry] solids_density_<density>``. With a
``[units.NAME.lab]`` table (the lab mill's dimensions, or its power and hold-up) the mill's
rate is read as the lab's and scaled by Herbst-Fuerstenau, S = S_lab (P/H) / (P_lab/H_lab).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from millflow.errors import InputError
from millflow.inputs import UNITS, number, quantity, string
from millflow.scaleup.plant import MillDesign

__all__ = ["DESIGN_KEYS", "DIMENSIONED", "ScaledRate", "is_design", "design_from_table", "read_design",
           "design_keys"]

#: Dimensional keys of a mill by dimensions: base name -> (dimension, MillDesign field, SI -> field factor).
DIMENSIONED = {"diameter": ("length", "diameter_m", 1.0), "length": ("length", "length_m", 1.0),
               "ball_size": ("length", "ball_size_mm", 1e3),
               "solids_density": ("density", "solid_density_kg_m3", 1.0),
               "ball_density": ("density", "ball_density_kg_m3", 1.0)}
#: Measured values a mill table may give instead of the computed ones.
GIVEN = {"power": ("power", "power_kW", 1e-3), "holdup": ("mass", "holdup_kg", 1.0)}
#: Dimensionless keys.
PLAIN = ("ball_filling", "critical_speed_fraction", "powder_filling", "bed_porosity", "drive_efficiency")
REQUIRED = ("diameter", "length", "ball_filling", "critical_speed_fraction", "ball_size")
#: The earlier spelling of solids_density (kept readable).
_ALIASES = {"solid_density": "solids_density"}
#: Earlier name of the key list (SI spellings), kept for callers.
DESIGN_KEYS = ("diameter_m", "length_m", "ball_filling", "critical_speed_fraction", "ball_size_mm", "powder_filling",
               "solid_density_kg_m3", "ball_density_kg_m3", "bed_porosity", "power_model", "drive_efficiency")


@dataclass(frozen=True)
class ScaledRate:
    """rate(x) * factor: a lab rate carried to another mill (Herbst-Fuerstenau factor)."""

    rate: Callable
    factor: float

    def __call__(self, x):
        return self.factor * np.asarray(self.rate(x), float)


def _base_of(key: str, bases) -> str | None:
    for b in bases:
        if key == b or key.startswith(b + "_"):
            return b
    return None


def is_design(data: dict) -> bool:
    """True when a mill table gives the mill by its dimensions (any spelling of diameter,
    length, ball size, or its ball filling or speed)."""
    return any(_base_of(k, ("diameter", "length", "ball_size")) for k in data) or \
        any(k in data for k in ("ball_filling", "critical_speed_fraction"))


def design_keys(given: bool = False) -> str:
    """The keys of a mill by dimensions, as an error message lists them."""
    dims = [f"{b}_<{d}: {', '.join(UNITS[d])}>" for b, (d, _, _) in DIMENSIONED.items()]
    if given:
        dims += [f"{b}_<{d}: {', '.join(UNITS[d])}>" for b, (d, _, _) in GIVEN.items()]
    return ", ".join(dims + list(PLAIN) + ["power_model"])


def read_design(table: dict, where: str, *, given: bool = False, extra=(), defaults: dict | None = None,
                name: str | None = None) -> tuple[MillDesign, set]:
    """(MillDesign, keys read) of a mill table (module docstring).

    ``given``: power_<unit> and holdup_<unit> are the mill's own (measured) values;
    ``extra``: keys the caller reads itself (left alone); ``defaults``: field -> value for
    keys the table does not give (e.g. the flowsheet's solids density). Keys that belong to
    none of these are the caller's to refuse (:func:`check_design_keys`).
    """
    used: set = set()
    kw = {}
    dims = dict(DIMENSIONED, **(GIVEN if given else {}))
    for alias, base in _ALIASES.items():
        spelled = [k for k in table if _base_of(k, (alias,)) == alias]
        if spelled:
            if any(_base_of(k, (base,)) == base for k in table):
                raise InputError(f"{where}: {spelled[0]} and {base}_<unit> both given; keep {base}_<unit>")
            v = quantity(table, alias, DIMENSIONED[base][0], where, used=used)
            kw[DIMENSIONED[base][1]] = v * DIMENSIONED[base][2]
    plain = {k: v for k, v in table.items() if k != "power_model"}  # not a power with unit "model"
    for base, (dim, field, factor) in dims.items():
        v = quantity(plain, base, dim, where, None, used=used)
        if v is not None:
            kw[field] = v * factor
    for key in PLAIN:
        v = number(table, key, where, None)
        if v is not None:
            kw[key] = v
            used.add(key)
    if "power_model" in table:
        kw["power_model"] = string(table, "power_model", where)
        used.add("power_model")
    missing = [f"{b}_<unit>" if b in DIMENSIONED else b for b in REQUIRED
               if (DIMENSIONED[b][1] if b in DIMENSIONED else b) not in kw]
    if missing:
        raise InputError(f"{where}: a mill given by dimensions needs {', '.join(missing)} (e.g. diameter_m, "
                         "ball_size_mm)")
    for field, v in (defaults or {}).items():
        kw.setdefault(field, v)
    try:
        return MillDesign(**kw, name=name or where), used
    except TypeError as exc:
        raise InputError(f"{where}: {exc}") from None


def check_design_keys(table: dict, used: set, where: str, allowed=(), given: bool = False) -> None:
    """Refuse, in one line naming it, a key of a mill table that is neither read nor ``allowed``."""
    for k in table:
        if k in used or k in allowed:
            continue
        raise InputError(f"{where}.{k}: unknown key; a mill by dimensions takes {design_keys(given)}"
                         + (f", {', '.join(allowed)}" if allowed else ""))


def design_from_table(where: str, data: dict, slurry=None) -> dict:
    """Hold-up [kg], net power [W], rate factor and the keys used, from a flowsheet mill table
    (its solids density, if not given, from the flowsheet's ``slurry``)."""
    defaults = {"solid_density_kg_m3": float(slurry.solids_density)} if slurry is not None else None
    mill, used = read_design(data, where, defaults=defaults)
    out = {"design": mill, "holdup_kg": mill.holdup(), "power_W": mill.power()["net_kW"] * 1e3,
           "power": mill.power(), "rate_factor": 1.0}
    lab = data.get("lab")
    if lab is not None:
        if not isinstance(lab, dict):
            raise InputError(f"{where}.lab: expected a table")
        lw = f"{where}.lab"
        P_lab = quantity(lab, "power", "power", lw, None)
        H_lab = quantity(lab, "holdup", "mass", lw, None)
        if P_lab is not None and H_lab is not None:
            lab_used = {k for k in lab if _base_of(k, ("power", "holdup"))}
            check_design_keys(lab, lab_used, lw, given=True)
            P_lab /= 1e3
        else:
            lm, lab_used = read_design(lab, lw, given=True)
            check_design_keys(lab, lab_used, lw, given=True)
            P_lab, H_lab = lm.power()["net_kW"], lm.holdup()
        out["rate_factor"] = (out["power_W"] / 1e3 / out["holdup_kg"]) / (P_lab / H_lab)
        used.add("lab")
    out["keys"] = used
    return out
