"""A mill's scene: what its definition declares, checked once, and the method it runs.

:func:`_scene` validates S, b, d and the transport, places the classification
(``where``) and chooses the cheapest exact method (:func:`choose_method`) unless one is
forced; :mod:`millflow.mill.steady` dispatches on ``scene.method``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import rtd
from millflow import checks
from millflow.errors import InputError
from millflow.mill.axial_open import check_discharge
from millflow.mill.cells import network_of

__all__ = ["METHODS", "WHERE", "AXIAL_KINDS", "choose_method"]

#: Steady-state methods by name (see the module docstring).
METHODS = ("well_mixed", "cells", "plug_flow", "segregated", "axial_fv", "composed", "quadrature")
#: Where classification acts: at the discharge (exit flows), at every cell outlet
#: (every flow of a cell network), along the axis (axial velocity of class i = d_i* u).
WHERE = ("discharge", "cells", "axis")


# ----------------------------------------------------------------------- checking
def _kind(transport) -> str:
    if hasattr(transport, "model_in_seconds"):  # an rtd.FitResult, not a model
        unit = getattr(transport, "time_unit", "") or "no unit"
        raise InputError(f"transport is an rtd fit result (times in {unit}); pass result.model_in_seconds() "
                         "(millflow's times are seconds)")
    if isinstance(transport, rtd.PerfectMixing):
        return "perfect_mixing"
    if isinstance(transport, rtd.PlugFlow):
        return "plug"
    if isinstance(transport, rtd.AxialDispersion):
        return "axial" if transport.bc == "closed" else "axial_open"
    if isinstance(transport, rtd.Series):
        return "series"
    if isinstance(transport, rtd.Parallel):
        return "parallel"
    if network_of(transport) is not None:
        return "network"
    if hasattr(transport, "laplace") and hasattr(transport, "mean"):
        return "rtd"
    raise InputError(
        f"transport is {transport!r}; expected an rtd model (rtd.PerfectMixing, rtd.PlugFlow, "
        "rtd.TanksInSeries, rtd.RecirculatingCells, rtd.AxialDispersion, rtd.Series, ...)")


_WHERE_OK = {
    "perfect_mixing": ("discharge", "cells"),
    "network": ("discharge", "cells"),
    "plug": ("axis",),
    "axial": ("axis",),
    "axial_open": ("axis",),
    "rtd": (),
    "series": (),
    "parallel": (),
}
_WHERE_DEFAULT = {"perfect_mixing": "discharge", "network": "discharge", "plug": "axis", "axial": "axis",
                  "axial_open": "axis"}
#: Transport kinds solved on the axis (finite volumes when classified).
AXIAL_KINDS = ("axial", "axial_open")


def _check_feed(feed, n: int) -> np.ndarray:
    feed = np.asarray(feed, dtype=float)
    if feed.ndim == 2 and feed.shape[0] == n:
        if not np.all(np.isfinite(feed)) or np.any(feed < 0):
            raise InputError("feed: expected finite flows >= 0 in every column")
        return feed
    return checks.class_vector(feed, n, "feed", "feed flow")


@dataclass(frozen=True)
class _Scene:
    """A validated mill definition: what the solvers need and nothing more."""

    S: np.ndarray
    b: np.ndarray
    transport: object
    kind: str
    d: np.ndarray | None
    where: str | None
    dispersion: np.ndarray | None
    method: str
    network: object = None
    forced: bool = False
    discharge: str | None = None


def _scene(S, b, transport, d=None, where=None, dispersion=None, method=None, discharge=None) -> _Scene:
    S, b = checks.kernel(S, b)
    n = S.size
    kind = _kind(transport)
    if d is not None:
        d = checks.class_vector(d, n, "d", "normalised discharge rate d_i*", positive=True)
    if dispersion is not None:
        if kind not in AXIAL_KINDS:
            raise InputError(f"dispersion is given but transport {transport!r} has no axial "
                             "dispersion; expected rtd.AxialDispersion")
        dispersion = checks.class_vector(dispersion, n, "dispersion", "relative dispersion", positive=True)
    if discharge is not None and kind != "axial_open":
        raise InputError(f"discharge = {discharge!r} is given but transport {transport!r} is not the open "
                         "vessel; expected rtd.AxialDispersion(bc='open') or discharge=None")
    if kind == "axial_open":  # the open vessel's default dispersion is d (one Peclet number)
        v = np.ones(n) if d is None else d
        check_discharge(discharge, v, v if dispersion is None else dispersion)
    if d is not None:
        allowed = _WHERE_OK[kind]
        if not allowed:
            raise InputError(
                f"transport {transport!r} cannot carry classification d (it has no cells or axis "
                "to place it on); expected rtd.PerfectMixing, rtd.TanksInSeries (integer n), "
                "rtd.RecirculatingCells, a CompartmentNetwork, rtd.PlugFlow or "
                "rtd.AxialDispersion, or d=None")
        where = _WHERE_DEFAULT[kind] if where is None else where
        if kind == "network" and not isinstance(where, str):
            where = _cell_list(where, network_of(transport).n)
        elif where not in allowed:
            raise InputError(f"where = {where!r} is not possible for {type(transport).__name__}; "
                             f"expected one of {', '.join(map(repr, allowed))}")
    elif where is not None and isinstance(where, str) and where not in WHERE:
        raise InputError(f"where = {where!r}; expected one of {', '.join(map(repr, WHERE))}")
    chosen = choose_method(kind, d is not None or dispersion is not None or discharge == "flux")
    if method is None:
        method = chosen
    elif method not in METHODS:
        raise InputError(f"method = {method!r} is unknown; expected one of {', '.join(METHODS)}")
    elif method != chosen and not _method_applies(method, kind, d, dispersion, discharge):
        raise InputError(f"method = {method!r} does not apply to {transport!r}"
                         f"{' with classification' if d is not None else ''}; the exact method is {chosen!r}")
    net = network_of(transport) if method == "cells" else None
    return _Scene(S, b, transport, kind, d, where, dispersion, method, net, method != chosen, discharge)


def _cell_list(where, n: int) -> tuple:
    try:
        cells = tuple(int(k) for k in where)
    except (TypeError, ValueError):
        raise InputError(f"where = {where!r}; expected 'discharge', 'cells' or 1-based cell numbers") from None
    bad = [k for k in cells if not 1 <= k <= n]
    if bad or not cells:
        raise InputError(f"where = {where!r}: cell {bad[0] if bad else '(none)'} is not in 1..{n}; "
                         "expected 1-based cell numbers of the network")
    return cells


def choose_method(kind: str, classified: bool) -> str:
    """The cheapest exact method for a transport kind (see the module docstring)."""
    if kind == "perfect_mixing":
        return "well_mixed"
    if kind == "network":
        return "cells"
    if kind == "plug":
        return "plug_flow"
    if kind in AXIAL_KINDS:
        return "axial_fv" if classified else "segregated"
    if kind in ("series", "parallel"):
        return "composed"
    return "segregated"


def _method_applies(method, kind, d, dispersion, discharge=None) -> bool:
    if method in ("segregated", "quadrature"):
        return d is None and dispersion is None and kind != "plug" and discharge != "flux"
    if method == "cells":
        return kind in ("perfect_mixing", "network")
    if method == "axial_fv":
        return kind in AXIAL_KINDS
    return False


def _part_scene(sc: _Scene, part) -> _Scene:
    """Scene of one part of a Series or Parallel (breakage already validated)."""
    kind = _kind(part)
    method = choose_method(kind, False)
    net = network_of(part) if method == "cells" else None
    return _Scene(sc.S, sc.b, part, kind, None, None, None, method, net, False)


def _tau(transport) -> float:
    tau = float(transport.mean)
    if not np.isfinite(tau) or tau <= 0:
        raise InputError(f"transport mean residence time is {tau!r}; expected tau > 0 [s]")
    return tau


# ------------------------------------------------------------------------ solving
