"""Flowsheet units: stateless, each a linear map from its (mixed) inlet to its outlets.

Every unit mixes whatever enters it and sends to each outlet port a linear image of
that mixed feed: outlet_p = B_p (sum of inlets) + s_p, with B_p an (N, N) block for a
mill (the transfer matrix P of eq. 3 or of any residence time distribution), a vector
(a diagonal block) for classifiers (diag(c), diag(1 - c)), mixers (ones) and splitters
(fraction * ones), and s_p a constant source for feeds. All flows are solids mass flows
per size class [kg/s], coarse -> fine. A mill whose hold-up is given instead of its
residence time (tau = holdup / throughput), or whose rates are per energy (S = S^E P / H,
H = tau F), is nonlinear: its block depends on its own throughput, which the solver tears
(see :mod:`millflow.flowsheet.solve`).

``unit.blocks(grid, throughput=None)`` returns ``(blocks, info)``: ``blocks`` maps each
outlet port to its block, ``info`` holds ``method``, ``error_estimate`` and
``runtime_s`` of building it. Units hold only parameters (SI) and never change.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np

from millflow.breakage.averaged import breakage_on_grid, curve_on_grid
from millflow.classifiers import efficiency, mill_discharge_rates
from millflow.errors import InputError, MillflowError, SolverError
from millflow.mill.transport import BUILDERS, build_transport, is_axial, is_tanks

__all__ = [
    "Feed", "MillUnit", "Mill", "Classifier", "Mixer", "Splitter", "Product", "UNIT_TYPES", "TRANSPORTS",
    "CLASSIFIER_PORTS", "mill_transfer_matrix",
]


#: Transport (residence time distribution) models by their canonical name in rtd's one
#: table (:mod:`rtd.names`; flowsheet files also accept its aliases); each builds an
#: ``rtd`` model from tau [s] and its own parameters (:data:`millflow.mill.transport.BUILDERS`).
TRANSPORTS = BUILDERS


#: The tolerance of a non-linear mill's product relative to its feed (that of the linear mills'
#: transfer matrices, :func:`millflow.mill.transfer_matrix`): discretised paths (axial grids, the
#: plug-flow ODE) refine until their error estimate meets it, or the solve raises.
KINETIC_TOL = 1e-8
#: The slowing-down forms kappa(F) of ``kinetics.kappa_fines`` (F the fines fraction, s >= 0).
KAPPA_FINES = {
    "hyperbolic": (lambda s: (lambda F: 1.0 / (1.0 + s * F)), lambda s: (lambda F: -s / (1.0 + s * F) ** 2)),
    "exponential": (lambda s: (lambda F: math.exp(-s * F)), lambda s: (lambda F: -s * math.exp(-s * F))),
}


# ------------------------------------------------------------------ mill transfer
def mill_transfer_matrix(S, b, transport, d=None, where=None, discharge=None) -> tuple[np.ndarray, str]:
    """P with product = P @ feed (:func:`millflow.mill.transfer_matrix`) and the method used."""
    from millflow.mill import transfer_matrix

    said = "".join(f", {k}={v!r}" for k, v in (("where", where), ("discharge", discharge)) if v is not None)
    return (transfer_matrix(S, b, transport, d, where=where, discharge=discharge),
            f"millflow.mill.transfer_matrix({transport!r}{said})")


# ------------------------------------------------------------------------- units
@dataclass(frozen=True)
class Feed:
    """Fresh feed: solids flow [kg/s], PSD on the grid and water [kg/s].

    Fresh feed: a constant solids flow ``solids`` [kg/s] with mass fractions ``psd`` on the grid,
    and ``water`` [kg/s] (0 for a dry feed; :mod:`millflow.flowsheet.water`).
    """

    name: str
    solids: float
    psd: np.ndarray = field(repr=False)
    water: float = 0.0
    type: ClassVar[str] = "feed"
    max_inlets: ClassVar[int | None] = 0

    @property
    def ports(self) -> tuple[str, ...]:
        """The outlet ports: ``("out",)``."""
        return ("out",)

    def blocks(self, grid, throughput=None, water=None):
        """No block (a feed is a constant source)."""
        return {}, {"method": "constant source", "error_estimate": 0.0, "runtime_s": 0.0}

    def source(self) -> dict:
        """The feed's solids flows [kg/s] per size class."""
        return {"out": self.solids * np.asarray(self.psd, dtype=float)}


@dataclass(frozen=True)
class MillUnit:
    """Continuous mill: breakage (``rate``, ``breakage``) with a transport model and optional discharge classification.

    Parameters
    ----------
    rate : callable
        x [m] -> S [1/s] (e.g. :class:`millflow.breakage.PowerLawRate`): breakage per time; or an
        :class:`millflow.breakage.EnergySpecificRate`, x -> S^E [kg/J]: breakage per energy, the
        mill's rates S_i = S_i^E P / H (Herbst-Fuerstenau) with its ``power`` P [W] and its solids
        hold-up H = tau F [kg] at the solved throughput F, so that S_i tau = S_i^E P / F.
    breakage : object with ``.b(x)`` or callable x -> b.
    transport : str
        Key of :data:`TRANSPORTS`; ``transport_params`` its parameters (e.g. ``{"n": 10}``).
    tau : float or None
        Mean residence time [s] (linear unit), or
    holdup : float or None
        Solids hold-up [kg]; tau = holdup / throughput (nonlinear unit, torn by the solver), or
    slurry_volume : float or None
        Slurry hold-up [m3] of a wet mill (its volume times the slurry filling); tau =
        slurry_volume / Q, Q = S/rho_s + w/rho_w the volumetric slurry flow through it
        (``slurry`` gives the densities; torn by the solver on its solids and water).
    classification : dict or None
        ``{"curve": name, **params}`` (sizes in m) of a discharge screen/grate; the
        efficiency c_i becomes d_i* = (1 - c_i)/(1 - c_N)
        (:func:`millflow.classifiers.mill_discharge_rates`).
    power : float or None
        Mill power draw [W]: drives the breakage when the rates are per energy; otherwise
        information only (the specific energy it gives is not causal, see ``power_role``).
    kinetics : dict or None
        Non-linear kinetics: ``aggregation_kernel`` (constant, sum, product,
        shear) with ``aggregation_beta0`` [1/s] (per time) or ``aggregation_beta0_E`` [kg/J]
        (per energy, beta0 = beta0^E P / H with the mill's power P and hold-up H = tau F,
        as the breakage rates per energy: equal specific energy, equal aggregation) and
        ``x_ref_m`` [m]; ``cushion_lambda`` with ``fines_m`` [m] and ``cushion_w`` (default 1):
        population-dependent rates S_i (1 + w F)^lambda; ``kappa_fines`` ("hyperbolic",
        "exponential") with ``kappa_s`` and ``fines_m``: slowing-down S_i kappa(F),
        kappa = 1/(1 + s F) or exp(-s F). F is the mass fraction below fines_m, each class
        counted by its share below it (the class that straddles it by its share in ln x,
        :func:`millflow.nonlinear.kinetics.fines_fraction`). Such a mill is not a linear map
        of its feed: the solver tears its inlet flow vector (:mod:`millflow.flowsheet.solve`).
        Every transport and classification of the linear mill applies
        (:func:`millflow.mill.nonlinear.solve_transport`), solved to :data:`KINETIC_TOL`.
    """

    name: str
    rate: Callable
    breakage: object
    transport: str = "perfect_mixing"
    transport_params: dict = field(default_factory=dict)
    tau: float | None = None
    holdup: float | None = None
    classification: dict | None = None
    power: float | None = None
    kinetics: dict | None = None
    slurry_volume: float | None = None
    slurry: object = None
    transport_note: str | None = None
    type: ClassVar[str] = "mill"
    max_inlets: ClassVar[int | None] = None

    def __post_init__(self):
        if sum(v is not None for v in (self.tau, self.holdup, self.slurry_volume)) != 1:
            raise InputError(f"units.{self.name}: give exactly one of tau (e.g. tau_min), holdup (e.g. holdup_t) "
                             "or the slurry hold-up (slurry_volume_m3, or slurry_filling with dimensions)")
        if self.slurry_volume is not None and self.slurry is None:
            raise InputError(f"units.{self.name}: a mill given by its slurry hold-up needs the solids density "
                             "([slurry] solids_density_t_m3)")
        if self.transport not in TRANSPORTS and self.transport != "series":
            raise InputError(f"units.{self.name}.transport: unknown model {self.transport!r}; "
                             f"valid names: {', '.join(sorted(TRANSPORTS))}")
        if self.breakage_basis == "energy" and not (self.power is not None and self.power > 0):
            raise InputError(f"units.{self.name}: the rates are per energy (S = S^E P / H, A_E_<unit> or "
                             "per_energy); give the mill's power (power_kW) or its dimensions")
        if self.kinetics is not None and "aggregation_beta0_E" in self.kinetics and not (
                self.power is not None and self.power > 0):
            raise InputError(f"units.{self.name}.kinetics: the aggregation rate is per energy "
                             "(aggregation_beta0_E_<unit>: beta0 = beta0^E P / H); give the mill's power (power_kW) "
                             "or its dimensions")

    @property
    def breakage_basis(self) -> str:
        """``"energy"`` when the rates are per energy (S = S^E P / H), ``"time"`` when they are in 1/s."""
        return getattr(self.rate, "basis", "time")

    @property
    def residence_time_from(self) -> str:
        """How tau is set: fixed, solids hold-up / solids flow, or slurry volume / slurry flow."""
        if self.tau is not None:
            return "fixed tau (given; does not follow the feed rate)"
        if self.slurry_volume is not None:
            return "slurry hold-up / slurry flow (follows the feed rate)"
        return "solids hold-up / solids flow (follows the feed rate)"

    @property
    def power_role(self) -> str | None:
        """What the power does: drives breakage (per-energy rates) or information only (per-time rates)."""
        if self.power is None:
            return None
        return ("drives breakage: S = S^E P / H" if self.breakage_basis == "energy"
                else "information only: the rates are per time (1/s), power does not enter the kinetics")

    @property
    def kinetic_nonlinear(self) -> bool:
        """True when the mill declares non-linear kinetics (its product is not P @ feed)."""
        return self.kinetics is not None

    def nonlinear_kinetics(self, grid, tau=None, throughput=None):
        """The non-linear kinetics of this mill on ``grid``.

        :class:`millflow.nonlinear.Kinetics` of this mill on ``grid`` (``tau`` [s] and ``throughput``
        [kg/s] set the hold-up of a mill whose rates are per energy).
        """
        from millflow.nonlinear import KERNELS, Aggregation, kinetics

        from millflow.nonlinear.kinetics import fines_fraction

        S, b = self.breakage_functions(grid, tau, throughput)
        k = self.kinetics
        agg = None
        if "aggregation_kernel" in k:
            beta0 = k.get("aggregation_beta0")
            if beta0 is None:  # per energy: beta0 = beta0^E P / H, H = tau F (as S = S^E P / H)
                if tau is None or throughput is None or not throughput > 0:
                    raise SolverError(f"units.{self.name}: an aggregation rate per energy needs the mill's hold-up, "
                                      f"H = tau F; throughput {throughput!r} kg/s")
                beta0 = k["aggregation_beta0_E"] * float(self.power) / (float(tau) * float(throughput))
            agg = Aggregation(KERNELS[k["aggregation_kernel"]](beta0), k["x_ref_m"])
        w, lam, mask, kappa, dkappa = None, 0.0, None, None, None
        if "fines_m" in k:
            share = fines_fraction(grid, k["fines_m"])
        if "cushion_lambda" in k:
            w = k.get("cushion_w", 1.0) * np.outer(np.ones(grid.n), share)
            lam = k["cushion_lambda"]
        if "kappa_fines" in k:
            form = KAPPA_FINES[k["kappa_fines"]]
            mask, kappa, dkappa = share, form[0](k["kappa_s"]), form[1](k["kappa_s"])
        return kinetics(S, b, w=w, lam=lam, aggregation=agg, grid=grid, fines_mask=mask, kappa=kappa, dkappa=dkappa)

    def product_flows(self, grid, inflow, water=None):
        """Product flows [kg/s] for the inlet flows (non-linear kinetics).

        Product flows [kg/s] for the inlet flows ``inflow`` [kg/s] (non-linear kinetics) and,
        for a mill given by its slurry hold-up, the water through it [kg/s] (tau = V / Q at
        those flows); the aggregation overflow (coarser than the grid) is added to class 1
        and reported, and above :data:`MAX_OVERFLOW` of the throughput refused.
        """
        from millflow.mill import nonlinear as nl

        t0 = time.perf_counter()
        total = float(np.sum(inflow))
        if not total > 0:
            raise SolverError(f"units.{self.name}: the mill receives no solids (inflow {total!r} kg/s)")
        if self.needs_water and water is None:
            raise SolverError(f"units.{self.name}: slurry hold-up given but the water through the mill is unknown")
        if is_tanks(self.transport):
            n = self.transport_params["n"]
            if not (isinstance(n, (int, float, np.integer, np.floating)) and float(n) == round(float(n)) and n >= 1):
                raise InputError(f"units.{self.name}.transport.n = {n!r}: a mill with non-linear kinetics solves "
                                 "each tank in turn and needs an integer number of tanks >= 1")
        tau = self.residence_time(total, water)
        kin = self.nonlinear_kinetics(grid, tau, total)
        feed = np.asarray(inflow, float) / total
        unit = f"units.{self.name}"
        c = self.discharge_efficiency(grid)
        d, where = None, None
        if c is not None:  # as in blocks(): d* from the efficiency, retained classes floored at 1e-12
            d = mill_discharge_rates(c)
            trapped = np.flatnonzero((d <= 1e-12) & (kin.S <= 0))
            if trapped.size:
                raise SolverError(f"units.{self.name}: {grid.label(trapped[0])} is retained by the discharge "
                                  "classification and never breaks (S = 0): it can never leave the mill")
            d = np.maximum(d, 1e-12)
            w = self.classification.get("where")
            where = tuple(w) if isinstance(w, list) else w
        try:
            tr = build_transport(self.transport, tau, self.transport_params)
            r = nl.solve_transport(kin, feed, tr, d, where=where, discharge=self.transport_params.get("discharge"),
                                   tol=KINETIC_TOL, holdup=False)
        except MillflowError as exc:
            raise type(exc)(f"{unit}: {exc}") from None
        if not r.error_estimate <= KINETIC_TOL * max(float(feed.sum()), 1.0):
            raise SolverError(f"{unit}: the non-linear mill's error estimate {r.error_estimate:.2g} of its feed is "
                              f"above the tolerance {KINETIC_TOL:g} ({r.method})")
        p = r.product.copy()
        overflow = float(r.overflow_mass)
        if overflow > MAX_OVERFLOW:
            raise SolverError(f"units.{self.name}: {overflow:.3g} of the mill's product aggregates beyond the top "
                              f"of the size grid ({grid.x[0] * 1e6:.4g} um); expected at most {MAX_OVERFLOW:g}: "
                              "raise [grid] top_um so the aggregates are resolved")
        p[0] += overflow
        axis = is_axial(self.transport)
        placed = "" if d is None else (", classification d* along the axis" if axis else ", discharge classification d*"
                                       + ("" if where in (None, "discharge") else f" ({where})"))
        info = {"method": f"non-linear kinetics ({kin.describe()}): {r.method}{placed}",
                "error_estimate": r.error_estimate,
                "residual": r.residual, "runtime_s": time.perf_counter() - t0, "tau_s": tau,
                "overflow_kg_s": total * overflow, **self._basis_info()}
        if overflow > 1e-12:  # above rounding
            info["note"] = (f"{overflow:.2g} of the product aggregated beyond the grid top "
                            f"({grid.x[0] * 1e6:.4g} um); counted in class 1")
        return total * p, info

    def _basis_info(self) -> dict:
        out = {"breakage_basis": ("per energy: S = S^E P / H" if self.breakage_basis == "energy"
                                  else "per time: S in 1/s"),
               "tau_from": self.residence_time_from}
        if self.power_role is not None:
            out["power_role"] = self.power_role
        return out

    @property
    def ports(self) -> tuple[str, ...]:
        """The outlet ports: ``("out",)``."""
        return ("out",)

    @property
    def nonlinear(self) -> bool:
        """True when the mill's block depends on its throughput.

        True when the block depends on the mill's throughput: tau from a hold-up, or rates per energy
        (S = S^E P / H with H = tau F).
        """
        return self.holdup is not None or self.slurry_volume is not None or self.breakage_basis == "energy"

    @property
    def needs_water(self) -> bool:
        """True when the block depends on the water through the mill (slurry hold-up)."""
        return self.slurry_volume is not None

    def discharge_efficiency(self, grid) -> np.ndarray | None:
        """The discharge classification's efficiency on ``grid``, or None."""
        if self.classification is None:
            return None
        params = dict(self.classification)
        params.pop("where", None)
        curve = params.pop("curve")
        return curve_on_grid(lambda x: efficiency(curve, x, **params), grid)

    def residence_time(self, throughput=None, water=None) -> float:
        """Mean residence time tau [s]: given, H / F (solids hold-up), or V / Q (slurry hold-up, Q in m3/s)."""
        if self.tau is not None:
            return float(self.tau)
        if self.slurry_volume is not None:
            Q = self.slurry.volume_flow(float(throughput or 0.0), float(water or 0.0))
            if not Q > 0:
                raise SolverError(f"units.{self.name}: slurry hold-up given but no slurry flows through the mill")
            return float(self.slurry_volume) / Q
        if throughput is None or not throughput > 0:
            raise SolverError(f"units.{self.name}: hold-up given but the throughput is {throughput!r} kg/s; "
                              "the mill receives no solids")
        tau = float(self.holdup) / float(throughput)
        if not math.isfinite(tau):
            raise SolverError(f"units.{self.name}: hold-up {self.holdup:.3g} kg / throughput {throughput:.3g} kg/s "
                              "gives a residence time beyond floating point; expected a finite tau")
        return tau

    def breakage_functions(self, grid, tau=None, throughput=None):
        """S [1/s] and b [-] of this mill on ``grid``.

        (S [1/s], b [-]) on ``grid``: continuous forms class-averaged (or at the upper edges
        on an "upper_edge" grid), a user's discrete S_i, b_ij as given
        (:func:`millflow.breakage.averaged.breakage_on_grid`); rates per energy become
        S = S^E P / H with H = tau F [kg] (the class average of S^E times P / H: the map is linear).
        """
        S, b = self._on_grid(grid)
        if self.breakage_basis == "energy":
            if tau is None or throughput is None or not throughput > 0:
                raise SolverError(f"units.{self.name}: rates per energy need the mill's hold-up, H = tau F; "
                                  f"throughput {throughput!r} kg/s")
            from millflow.breakage.energy import time_rates

            S = time_rates(S, float(self.power), float(tau) * float(throughput))
        return S, b

    def _on_grid(self, grid):
        """S (or S^E) and b of this mill on ``grid``, computed once per grid.

        (S or S^E, b) of this mill's forms on ``grid``, computed once per grid object and kept
        read-only on the unit (a torn mill asks for them at every tear iteration; they do not
        depend on tau or the throughput).
        """
        kept = self.__dict__.get("_grid_forms")
        if kept is not None and kept[0] is grid:
            return kept[1], kept[2]
        S, b, _ = breakage_on_grid(self.rate, self.breakage, grid)
        S, b = np.array(S, dtype=float), np.array(b, dtype=float)
        S.flags.writeable = b.flags.writeable = False
        object.__setattr__(self, "_grid_forms", (grid, S, b))  # a cache, not a field (eq, repr, replace)
        return S, b

    def discretisation(self, grid) -> str:
        """How this mill's breakage is put on ``grid``.

        "class average", "upper edge" or "discrete (as given)"
        (:func:`millflow.breakage.averaged.breakage_on_grid`).
        """
        from millflow.breakage.averaged import continuous_rate

        if continuous_rate(self.rate) is None or not callable(getattr(self.breakage, "cumulative", None)):
            return "discrete (as given)"
        return "class average" if grid.scheme == "class_average" else "upper edge"

    def blocks(self, grid, throughput=None, water=None):
        """The mill's transfer matrix (its block) and its report, at the given throughput [kg/s]."""
        t0 = time.perf_counter()
        tau = self.residence_time(throughput, water)
        S, b = self.breakage_functions(grid, tau, throughput)
        c = self.discharge_efficiency(grid)
        d = None
        if c is not None:
            d = mill_discharge_rates(c)
            trapped = np.flatnonzero((d <= 1e-12) & (S <= 0))
            if trapped.size:
                raise SolverError(f"units.{self.name}: {grid.label(trapped[0])} is retained by the discharge "
                                  "classification and never breaks (S = 0): it can never leave the mill")
            retained = np.flatnonzero(d <= 1e-12)
            d = np.maximum(d, 1e-12)  # c = 1 in floating point: retained, leaves only as breakage products
        try:
            where = None if self.classification is None else self.classification.get("where")
            where = tuple(where) if isinstance(where, list) else where
            P, how = mill_transfer_matrix(S, b, build_transport(self.transport, tau, self.transport_params), d, where,
                                          self.transport_params.get("discharge"))
        except SolverError as exc:
            raise SolverError(f"units.{self.name}: {exc}") from None
        err = float(np.max(np.abs(P.sum(axis=0) - 1.0)))
        if self.transport_note:
            how += f" [{self.transport_note}]"
        placed = "" if d is None else (", classification d* along the axis" if where == "axis"
                                       else ", discharge classification d*")
        info = {"method": how + placed, "error_estimate": err,
                "runtime_s": time.perf_counter() - t0, "tau_s": tau, **self._basis_info()}
        if d is not None and retained.size:  # said, not silent: the floor is far below any rate that matters
            info["note"] = (f"{retained.size} classes retained completely by the discharge (c = 1): their "
                            "discharge rate d* is set to 1e-12; they leave as breakage products")
        return {"out": P}, info


#: Largest fraction of a non-linear mill's product that may aggregate beyond the grid top
#: (it is counted in class 1; more would misstate the coarse end of every PSD downstream).
MAX_OVERFLOW = 1e-3


#: Outlet port names (coarse, fine) of each classifier type.
CLASSIFIER_PORTS = {
    "hydrocyclone": ("underflow", "overflow"),
    "screen": ("oversize", "undersize"),
    "air_separator": ("rejects", "fines"),
}


@dataclass(frozen=True)
class Classifier:
    """Hydrocyclone, screen or air separator: coarse = diag(c) feed, fine = diag(1 - c) feed.

    ``kind`` is a key of :data:`CLASSIFIER_PORTS`; ``curve`` a key of
    :data:`millflow.classifiers.CURVES` with ``params`` (sizes in m). ``water`` says
    where the feed's water goes: ``{"to_coarse": R_f}`` or ``{"coarse_solids_content": p}``
    (:mod:`millflow.flowsheet.water`); a hydrocyclone's default is R_f = its bypass.
    """

    name: str
    kind: str
    curve: str
    params: dict
    water: dict | None = None
    type: ClassVar[str] = "classifier"
    max_inlets: ClassVar[int | None] = None

    @property
    def ports(self) -> tuple[str, ...]:
        """The outlet ports (coarse, fine) of this kind of classifier."""
        return CLASSIFIER_PORTS[self.kind]

    def efficiency(self, grid) -> np.ndarray:
        """Fraction to the coarse stream per class, class-averaged on ``grid``."""
        return curve_on_grid(lambda x: efficiency(self.curve, x, **self.params), grid)

    def blocks(self, grid, throughput=None, water=None):
        """The two diagonal blocks (coarse, fine) and the report."""
        t0 = time.perf_counter()
        c = self.efficiency(grid)
        coarse, fine = self.ports
        return ({coarse: c, fine: 1.0 - c},
                {"method": f"efficiency curve ({self.curve})", "error_estimate": 0.0,
                 "runtime_s": time.perf_counter() - t0})


@dataclass(frozen=True)
class Mixer:
    """Mixer (or a well-mixed tank at steady state, ``holdup`` [kg] for information): out = sum of inlets."""

    name: str
    holdup: float | None = None
    type: ClassVar[str] = "mixer"
    max_inlets: ClassVar[int | None] = None

    @property
    def ports(self) -> tuple[str, ...]:
        """The outlet ports: ``("out",)``."""
        return ("out",)

    def blocks(self, grid, throughput=None, water=None):
        """The identity block (the inlets summed) and the report."""
        return {"out": np.ones(grid.n)}, {"method": "sum", "error_estimate": 0.0, "runtime_s": 0.0}


@dataclass(frozen=True)
class Splitter:
    """Splitter: each outlet port gets a fixed fraction of the mixed feed, same PSD."""

    name: str
    fractions: dict
    type: ClassVar[str] = "splitter"
    max_inlets: ClassVar[int | None] = None

    def __post_init__(self):
        total = math.fsum(self.fractions.values())
        if len(self.fractions) < 2 or abs(total - 1.0) > 1e-12:
            raise InputError(f"units.{self.name}.fractions: {dict(self.fractions)} must name at least two outlets "
                             f"with fractions summing to 1 (sum = {total!r})")

    @property
    def ports(self) -> tuple[str, ...]:
        """The outlet ports, one per fraction."""
        return tuple(self.fractions)

    def blocks(self, grid, throughput=None, water=None):
        """A constant block per outlet (its fraction) and the report."""
        return ({p: np.full(grid.n, float(f)) for p, f in self.fractions.items()},
                {"method": "fixed fractions", "error_estimate": 0.0, "runtime_s": 0.0})


@dataclass(frozen=True)
class Product:
    """Product (a sink of the flowsheet): no outlets."""

    name: str
    type: ClassVar[str] = "product"
    max_inlets: ClassVar[int | None] = None

    @property
    def ports(self) -> tuple[str, ...]:
        """No outlets (a product is a sink)."""
        return ()

    def blocks(self, grid, throughput=None, water=None):
        """No block (a product is a sink)."""
        return {}, {"method": "sink", "error_estimate": 0.0, "runtime_s": 0.0}


#: Unit types by the ``type`` name used in flowsheet files.
#: The earlier name of :class:`MillUnit` (kept so existing scripts run; ``millflow.Mill``
#: is the library's mill, this is the flowsheet unit that holds one).
Mill = MillUnit

UNIT_TYPES = {
    "feed": Feed,
    "mill": MillUnit,
    "hydrocyclone": Classifier,
    "screen": Classifier,
    "air_separator": Classifier,
    "dynamic_classifier": Classifier,
    "mixer": Mixer,
    "tank": Mixer,
    "splitter": Splitter,
    "product": Product,
}
