"""Carrying breakage rates from the mill they were measured in to another mill.

- :func:`herbst_fuerstenau_rates`: S_i = S_i^E P / H (specific-energy scaling),
  S_i^E = S_i,lab H_lab / P_lab: the rate per unit of net specific power is a property of
  the material, so the product depends on the specific energy E = P t / H alone.
  B (normalised) is carried unchanged.
  Source: J. A. Herbst, D. W. Fuerstenau, Scale-up procedure for continuous grinding mill
  design using population balance models, Int. J. Miner. Process. 7 (1980) 1-31,
  doi:10.1016/0301-7516(80)90034-4.
  Validity: same material, same breakage mechanism (ball size and speed in the range
  where S^E was found constant; Herbst & Fuerstenau report it for ball mills of 0.25 to
  ~1 m and pilot scale).
- :func:`austin_factors`: multiplicative factors on A and mu of eq. 7 for mill diameter,
  ball diameter, ball filling J, powder filling U and fraction of critical speed phi_c,
  after Austin, Klimpel & Luckie (1984), Process Engineering of Size Reduction: Ball
  Milling, ch. 10 (and L. G. Austin, K. Shoji, P. T. Luckie, Powder Technol. 14 (1976) 71-79
  for the ball-size terms). Every exponent is an argument; the defaults are the values
  AKL quote as typical, to be replaced by tested values where they exist. The ball-size
  exponent of the size at maximum rate, mu ~ d^N2, is N2 = 2: Austin, Shoji and Luckie
  (1976, abstract) find the size of maximum breakage rate proportional to the square of the
  ball diameter (earlier versions of this module used N2 = 1, i.e. mu ~ d).
"""
from __future__ import annotations

import math

import numpy as np

from millflow.errors import InputError
from millflow.scaleup.power import _positive, check_operation

__all__ = ["herbst_fuerstenau_rates", "specific_rates", "austin_factors", "AUSTIN_DEFAULTS"]


def specific_rates(S, power_W, holdup_kg):
    """S^E [kg/J] = S [1/s] H [kg] / P [W] (inverse of :func:`herbst_fuerstenau_rates`)."""
    return np.asarray(S, float) * _positive(holdup_kg, "holdup_kg") / _positive(power_W, "power_W")


def herbst_fuerstenau_rates(S_E, power_W, holdup_kg):
    """S [1/s] = S^E [kg/J] P [W] / H [kg] (Herbst & Fuerstenau 1980, eq. 5 of their paper)."""
    from millflow.breakage.energy import time_rates  # the one implementation of S = S^E P / H

    return time_rates(S_E, _positive(power_W, "power_W"), _positive(holdup_kg, "holdup_kg"))


#: Austin's scale-up exponents and constants (AKL 1984 ch. 10, typical values).
AUSTIN_DEFAULTS = {
    "N0": 1.0,     # A ~ (d_ref/d)^N0, ball diameter (xi of eq. 7)
    "N1": 0.5,     # A ~ D^N1 for D up to D_large
    "N2": 2.0,     # mu ~ (d/d_ref)^N2 (eta of eq. 7): the size of maximum rate ~ d^2 (Austin, Shoji & Luckie 1976)
    "N3": 0.2,     # mu ~ D^N3
    "Delta": 0.2,  # above D_large, A ~ D^(N1 - Delta)
    "D_large_m": 3.81,
    "c_U": 1.2,    # A ~ exp(-c_U (U - U_ref)) for U > ~0.6 (powder-filling term, AKL)
    "a_J": 6.6, "p_J": 2.3,  # A ~ 1 / (1 + a_J J^p_J) (ball filling)
}


def _diameter_term(D, D_ref, N1, Delta, D_large):
    """The diameter factor (D/D_ref)^N1, with a reduced exponent above D_large.

    (D/D_ref)^N1 up to D_large, with the exponent reduced by Delta above it (AKL: large
    mills break less per unit power than the D^0.5 trend of small mills).
    """
    def g(x):
        return x ** N1 if x <= D_large else D_large ** N1 * (x / D_large) ** (N1 - Delta)
    return g(D) / g(D_ref)


def austin_factors(lab: dict, plant: dict, **overrides) -> dict:
    """Factors (plant / lab) on A and mu of eq. 7.

    lab, plant : dicts with diameter_m, ball_size_mm, ball_filling (J),
        critical_speed_fraction (phi_c) and powder_filling (U).

    A_plant/A_lab = (d_lab/d_plant)^N0 * D-term (N1, Delta, D_large)
                    * (1 + a_J J_lab^p_J)/(1 + a_J J^p_J) * exp(-c_U (U - U_lab))
                    * (phi_c - 0.1)/(phi_c,lab - 0.1)
                    * (1 + exp(15.7 (phi_c,lab - 0.94)))/(1 + exp(15.7 (phi_c - 0.94)))
    mu_plant/mu_lab = (d_plant/d_lab)^N2 (D_plant/D_lab)^N3

    Validity: ball mills, phi_c 0.6-0.9, J 0.2-0.5, U 0.5-1.5 (AKL); the D term is an
    extrapolation beyond ~5 m. Overrides: any key of :data:`AUSTIN_DEFAULTS`.

    Returns dict with "A" and "mu" factors and the individual terms.
    """
    unknown = set(overrides) - set(AUSTIN_DEFAULTS)
    if unknown:
        raise InputError(f"austin_factors: unknown overrides {sorted(unknown)}; expected {sorted(AUSTIN_DEFAULTS)}")
    p = {**AUSTIN_DEFAULTS, **{k: float(v) for k, v in overrides.items()}}
    vals = {}
    for where, m in (("lab", lab), ("plant", plant)):
        try:
            D = _positive(m["diameter_m"], f"{where}.diameter_m")
            d = _positive(m["ball_size_mm"], f"{where}.ball_size_mm")
            J, phi = float(m["ball_filling"]), float(m["critical_speed_fraction"])
            U = float(m.get("powder_filling", 1.0))
        except KeyError as exc:
            raise InputError(f"{where}: missing key {exc.args[0]!r} (needed by the Austin scale-up factors)") from None
        check_operation(phi, J, U, where)
        vals[where] = (D, d, J, phi, U)
    (D0, d0, J0, f0, U0), (D, d, J, f, U) = vals["lab"], vals["plant"]
    terms = {
        "ball_size": (d0 / d) ** p["N0"],
        "diameter": _diameter_term(D, D0, p["N1"], p["Delta"], p["D_large_m"]),
        "ball_filling": (1 + p["a_J"] * J0 ** p["p_J"]) / (1 + p["a_J"] * J ** p["p_J"]),
        "powder_filling": math.exp(-p["c_U"] * (U - U0)),
        "speed": (f - 0.1) / (f0 - 0.1) * (1 + math.exp(15.7 * (f0 - 0.94))) / (1 + math.exp(15.7 * (f - 0.94))),
    }
    A = math.prod(terms.values())
    mu = (d / d0) ** p["N2"] * (D / D0) ** p["N3"]
    return {"A": A, "mu": mu, "terms": terms, "exponents": p}
