"""Hydrocyclones predicted from geometry and operation: Plitt's and Nageswararao's models.

Both models are empirical power laws fitted to plant and pilot data. From the cyclone's
geometry (:class:`CycloneGeometry`), the feed slurry (:class:`CycloneFeed`) and either
the feed flow per cyclone or the inlet pressure drop, they predict the corrected cut
size d50c, the pressure-flow relation and the split of slurry and water to the
underflow. Each equation is written in the units of its source (cm, L/min, kPa, % solids
by volume for Plitt; m, kPa, t/m3, m3/h for Nageswararao); arguments and results are SI
and are converted only at the function boundary.

Plitt, revised form (Flintoff, Plitt & Turak 1987; Napier-Munn et al. 1996 ch. 10;
King 2001 ch. 5). Lengths D_c, D_i, D_o, D_u, h [cm], Q [L/min], phi [% by volume],
mu [mPa s = cP], rho [g/cm3], P [kPa], H = P / (rho_p g) [m of slurry], d50c [um]::

    d50c = F1 39.7 D_c^0.46 D_i^0.6 D_o^1.21 mu^0.5 exp(0.063 phi)
           / (D_u^0.71 h^0.38 Q^0.45 ((rho_s - rho_l)/1.6)^k)            k = 0.5
    P    = F2 1.88 Q^1.78 exp(0.0055 phi) / (D_c^0.37 D_i^0.94 h^0.28 (D_u^2 + D_o^2)^0.87)
    S    = F3 1.9 (D_u/D_o)^3.31 h^0.54 (D_u^2 + D_o^2)^0.36 exp(0.0054 phi) / (H^0.24 D_c^1.11)
    m    = F4 1.94 exp(-1.58 S/(1 + S)) (D_c^2 h / Q)^0.15

S = Q_u/Q_o is the split of slurry volume; R_v = S/(1 + S) the slurry volume to the
underflow. The water split R_f follows from the volume balance R_v = (1 - phi) R_f +
phi R_s once the solids recovery R_s to underflow is known, either given or from the
feed size distribution, R_s = R_f + (1 - R_f) C with C = sum_i w_i c_corr,i, which
gives R_f = (R_v - phi C)/(1 - phi C) in closed form.

Nageswararao (1978), JKSimMet form (Napier-Munn et al. 1996 ch. 10; Nageswararao,
Wiseman & Napier-Munn 2004). D_c, D_o, D_u, D_i, L_c [m], theta [deg], P [kPa],
rho_p [t/m3], g = 9.81 m/s2 (so P/(rho_p g D_c) is a pure number), Q [m3/h], d50c [um],
R_f and R_v [%], lambda = 10^(1.82 C_v) / (8.05 (1 - C_v)^2) the hindered-settling term::

    d50c = K_D0 D_c^0.35 (D_o/D_c)^0.52 (D_u/D_c)^-0.47 lambda^0.93 (P/(rho_p g D_c))^-0.22
           (D_i/D_c)^-0.50 (L_c/D_c)^0.20 theta^0.15
    Q    = K_Q0 D_c^1.9 (P/rho_p)^0.5 (D_o/D_c)^0.68 (D_i/D_c)^0.45 (L_c/D_c)^0.20 theta^-0.10
    R_v  = K_V1 (D_o/D_c)^-0.94 (D_u/D_c)^1.83 (P/(rho_p g D_c))^-0.31 (D_i/D_c)^-0.25
           (L_c/D_c)^0.22 theta^-0.24
    R_f  = K_W1 (D_o/D_c)^-1.19 (D_u/D_c)^2.40 (P/(rho_p g D_c))^-0.53 lambda^0.27
           (D_i/D_c)^-0.50 (L_c/D_c)^0.22 theta^-0.24

The K constants depend on the ore and on the units above; the defaults of
:class:`NageswararaoConstants` are illustrative magnitudes, not values from the sources.
R_v has no lambda term, as in the public implementations we compared with. Some
implementations write the capacity with the head ratio, (P/(rho_p g D_c))^0.5, instead of
(P/rho_p)^0.5: that changes what K_Q0 means, not the trends.

Either model gives a :class:`CyclonePrediction`, whose :meth:`~CyclonePrediction.efficiency`
is the actual curve c = R_f + (1 - R_f) c_corr (the water split as bypass) through
:func:`millflow.classifiers.plitt` (Plitt) or :func:`millflow.classifiers.whiten`
(Nageswararao, sharpness alpha).

References: Plitt, CIM Bull. 69(776) (1976) 114-123; Flintoff, Plitt & Turak, CIM Bull.
80(905) (1987) 39-50; Nageswararao, PhD thesis, Univ. of Queensland (1978); Napier-Munn,
Morrell, Morrison & Kojovic, Mineral Comminution Circuits (JKMRC, 1996) ch. 10;
Nageswararao, Wiseman & Napier-Munn, Miner. Eng. 17 (2004) 671-687; King, Modeling and
Simulation of Mineral Processing Systems (2001) ch. 5.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from millflow.classifiers import plitt, whiten
from millflow.errors import InputError
from millflow.grid import as_sizes

__all__ = ["CycloneGeometry", "CycloneFeed", "PlittCalibration", "NageswararaoConstants", "CyclonePrediction",
           "slurry_flow", "hindered_settling_factor",
           "plitt_d50c", "plitt_pressure", "plitt_flow", "plitt_split", "plitt_sharpness",
           "plitt_water_split", "plitt_cyclone",
           "nageswararao_d50c", "nageswararao_flow", "nageswararao_pressure", "nageswararao_volume_recovery",
           "nageswararao_water_recovery", "nageswararao_cyclone", "ValidityRange", "VALIDITY", "out_of_range",
           "describe_out_of_range", "illustrative_constants"]

G = 9.81  # [m/s2], as in the sources (Napier-Munn et al. 1996; Plitt's head H)


def _positive(value, name: str, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {name} = {value!r}; expected a finite number > 0") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{where}: {name} = {value!r}; expected a finite number > 0")
    return v


def _positive_fields(obj) -> None:
    """Every field of a frozen dataclass of constants checked finite and > 0 (stored as float)."""
    for f in fields(obj):
        object.__setattr__(obj, f.name, _positive(getattr(obj, f.name), f.name, type(obj).__name__))


def _open_fraction(value, name: str, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {name} = {value!r}; expected a fraction in (0, 1)") from None
    if not (math.isfinite(v) and 0.0 < v < 1.0):
        raise InputError(f"{where}: {name} = {value!r}; expected a fraction in (0, 1)")
    return v


# ------------------------------------------------------------------------------ inputs

@dataclass(frozen=True)
class CycloneGeometry:
    """Dimensions of one hydrocyclone [m]; the cone angle [deg].

    ``diameter_m`` D_c (cylinder), ``inlet_diameter_m`` D_i (diameter of a circle of
    the inlet's area), ``vortex_finder_m`` D_o, ``apex_m`` D_u (spigot),
    ``free_vortex_height_m`` h (bottom of the vortex finder to the apex; Plitt),
    ``cylinder_length_m`` L_c and ``cone_angle_deg`` theta (full angle; Nageswararao,
    which needs both). Checked on construction: every size finite and > 0, D_i, D_o < D_c,
    D_u < D_o, 0 < theta < 180.
    """

    diameter_m: float
    inlet_diameter_m: float
    vortex_finder_m: float
    apex_m: float
    free_vortex_height_m: float
    cone_angle_deg: float | None = None
    cylinder_length_m: float | None = None

    def __post_init__(self):
        where = "CycloneGeometry"
        for name in ("diameter_m", "inlet_diameter_m", "vortex_finder_m", "apex_m", "free_vortex_height_m"):
            object.__setattr__(self, name, _positive(getattr(self, name), name, where))
        if self.cylinder_length_m is not None:
            object.__setattr__(self, "cylinder_length_m",
                               _positive(self.cylinder_length_m, "cylinder_length_m", where))
        if self.cone_angle_deg is not None:
            theta = _positive(self.cone_angle_deg, "cone_angle_deg", where)
            if theta >= 180.0:
                raise InputError(f"{where}: cone_angle_deg = {theta!r}; expected a full cone angle in (0, 180) deg")
            object.__setattr__(self, "cone_angle_deg", theta)
        dc = self.diameter_m
        for name in ("inlet_diameter_m", "vortex_finder_m"):
            if getattr(self, name) >= dc:
                raise InputError(f"{where}: {name} = {getattr(self, name)!r}; expected less than "
                                 f"diameter_m = {dc!r}")
        if self.apex_m >= self.vortex_finder_m:
            raise InputError(f"{where}: apex_m = {self.apex_m!r}; expected less than "
                             f"vortex_finder_m = {self.vortex_finder_m!r} (apex smaller than vortex finder)")


@dataclass(frozen=True)
class CycloneFeed:
    """Feed slurry: solids volume fraction phi_v [-] in (0, 1), solids and liquid densities
    [kg/m3] (rho_s > rho_l) and liquid viscosity [Pa s].

    :meth:`from_flows` builds it from the feed water and solids flows.
    """

    solids_volume_fraction: float
    solids_density_kg_m3: float
    liquid_density_kg_m3: float = 1000.0
    viscosity_Pa_s: float = 1.0e-3

    def __post_init__(self):
        where = "CycloneFeed"
        object.__setattr__(self, "solids_volume_fraction",
                           _open_fraction(self.solids_volume_fraction, "solids_volume_fraction", where))
        for name in ("solids_density_kg_m3", "liquid_density_kg_m3", "viscosity_Pa_s"):
            object.__setattr__(self, name, _positive(getattr(self, name), name, where))
        if self.solids_density_kg_m3 <= self.liquid_density_kg_m3:
            raise InputError(f"{where}: solids_density_kg_m3 = {self.solids_density_kg_m3!r}; expected more than "
                             f"liquid_density_kg_m3 = {self.liquid_density_kg_m3!r}")

    @property
    def slurry_density_kg_m3(self) -> float:
        """rho_p = phi rho_s + (1 - phi) rho_l [kg/m3]."""
        phi = self.solids_volume_fraction
        return phi * self.solids_density_kg_m3 + (1.0 - phi) * self.liquid_density_kg_m3

    @classmethod
    def from_flows(cls, water_kg_s: float, solids_kg_s: float, solids_density_kg_m3: float,
                   liquid_density_kg_m3: float = 1000.0, viscosity_Pa_s: float = 1.0e-3) -> CycloneFeed:
        """Feed of ``water_kg_s`` liquid and ``solids_kg_s`` solids [kg/s]:
        phi_v = (M_s/rho_s) / (M_s/rho_s + M_w/rho_l)."""
        w = _positive(water_kg_s, "water_kg_s", "CycloneFeed.from_flows")
        s = _positive(solids_kg_s, "solids_kg_s", "CycloneFeed.from_flows")
        rs = _positive(solids_density_kg_m3, "solids_density_kg_m3", "CycloneFeed.from_flows")
        rl = _positive(liquid_density_kg_m3, "liquid_density_kg_m3", "CycloneFeed.from_flows")
        return cls(s / rs / (s / rs + w / rl), rs, rl, viscosity_Pa_s)


def slurry_flow(water_kg_s: float, solids_kg_s: float, solids_density_kg_m3: float,
                liquid_density_kg_m3: float = 1000.0) -> float:
    """Slurry volume flow Q = M_w/rho_l + M_s/rho_s [m3/s] of a feed given as mass flows [kg/s]."""
    where = "slurry_flow"
    return (_positive(water_kg_s, "water_kg_s", where) / _positive(liquid_density_kg_m3, "liquid_density_kg_m3", where)
            + _positive(solids_kg_s, "solids_kg_s", where) / _positive(solids_density_kg_m3, "solids_density_kg_m3",
                                                                       where))


def _operating_point(flow_m3_s, pressure_Pa, where: str) -> tuple[float | None, float | None]:
    if (flow_m3_s is None) == (pressure_Pa is None):
        raise InputError(f"{where}: give exactly one of flow_m3_s (feed flow per cyclone [m3/s]) and "
                         f"pressure_Pa (inlet pressure drop [Pa]); got flow_m3_s = {flow_m3_s!r}, "
                         f"pressure_Pa = {pressure_Pa!r}")
    if flow_m3_s is not None:
        return _positive(flow_m3_s, "flow_m3_s", where), None
    return None, _positive(pressure_Pa, "pressure_Pa", where)


# ------------------------------------------------------------------------------ result

@dataclass(frozen=True)
class CyclonePrediction:
    """What a cyclone model predicts at one operating point (SI units).

    ``d50c_m`` corrected cut size [m]; ``sharpness`` m of the Plitt curve or alpha of
    the Whiten curve, as ``curve`` says; ``pressure_Pa`` and ``flow_m3_s`` the operating
    point (per cyclone); ``water_split`` R_f, the fraction of the feed water (and the
    bypass of every size) to underflow [-]; ``volume_split`` S = Q_u/Q_o of slurry [-];
    ``model`` the model's name; ``calibration`` the factors or constants used.
    """

    model: str
    d50c_m: float
    sharpness: float
    curve: str
    pressure_Pa: float
    flow_m3_s: float
    water_split: float
    volume_split: float
    calibration: object

    @property
    def volume_recovery(self) -> float:
        """R_v = S/(1 + S): fraction of the feed slurry volume to the underflow [-]."""
        return self.volume_split / (1.0 + self.volume_split)

    def efficiency(self, x_m) -> np.ndarray:
        """Actual partition to underflow c_i = R_f + (1 - R_f) c_corr(x_i) at sizes ``x_m`` [m]."""
        if self.curve == "plitt":
            return plitt(x_m, self.d50c_m, self.sharpness, bypass=self.water_split)
        return whiten(x_m, self.d50c_m, self.sharpness, bypass=self.water_split)


# ------------------------------------------------------------------------------ Plitt

@dataclass(frozen=True)
class PlittCalibration:
    """Plitt's calibration factors F1 (d50c), F2 (pressure), F3 (split), F4 (sharpness), all 1
    for the uncalibrated model and fitted to a plant survey in practice; ``density_exponent`` k of
    the density term ((rho_s - rho_l)/1.6)^k, 0.5 in the revised model (Flintoff et al. 1987)."""

    F1: float = 1.0
    F2: float = 1.0
    F3: float = 1.0
    F4: float = 1.0
    density_exponent: float = 0.5

    def __post_init__(self):
        _positive_fields(self)


def _cm(geometry: CycloneGeometry) -> tuple[float, float, float, float, float]:
    g = geometry
    return (100.0 * g.diameter_m, 100.0 * g.inlet_diameter_m, 100.0 * g.vortex_finder_m, 100.0 * g.apex_m,
            100.0 * g.free_vortex_height_m)


def _plitt_pressure_coefficient(geometry: CycloneGeometry, feed: CycloneFeed, cal: PlittCalibration) -> float:
    """P [kPa] = coefficient * Q[L/min]^1.78."""
    dc, di, do, du, h = _cm(geometry)
    phi = 100.0 * feed.solids_volume_fraction
    return cal.F2 * 1.88 * math.exp(0.0055 * phi) / (dc ** 0.37 * di ** 0.94 * h ** 0.28 * (du ** 2 + do ** 2) ** 0.87)


def plitt_d50c(geometry: CycloneGeometry, feed: CycloneFeed, flow_m3_s: float,
               calibration: PlittCalibration = PlittCalibration()) -> float:
    """Corrected cut size d50c [m] by Plitt's revised equation (module docstring).

    d50c[um] = F1 39.7 D_c^0.46 D_i^0.6 D_o^1.21 mu^0.5 e^(0.063 phi) / (D_u^0.71 h^0.38 Q^0.45
    ((rho_s - rho_l)/1.6)^k), lengths [cm], Q [L/min], mu [cP], phi [% v/v], rho [g/cm3].
    ``flow_m3_s`` is the feed flow per cyclone [m3/s].
    """
    q = 6.0e4 * _positive(flow_m3_s, "flow_m3_s", "plitt_d50c")
    dc, di, do, du, h = _cm(geometry)
    phi = 100.0 * feed.solids_volume_fraction
    mu_cp = 1.0e3 * feed.viscosity_Pa_s
    drho = (feed.solids_density_kg_m3 - feed.liquid_density_kg_m3) / 1000.0
    d50_um = (calibration.F1 * 39.7 * dc ** 0.46 * di ** 0.6 * do ** 1.21 * mu_cp ** 0.5 * math.exp(0.063 * phi)
              / (du ** 0.71 * h ** 0.38 * q ** 0.45 * (drho / 1.6) ** calibration.density_exponent))
    return 1.0e-6 * d50_um


def plitt_pressure(geometry: CycloneGeometry, feed: CycloneFeed, flow_m3_s: float,
                   calibration: PlittCalibration = PlittCalibration()) -> float:
    """Inlet pressure drop [Pa] at feed flow ``flow_m3_s`` [m3/s] per cyclone.

    P[kPa] = F2 1.88 Q^1.78 e^(0.0055 phi) / (D_c^0.37 D_i^0.94 h^0.28 (D_u^2 + D_o^2)^0.87),
    lengths [cm], Q [L/min], phi [% v/v].
    """
    q = 6.0e4 * _positive(flow_m3_s, "flow_m3_s", "plitt_pressure")
    return 1.0e3 * _plitt_pressure_coefficient(geometry, feed, calibration) * q ** 1.78


def plitt_flow(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
               calibration: PlittCalibration = PlittCalibration()) -> float:
    """Feed flow per cyclone [m3/s] that gives the pressure drop ``pressure_Pa`` [Pa]:
    the pressure equation of :func:`plitt_pressure` solved for Q, Q = (P / coefficient)^(1/1.78)."""
    p_kpa = 1.0e-3 * _positive(pressure_Pa, "pressure_Pa", "plitt_flow")
    q = (p_kpa / _plitt_pressure_coefficient(geometry, feed, calibration)) ** (1.0 / 1.78)
    return q / 6.0e4


def plitt_split(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
                calibration: PlittCalibration = PlittCalibration()) -> float:
    """Volume split S = Q_u/Q_o of slurry [-] at the pressure drop ``pressure_Pa`` [Pa].

    S = F3 1.9 (D_u/D_o)^3.31 h^0.54 (D_u^2 + D_o^2)^0.36 e^(0.0054 phi) / (H^0.24 D_c^1.11),
    lengths [cm], phi [% v/v], H = P/(rho_p g) the feed head [m of slurry].
    """
    head_m = _positive(pressure_Pa, "pressure_Pa", "plitt_split") / (feed.slurry_density_kg_m3 * G)
    dc, _, do, du, h = _cm(geometry)
    phi = 100.0 * feed.solids_volume_fraction
    return (calibration.F3 * 1.9 * (du / do) ** 3.31 * h ** 0.54 * (du ** 2 + do ** 2) ** 0.36 * math.exp(0.0054 * phi)
            / (head_m ** 0.24 * dc ** 1.11))


def plitt_sharpness(geometry: CycloneGeometry, flow_m3_s: float, volume_split: float,
                    calibration: PlittCalibration = PlittCalibration()) -> float:
    """Sharpness m [-] of the Plitt (Rosin-Rammler) curve.

    m = F4 1.94 exp(-1.58 S/(1 + S)) (D_c^2 h / Q)^0.15, lengths [cm], Q [L/min].
    """
    q = 6.0e4 * _positive(flow_m3_s, "flow_m3_s", "plitt_sharpness")
    s = _positive(volume_split, "volume_split", "plitt_sharpness")
    dc, _, _, _, h = _cm(geometry)
    return calibration.F4 * 1.94 * math.exp(-1.58 * s / (1.0 + s)) * (dc ** 2 * h / q) ** 0.15


def plitt_water_split(volume_split: float, solids_volume_fraction: float, *, solids_recovery: float | None = None,
                      corrected_recovery: float | None = None) -> float:
    """Water split R_f [-] from the slurry volume balance R_v = (1 - phi) R_f + phi R_s.

    With the solids recovery R_s to underflow: R_f = (R_v - phi R_s)/(1 - phi). With the
    feed-weighted corrected curve C = sum_i w_i c_corr,i instead (R_s = R_f + (1 - R_f) C):
    R_f = (R_v - phi C)/(1 - phi C). R_v = S/(1 + S). A result outside [0, 1) means the
    slurry split cannot carry that much solids: an InputError, never clipped.
    """
    where = "plitt_water_split"
    s = _positive(volume_split, "volume_split", where)
    phi = _open_fraction(solids_volume_fraction, "solids_volume_fraction", where)
    if (solids_recovery is None) == (corrected_recovery is None):
        raise InputError(f"{where}: give exactly one of solids_recovery (R_s [-]) and corrected_recovery "
                         f"(C = sum w_i c_corr,i [-])")
    rv = s / (1.0 + s)
    if solids_recovery is not None:
        rs = float(solids_recovery)
        if not (math.isfinite(rs) and 0.0 <= rs <= 1.0):
            raise InputError(f"{where}: solids_recovery = {solids_recovery!r}; expected a fraction in [0, 1]")
        rf = (rv - phi * rs) / (1.0 - phi)
    else:
        c = float(corrected_recovery)
        if not (math.isfinite(c) and 0.0 <= c <= 1.0):
            raise InputError(f"{where}: corrected_recovery = {corrected_recovery!r}; expected a fraction in [0, 1]")
        rf = (rv - phi * c) / (1.0 - phi * c)
    if not (0.0 <= rf < 1.0):
        raise InputError(f"{where}: the volume split S = {s:.4g} (R_v = {rv:.4g}) with phi = {phi:.4g} gives a water "
                         f"split R_f = {rf:.4g}; expected 0 <= R_f < 1 (the underflow cannot hold the solids "
                         f"sent to it: check apex, flow or F3)")
    return rf


def plitt_cyclone(geometry: CycloneGeometry, feed: CycloneFeed, *, flow_m3_s: float | None = None,
                  pressure_Pa: float | None = None, calibration: PlittCalibration = PlittCalibration(),
                  solids_recovery: float | None = None, x_m=None, feed_fractions=None,
                  corrected_recovery: float | None = None) -> CyclonePrediction:
    """Plitt's model at one operating point: give the feed flow per cyclone ``flow_m3_s`` [m3/s]
    or the pressure drop ``pressure_Pa`` [Pa] (the other follows from the pressure equation).

    The water split needs the solids to underflow: either ``solids_recovery`` R_s [-], or the
    feed size distribution, sizes ``x_m`` [m] (decreasing) and mass fractions ``feed_fractions``
    [-] (summing to 1), or directly C = sum_i w_i c_corr,i (``corrected_recovery`` [-], as a
    flowsheet tears it), from which R_f follows in closed form (:func:`plitt_water_split`).
    """
    where = "plitt_cyclone"
    flow, pressure = _operating_point(flow_m3_s, pressure_Pa, where)
    if flow is None:
        flow = plitt_flow(geometry, feed, pressure, calibration)
    else:
        pressure = plitt_pressure(geometry, feed, flow, calibration)
    d50c = plitt_d50c(geometry, feed, flow, calibration)
    s = plitt_split(geometry, feed, pressure, calibration)
    m = plitt_sharpness(geometry, flow, s, calibration)
    phi = feed.solids_volume_fraction
    if corrected_recovery is not None:
        if solids_recovery is not None or x_m is not None or feed_fractions is not None:
            raise InputError(f"{where}: give one of solids_recovery, corrected_recovery or x_m with feed_fractions")
        rf = plitt_water_split(s, phi, corrected_recovery=corrected_recovery)
    elif x_m is not None or feed_fractions is not None:
        if solids_recovery is not None or x_m is None or feed_fractions is None:
            raise InputError(f"{where}: give either solids_recovery or both x_m and feed_fractions")
        c = float(np.dot(_fractions(feed_fractions, as_sizes(x_m), where), plitt(x_m, d50c, m)))
        rf = plitt_water_split(s, phi, corrected_recovery=c)
    elif solids_recovery is not None:
        rf = plitt_water_split(s, phi, solids_recovery=solids_recovery)
    else:
        raise InputError(f"{where}: the water split R_f needs the solids to underflow: give solids_recovery "
                         f"(R_s [-]) or the feed PSD (x_m [m] and feed_fractions [-])")
    return CyclonePrediction("plitt", d50c, m, "plitt", pressure, flow, rf, s, calibration)


def _fractions(w, x: np.ndarray, where: str) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    if w.shape != x.shape or not np.all(np.isfinite(w)) or np.any(w < 0) or abs(w.sum() - 1.0) > 1e-6:
        raise InputError(f"{where}: feed_fractions must be {x.size} finite mass fractions >= 0 (one per size in "
                         f"x_m) summing to 1; got shape {w.shape}, sum {w.sum() if w.size else 0.0:.6g}")
    return w


# ------------------------------------------------------------------------------ Nageswararao

@dataclass(frozen=True)
class NageswararaoConstants:
    """Ore- and unit-dependent constants of Nageswararao's model, for the units of the module
    docstring (D_c [m], P [kPa], rho_p [t/m3], Q [m3/h], d50c [um], R_f and R_v [%]).

    K_D0 (cut size), K_Q0 (capacity), K_V1 (slurry recovery), K_W1 (water recovery) are fitted
    to a survey of the plant's own cyclones; the defaults 150, 185, 573.1 and 1062 are only
    illustrative magnitudes (a 0.5 m cyclone at 100 kPa and 20 % solids by volume gets
    d50c ~ 125 um, Q ~ 155 m3/h, R_f ~ 15 %, R_v ~ 28 %), not values from the sources.
    ``alpha`` is the sharpness of the Whiten curve (typically 2-5).
    """

    K_D0: float = 150.0
    K_Q0: float = 185.0
    K_V1: float = 573.1
    K_W1: float = 1062.0
    alpha: float = 3.0

    def __post_init__(self):
        _positive_fields(self)


def hindered_settling_factor(solids_volume_fraction: float) -> float:
    """lambda = 10^(1.82 C_v) / (8.05 (1 - C_v)^2) [-], C_v the solids volume fraction (Nageswararao)."""
    cv = _open_fraction(solids_volume_fraction, "solids_volume_fraction", "hindered_settling_factor")
    return 10.0 ** (1.82 * cv) / (8.05 * (1.0 - cv) ** 2)


def _nage_ratios(geometry: CycloneGeometry, where: str) -> tuple[float, float, float, float, float, float]:
    g = geometry
    if g.cone_angle_deg is None or g.cylinder_length_m is None:
        raise InputError(f"{where}: Nageswararao's model needs cone_angle_deg and cylinder_length_m in the "
                         f"CycloneGeometry; got cone_angle_deg = {g.cone_angle_deg!r}, "
                         f"cylinder_length_m = {g.cylinder_length_m!r}")
    dc = g.diameter_m
    return dc, g.vortex_finder_m / dc, g.apex_m / dc, g.inlet_diameter_m / dc, g.cylinder_length_m / dc, \
        g.cone_angle_deg


def _head_ratio(pressure_Pa: float, feed: CycloneFeed, dc: float, where: str) -> float:
    """P/(rho_p g D_c) [-]: the feed head in cyclone diameters."""
    return _positive(pressure_Pa, "pressure_Pa", where) / (feed.slurry_density_kg_m3 * G * dc)


def nageswararao_d50c(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
                      constants: NageswararaoConstants = NageswararaoConstants()) -> float:
    """Corrected cut size d50c [m] at the pressure drop ``pressure_Pa`` [Pa].

    d50c[um] = K_D0 D_c^0.35 (D_o/D_c)^0.52 (D_u/D_c)^-0.47 lambda^0.93 (P/(rho_p g D_c))^-0.22
    (D_i/D_c)^-0.50 (L_c/D_c)^0.20 theta^0.15, D_c [m], theta [deg].
    """
    where = "nageswararao_d50c"
    dc, ro, ru, ri, rl, theta = _nage_ratios(geometry, where)
    lam = hindered_settling_factor(feed.solids_volume_fraction)
    d50_um = (constants.K_D0 * dc ** 0.35 * ro ** 0.52 * ru ** -0.47 * lam ** 0.93
              * _head_ratio(pressure_Pa, feed, dc, where) ** -0.22 * ri ** -0.50 * rl ** 0.20 * theta ** 0.15)
    return 1.0e-6 * d50_um


def _nage_capacity(geometry: CycloneGeometry, constants: NageswararaoConstants, where: str) -> float:
    """Q[m3/h] = capacity * (P[kPa]/rho_p[t/m3])^0.5."""
    dc, ro, _, ri, rl, theta = _nage_ratios(geometry, where)
    return constants.K_Q0 * dc ** 1.9 * ro ** 0.68 * ri ** 0.45 * rl ** 0.20 * theta ** -0.10


def nageswararao_flow(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
                      constants: NageswararaoConstants = NageswararaoConstants()) -> float:
    """Feed flow per cyclone [m3/s] at the pressure drop ``pressure_Pa`` [Pa].

    Q[m3/h] = K_Q0 D_c^1.9 (P/rho_p)^0.5 (D_o/D_c)^0.68 (D_i/D_c)^0.45 (L_c/D_c)^0.20 theta^-0.10,
    P [kPa], rho_p [t/m3], D_c [m].
    """
    where = "nageswararao_flow"
    p_kpa = 1.0e-3 * _positive(pressure_Pa, "pressure_Pa", where)
    return _nage_capacity(geometry, constants, where) * (p_kpa / (1.0e-3 * feed.slurry_density_kg_m3)) ** 0.5 / 3600.0


def nageswararao_pressure(geometry: CycloneGeometry, feed: CycloneFeed, flow_m3_s: float,
                          constants: NageswararaoConstants = NageswararaoConstants()) -> float:
    """Pressure drop [Pa] at the feed flow ``flow_m3_s`` [m3/s] per cyclone: the capacity
    equation of :func:`nageswararao_flow` solved for P, P = rho_p (Q / (K_Q0 D_c^1.9 ...))^2."""
    where = "nageswararao_pressure"
    q_m3h = 3600.0 * _positive(flow_m3_s, "flow_m3_s", where)
    p_kpa = 1.0e-3 * feed.slurry_density_kg_m3 * (q_m3h / _nage_capacity(geometry, constants, where)) ** 2
    return 1.0e3 * p_kpa


def nageswararao_volume_recovery(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
                                 constants: NageswararaoConstants = NageswararaoConstants()) -> float:
    """Fraction R_v of the feed slurry volume to underflow [-] (the equation gives %).

    R_v[%] = K_V1 (D_o/D_c)^-0.94 (D_u/D_c)^1.83 (P/(rho_p g D_c))^-0.31 (D_i/D_c)^-0.25
    (L_c/D_c)^0.22 theta^-0.24.
    """
    where = "nageswararao_volume_recovery"
    dc, ro, ru, ri, rl, theta = _nage_ratios(geometry, where)
    rv = 0.01 * (constants.K_V1 * ro ** -0.94 * ru ** 1.83 * _head_ratio(pressure_Pa, feed, dc, where) ** -0.31
                 * ri ** -0.25 * rl ** 0.22 * theta ** -0.24)
    return _recovery(rv, "R_v", where)


def nageswararao_water_recovery(geometry: CycloneGeometry, feed: CycloneFeed, pressure_Pa: float,
                                constants: NageswararaoConstants = NageswararaoConstants()) -> float:
    """Fraction R_f of the feed water to underflow [-] (the equation gives %).

    R_f[%] = K_W1 (D_o/D_c)^-1.19 (D_u/D_c)^2.40 (P/(rho_p g D_c))^-0.53 lambda^0.27
    (D_i/D_c)^-0.50 (L_c/D_c)^0.22 theta^-0.24.
    """
    where = "nageswararao_water_recovery"
    dc, ro, ru, ri, rl, theta = _nage_ratios(geometry, where)
    lam = hindered_settling_factor(feed.solids_volume_fraction)
    rf = 0.01 * (constants.K_W1 * ro ** -1.19 * ru ** 2.40 * _head_ratio(pressure_Pa, feed, dc, where) ** -0.53
                 * lam ** 0.27 * ri ** -0.50 * rl ** 0.22 * theta ** -0.24)
    return _recovery(rf, "R_f", where)


def _recovery(r: float, name: str, where: str) -> float:
    if not (0.0 <= r < 1.0):
        raise InputError(f"{where}: {name} = {100 * r:.4g} %; expected 0 <= {name} < 100 % (the operating point is "
                         f"outside the model: check apex, pressure or the K constants)")
    return r


def nageswararao_cyclone(geometry: CycloneGeometry, feed: CycloneFeed, *, flow_m3_s: float | None = None,
                         pressure_Pa: float | None = None,
                         constants: NageswararaoConstants = NageswararaoConstants()) -> CyclonePrediction:
    """Nageswararao's model at one operating point: give the feed flow per cyclone ``flow_m3_s``
    [m3/s] or the pressure drop ``pressure_Pa`` [Pa]. The volume split is S = R_v/(1 - R_v)
    and the curve is Whiten's with ``constants.alpha``."""
    where = "nageswararao_cyclone"
    flow, pressure = _operating_point(flow_m3_s, pressure_Pa, where)
    if flow is None:
        flow = nageswararao_flow(geometry, feed, pressure, constants)
    else:
        pressure = nageswararao_pressure(geometry, feed, flow, constants)
    rv = nageswararao_volume_recovery(geometry, feed, pressure, constants)
    rf = nageswararao_water_recovery(geometry, feed, pressure, constants)
    return CyclonePrediction("nageswararao", nageswararao_d50c(geometry, feed, pressure, constants), constants.alpha,
                             "whiten", pressure, flow, rf, rv / (1.0 - rv), constants)


# ------------------------------------------------------------------------------ range of use

@dataclass(frozen=True)
class ValidityRange:
    """Where a cyclone model is used with confidence: closed intervals (low, high), each with
    the basis it rests on (``basis``: quantity -> source, or "judgment").

    ``pressure_kPa`` inlet pressure drop; ``feed_solids_pct_v`` feed solids [% by volume];
    ``underflow_solids_pct_v`` the roping limit of the underflow: above about 50-55 % solids by
    volume the underflow no longer sprays but ropes, the air core collapses and coarse solids
    report to the overflow, which neither model describes (Plitt, Conil and Broussaud, Miner.
    Eng. 3 (1990), put the roping onset near 56 % v/v; 50 % keeps a margin); ``diameter_mm`` the
    cyclone diameter D_c. Geometry ratios to D_c: ``inlet_ratio`` D_i/D_c, ``vortex_finder_ratio``
    D_o/D_c, ``apex_ratio`` D_u/D_c; ``apex_to_vortex`` D_u/D_o.

    Each model has its own range (:data:`VALIDITY`). A plant survey of the cyclones themselves is
    the better guide: pass a tighter or wider range where it is known.
    """

    pressure_kPa: tuple = (40.0, 200.0)
    feed_solids_pct_v: tuple = (1.0, 35.0)
    underflow_solids_pct_v: tuple = (0.0, 50.0)
    diameter_mm: tuple = (50.0, 800.0)
    inlet_ratio: tuple = (0.1, 0.4)
    vortex_finder_ratio: tuple = (0.2, 0.45)
    apex_ratio: tuple = (0.05, 0.35)
    apex_to_vortex: tuple = (0.2, 0.9)
    basis: tuple = ()   # ((quantity, where the bounds come from), ...)

    def source(self, quantity: str) -> str:
        """Where the bounds of ``quantity`` come from ("judgment" when no source is given)."""
        return dict(self.basis).get(quantity, "judgment")


_JUDGMENT_ENVELOPE = ("judgment: the envelope of conventional mineral-processing cyclones (Napier-Munn et al. "
                      "1996 ch. 10; King 2001 ch. 5), not the fitted data's exact envelope")
_ROPING = "roping onset near 56 % v/v (Plitt, Conil and Broussaud 1990), 50 % for a margin"

#: Range of use of each model, with the basis of each bound. The two models were fitted to
#: different data: Nageswararao's to Krebs cyclones of 102-381 mm (4-15 in) on limestone
#: (Nageswararao 1978, as summarised by Napier-Munn et al. 1996 ch. 10 and Nageswararao, Wiseman
#: and Napier-Munn 2004; recalled from those summaries, not re-read here), so its diameter range
#: is that data base's, rounded outward; Plitt's revised model (Flintoff, Plitt and Turak 1987)
#: was calibrated on laboratory to industrial cyclones, and its 50-800 mm is a judgment of that
#: span, not a published bound. Pressure, feed solids and geometry ratios are judgments of
#: conventional operation for both.
VALIDITY = {
    "plitt": ValidityRange(
        diameter_mm=(50.0, 800.0),
        basis=(("pressure_kPa", _JUDGMENT_ENVELOPE), ("feed_solids_pct_v", _JUDGMENT_ENVELOPE),
               ("underflow_solids_pct_v", _ROPING),
               ("diameter_mm", "judgment: the laboratory-to-industrial span of the revised model's calibration "
                               "(Flintoff, Plitt and Turak 1987); no published bound"),
               ("inlet_ratio", _JUDGMENT_ENVELOPE), ("vortex_finder_ratio", _JUDGMENT_ENVELOPE),
               ("apex_ratio", _JUDGMENT_ENVELOPE), ("apex_to_vortex", _JUDGMENT_ENVELOPE))),
    "nageswararao": ValidityRange(
        diameter_mm=(100.0, 400.0),
        basis=(("pressure_kPa", _JUDGMENT_ENVELOPE), ("feed_solids_pct_v", _JUDGMENT_ENVELOPE),
               ("underflow_solids_pct_v", _ROPING),
               ("diameter_mm", "the model's data base: Krebs cyclones of 102-381 mm (Nageswararao 1978; "
                               "Napier-Munn et al. 1996 ch. 10), rounded outward"),
               ("inlet_ratio", _JUDGMENT_ENVELOPE), ("vortex_finder_ratio", _JUDGMENT_ENVELOPE),
               ("apex_ratio", _JUDGMENT_ENVELOPE), ("apex_to_vortex", _JUDGMENT_ENVELOPE))),
}

_RANGE_NAMES = {"pressure_kPa": ("pressure", "kPa"), "feed_solids_pct_v": ("feed solids", "% v/v"),
                "underflow_solids_pct_v": ("underflow solids (roping limit)", "% v/v"),
                "diameter_mm": ("cyclone diameter", "mm"),
                "inlet_ratio": ("inlet diameter ratio D_i/D_c", ""),
                "vortex_finder_ratio": ("vortex finder ratio D_o/D_c", ""),
                "apex_ratio": ("apex ratio D_u/D_c", ""), "apex_to_vortex": ("apex to vortex finder D_u/D_o", "")}


def out_of_range(model: str, geometry: CycloneGeometry, *, pressure_Pa: float, feed_solids_volume_fraction: float,
                 underflow_solids_volume_fraction: float | None = None,
                 validity: ValidityRange | None = None) -> list[tuple[str, float, tuple]]:
    """The quantities of one operating point outside the model's range of use.

    Returns ``[(quantity, value, (low, high)), ...]`` in the units of :class:`ValidityRange`
    (empty when all are in range). ``validity`` defaults to ``VALIDITY[model]``.

    >>> g = CycloneGeometry(0.66, 0.19, 0.25, 0.15, 2.0)
    >>> [q for q, _, _ in out_of_range("plitt", g, pressure_Pa=14e3, feed_solids_volume_fraction=0.28)]
    ['pressure_kPa']
    >>> [q for q, _, _ in out_of_range("nageswararao", g, pressure_Pa=80e3, feed_solids_volume_fraction=0.28)]
    ['diameter_mm']
    """
    rng = validity or VALIDITY[model]
    dc = geometry.diameter_m
    values = {"pressure_kPa": pressure_Pa / 1e3, "feed_solids_pct_v": 100.0 * feed_solids_volume_fraction,
              "diameter_mm": dc * 1e3,
              "inlet_ratio": geometry.inlet_diameter_m / dc, "vortex_finder_ratio": geometry.vortex_finder_m / dc,
              "apex_ratio": geometry.apex_m / dc, "apex_to_vortex": geometry.apex_m / geometry.vortex_finder_m}
    if underflow_solids_volume_fraction is not None:
        values["underflow_solids_pct_v"] = 100.0 * underflow_solids_volume_fraction
    out = []
    for key, v in values.items():
        lo, hi = getattr(rng, key)
        if not (lo <= v <= hi):
            out.append((key, float(v), (lo, hi)))
    return out


def describe_out_of_range(found) -> list[str]:
    """One phrase per quantity of :func:`out_of_range`: "pressure 13.9 kPa outside 40-200 kPa"."""
    out = []
    for key, v, (lo, hi) in found:
        name, unit = _RANGE_NAMES[key]
        u = f" {unit}" if unit else ""
        out.append(f"{name} {v:.3g}{u} outside {lo:g}-{hi:g}{u}")
    return out


def illustrative_constants(model: str, calibration) -> bool:
    """True when Nageswararao's model runs on the default (illustrative) constants."""
    return model == "nageswararao" and (calibration is None or calibration == NageswararaoConstants())
