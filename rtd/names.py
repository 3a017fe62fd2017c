"""The one table of transport (RTD) model names, used everywhere a name is read.

``rtd.fit``, ``python -m rtd fit`` / ``millflow fit-rtd``, flowsheet TOML
(``[units.X.transport] model = ...``) and fit configs (``[model] transport = ...``) all
resolve names here. Each model has one canonical snake_case name; the short names of
earlier versions (``cstr``, ``tis``, ``cells``, ``ad-closed``, ...) and the class names
(``TanksInSeries``, ...) are accepted as aliases.
"""
from __future__ import annotations

from dataclasses import dataclass

from rtd.axial import AxialDispersion
from rtd.base import RTDError, RTDModel
from rtd.compartments import RecirculatingCells
from rtd.models import PerfectMixing, PlugFlow, TanksInSeries

__all__ = ["Transport", "TRANSPORTS", "ALIASES", "canonical_name", "transport", "build"]


@dataclass(frozen=True)
class Transport:
    """One entry of the table of transport names.

    One entry: the model class, fixed constructor keywords, the parameters besides
    ``tau`` that must be given and those that may be.
    """

    name: str
    cls: type
    fixed: tuple = ()
    required: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()

    def build(self, tau: float, **params) -> RTDModel:
        """The model with mean residence time ``tau`` (any time unit, used consistently)."""
        unknown = sorted(set(params) - set(self.required) - set(self.optional))
        missing = [k for k in self.required if k not in params]
        if unknown or missing:
            need = ", ".join(self.required) or "none"
            may = ", ".join(self.optional) or "none"
            what = f"unknown {', '.join(unknown)}" if unknown else f"missing {', '.join(missing)}"
            raise RTDError(f"transport {self.name!r}: {what}; parameters besides tau: required {need}, optional {may}")
        return self.cls(tau, **dict(self.fixed), **params)


TRANSPORTS: dict[str, Transport] = {t.name: t for t in (
    Transport("perfect_mixing", PerfectMixing),
    Transport("plug_flow", PlugFlow),
    Transport("tanks_in_series", TanksInSeries, required=("n",)),
    Transport("recirculating_cells", RecirculatingCells, required=("n",), optional=("r", "dead", "bypass")),
    Transport("axial_dispersion", AxialDispersion, fixed=(("bc", "closed"),), required=("pe",)),
    Transport("axial_dispersion_open", AxialDispersion, fixed=(("bc", "open"),), required=("pe",)),
)}

#: Other spellings -> canonical name (short names of rtd.fit and millflow fit-rtd, class names).
ALIASES = {
    "cstr": "perfect_mixing", "PerfectMixing": "perfect_mixing",
    "plug": "plug_flow", "PlugFlow": "plug_flow",
    "tis": "tanks_in_series", "TanksInSeries": "tanks_in_series",
    "cells": "recirculating_cells", "RecirculatingCells": "recirculating_cells",
    "ad-closed": "axial_dispersion", "axial_dispersion_closed": "axial_dispersion",
    "AxialDispersion": "axial_dispersion",
    "ad-open": "axial_dispersion_open",
}


def canonical_name(name: str) -> str:
    """The canonical name for ``name`` (canonical or alias); RTDError listing the valid ones."""
    if isinstance(name, str):
        if name in TRANSPORTS:
            return name
        if name in ALIASES:
            return ALIASES[name]
    raise RTDError(f"transport model {name!r} unknown; expected one of {', '.join(TRANSPORTS)} "
                   f"(or an alias: {', '.join(ALIASES)})")


def transport(name: str) -> Transport:
    """The table entry for a canonical name or alias."""
    return TRANSPORTS[canonical_name(name)]


def build(name: str, tau: float, **params) -> RTDModel:
    """``rtd.names.build("tanks_in_series", 600.0, n=3)`` -> ``TanksInSeries(600.0, 3)``."""
    return transport(name).build(tau, **params)
