"""Water in a flowsheet: the slurry's second component, balanced after the solids.

Every stream carries a water mass flow w [kg/s] beside its solids. Water does not
break or classify by size; each unit sends to its outlet port p the water
w_p = a_p W_u + c_p, with W_u = (sum of its inlet streams' water) + its added water
(``add_water_tph``), so the flowsheet's water is one small linear system
(I - A) w = c over the streams, solved once after the solids (the constants c may
depend on the solved solids):

- feed: c = its water (``water_tph``, or from ``solids_content_pct``);
- mill, mixer (sump), product: a = 1 (water passes);
- splitter: a = the port's fraction;
- classifier with a water split R_f (``water_to_coarse``; for a hydrocyclone given by a
  fixed curve, R_f = its bypass, the usual convention that fines short-circuit with the
  water): coarse a = R_f, fine a = 1 - R_f;
- classifier with the coarse stream's % solids given (``coarse_solids_content_pct`` = p):
  coarse a = 0, c = S_c (1 - p)/p; fine a = 1, c = -S_c (1 - p)/p (S_c the coarse solids);
- a hydrocyclone predicted from its geometry reports its own R_f (``water_split`` of its
  unit report).

A negative water flow means the stated splits cannot hold (an underflow % solids that
needs more water than the feed brings): SolverError naming the unit. Slurry properties
of a stream (Wills & Finch, Mineral Processing Technology, 8th ed., ch. 3): % solids by
mass C_w = S/(S + w); volumetric flow Q = S/rho_s + w/rho_w; pulp density
rho_p = (S + w)/Q; % solids by volume C_v = (S/rho_s)/Q.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError, SolverError

__all__ = ["Slurry", "WaterSolution", "solve_water", "slurry_properties"]


@dataclass(frozen=True)
class Slurry:
    """Densities of the ore's solids and of the water [kg/m3] (given once per flowsheet)."""

    solids_density: float
    water_density: float = 1000.0

    #: Densest solid (osmium, 22.6 t/m3) rounded up: a density above it is a unit slip.
    MAX_DENSITY = 25_000.0

    def __post_init__(self):
        for k in ("solids_density", "water_density"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= self.MAX_DENSITY):
                raise InputError(f"slurry.{k} = {v!r} kg/m3: expected a density in (0, {self.MAX_DENSITY:g}] kg/m3 "
                                 "(check the unit: t_m3 or kg_m3)")

    def volume_flow(self, solids: float, water: float) -> float:
        """Q = S/rho_s + w/rho_w [m3/s] of solids S and water w [kg/s]."""
        return solids / self.solids_density + water / self.water_density


@dataclass(frozen=True, eq=False)
class WaterSolution:
    """Water per stream [kg/s] (``flows``, rows in stream order) and per unit balance."""

    flows: np.ndarray
    units: dict
    overall_error: float


def _rules(fs, uname, unit, solids_of, info) -> dict:
    """Port -> (a, c): water to the port = a W_u + c (see the module)."""
    kind = unit.type
    if kind == "feed":
        return {"out": (0.0, float(getattr(unit, "water", 0.0)))}
    if kind == "splitter":
        return {p: (float(f), 0.0) for p, f in unit.fractions.items()}
    if kind == "classifier":
        coarse, fine = unit.ports
        split = info.get("water_split")
        rule = getattr(unit, "water", None) or {}
        if split is None and "to_coarse" in rule:
            split = rule["to_coarse"]
        if split is None and not rule and unit.kind == "hydrocyclone" and hasattr(unit, "params"):
            split = unit.params.get("bypass", 0.0)  # R_f = bypass: fines short-circuit with the water
        if split is None and "coarse_solids_content" in rule:
            p = rule["coarse_solids_content"]
            c = solids_of(coarse) * (1.0 - p) / p
            return {coarse: (0.0, c), fine: (1.0, -c)}
        if split is None:
            return {coarse: (None, 0.0), fine: (None, 0.0)}  # undefined: an error if water arrives
        return {coarse: (float(split), 0.0), fine: (1.0 - float(split), 0.0)}
    return {p: (1.0, 0.0) for p in unit.ports}


def solve_water(fs, flows, infos) -> WaterSolution:
    """Water of every stream for the solved solids ``flows`` [kg/s] (see the module)."""
    names = fs.stream_names
    S = len(names)
    sidx = {n: k for k, n in enumerate(names)}
    solids = {n: math.fsum(flows[k]) for k, n in enumerate(names)}
    added = dict(getattr(fs, "water_added", {}) or {})
    A = np.zeros((S, S))
    c = np.zeros(S)
    undefined = {}
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        rules = _rules(fs, uname, unit, lambda port, u=uname: solids[fs.outlet(u, port)], infos.get(uname, {}))
        for port, (a, const) in rules.items():
            o = sidx[fs.outlet(uname, port)]
            if a is None:
                undefined[uname] = o
                continue
            for i in ins:
                A[o, i] += a
            c[o] += const + a * added.get(uname, 0.0)
    M = np.eye(S) - A
    try:
        w = np.linalg.solve(M, c)
        if not np.all(np.isfinite(w)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        raise SolverError("water balance is singular: a recycle loop returns all of its water (a classifier "
                          "with water_to_coarse = 1 or a splitter sending everything back)") from None
    w = w + np.linalg.solve(M, c - M @ w)  # one refinement step
    scale = max(float(np.max(np.abs(w))) if w.size else 0.0, 1e-300)
    for uname in undefined:
        win = math.fsum(w[sidx[i]] for i in fs.inlets(uname)) + added.get(uname, 0.0)
        if win > 0:
            raise InputError(f"units.{uname}: its feed carries {win * 3.6:.6g} t/h of water; say where it goes "
                             "with water_to_coarse (fraction of the feed water to the coarse stream) or "
                             "coarse_solids_content_pct")
    for k in np.flatnonzero(w < -1e-12 * scale):
        st = fs.streams[names[k]]
        raise SolverError(f"units.{st.source}: stream {names[k]} ({st.source}.{st.port}) would need "
                          f"{w[k] * 3.6:.6g} t/h of water: the stated split asks for more water than the "
                          "unit's feed brings (lower the coarse % solids or add water upstream)")
    w = np.where(w < 0, 0.0, w)  # rounding-level negatives only (|w| <= 1e-12 of the largest flow)
    units = {}
    for uname, unit in fs.units.items():
        win = math.fsum(w[sidx[i]] for i in fs.inlets(uname)) + added.get(uname, 0.0)
        if unit.type == "feed":
            win = float(getattr(unit, "water", 0.0))
        wout = win if unit.type == "product" else math.fsum(w[sidx[s]] for s in fs.outlets(uname))
        units[uname] = {"water_in_kg_s": win, "water_added_kg_s": added.get(uname, 0.0), "water_out_kg_s": wout,
                        "water_balance_error": abs(wout - win) / max(abs(win), abs(wout), 1e-300)
                        if max(abs(win), abs(wout)) > 0 else 0.0}
    fed = math.fsum(float(getattr(u, "water", 0.0)) for u in fs.units.values() if u.type == "feed")
    fed += math.fsum(added.values())
    out = math.fsum(w[sidx[s]] for n, u in fs.units.items() if u.type == "product" for s in fs.inlets(n))
    overall = abs(out - fed) / max(fed, out) if max(fed, out) > 0 else 0.0
    return WaterSolution(flows=w, units=units, overall_error=overall)


def slurry_properties(solids: float, water: float, slurry: Slurry | None) -> dict:
    """% solids by mass and volume, volumetric flow [m3/s] and pulp density [kg/m3] of a stream."""
    total = solids + water
    out = {"solids_content": solids / total if total > 0 else float("nan")}
    if slurry is not None:
        Q = slurry.volume_flow(solids, water)
        out.update(volume_flow_m3_s=Q, pulp_density_kg_m3=total / Q if Q > 0 else float("nan"),
                   solids_volume_fraction=(solids / slurry.solids_density) / Q if Q > 0 else float("nan"))
    return out
