"""What the scale-up band owes to the model, beside the fit's parameters.

A plant prediction carries four kinds of error, each estimated here by a stated method and
reported as its own half-width around the point estimate q0 (the throughput at the target
P80, or the P80 at the plant feed rate):

- **parameters**: the fit's covariance (eq. 9) through the prediction, the 95 % band of
  :func:`millflow.scaleup.api.predict_plant` (Monte Carlo if run, else the delta method):
  half-width max(hi - q0, q0 - lo);
- **power model**: lab and plant both under each power family of
  :data:`millflow.scaleup.power.POWER_MODELS` (Bond/Rowland, Austin, Hogg-Fuerstenau):
  half-width the largest |q_m - q0|;
- **scaling rule**: Herbst-Fuerstenau (S = S^E P / H) against Austin's factors on A and mu:
  half-width |q_other - q0|;
- **size grid**: Richardson's estimate from the prediction on the grid with every class
  halved in log size (q_f) and, where the classes pair up, on the grid with pairs of classes
  merged (q_2h), at the observed order p = log2(|q_2h - q0| / |q0 - q_f|): the converged value
  q_ext = q_f + (q_f - q0)/(2^p - 1) and the half-width F_s |q0 - q_ext|, with Roache's safety
  factor F_s = 1.25 when p is within 0.5 of the scheme's order (2 for class-averaged forms:
  the asymptotic range) and F_s = 3 with p the smaller of the two otherwise, or with two grids
  only (:func:`grid_error`).

Each contribution is also stated as a log factor l: the largest |ln(q / q0)| over its
alternatives (parameters: the band's ends; the size grid: ln(q0 / (q0 - h)), the larger
side). A shift of -50 % is a factor 2. The
**total band** adds these log factors linearly, L = sum l, and is [q0 e^-L, q0 e^L]:
a conservative bound that stays positive (the model-form spreads are ranges of plausible
models, not probabilities, so they are not combined in quadrature with the parameter band).
"""
from __future__ import annotations

import dataclasses
import math

from millflow.errors import MillflowError
from millflow.scaleup.power import POWER_MODELS

__all__ = ["quantity", "contributions", "grid_error", "error_estimate", "TOTAL_RULE"]

TOTAL_RULE = ("total = [q0 / F, q0 F], F = exp(sum of each contribution's log factor): parameter 95 % band, "
              "power model, scaling rule and size grid added linearly in log (a conservative bound; model-form "
              "spreads are ranges, not probabilities)")


def quantity(su, target_p80_m=None) -> float:
    """The reported prediction: throughput [t/h] at the target P80, or P80 [um] at the feed rate."""
    if target_p80_m is not None:
        return float(su.throughput_for_p80(su.fit.theta, target_p80_m)["feed_tph"])
    return float(su.operate(su.fit.theta)["p80_m"] * 1e6)


def _scheme_order(su) -> int:
    """Order of the size discretisation of the plant prediction: 2 on class averages, 1 on upper edges."""
    return 1 if getattr(su.grid, "scheme", "class_average") == "upper_edge" else 2


def error_estimate(su, target_p80_m, size_grid: dict | None) -> dict:
    """The reported quantity's error split by source: ``solver`` (the flowsheet solve's relative
    residual and mass balance, and the root's P80 residual) and ``grid`` (:func:`grid_error`)."""
    if target_p80_m is not None:
        r = su.throughput_for_p80(su.fit.theta, target_p80_m)
        solver = max(r["residual_rel"], r.get("relative_residual", 0.0), r["mass_balance"])
        how = ("flowsheet solve (relative residual, mass balance) and the throughput root (|P80 - target| / "
               "target, Brent on ln of the mill flow to 1e-13)")
    else:
        r = su.operate(su.fit.theta)
        solver = max(r.get("relative_residual", 0.0), r["mass_balance"])
        how = "flowsheet solve (relative residual, mass balance) at the fresh feed rate (Brent on ln of the mill flow)"
    out = {"solver": {"value": float(solver), "unit": "relative", "method": how}}
    if size_grid is None:
        out["grid"] = {"value": None, "unit": "relative", "method": "not estimated (no refined grid)"}
    else:
        est = size_grid["estimate"]
        out["grid"] = {"value": est["value"], "unit": "relative", "method": est["how"], "order": est["order"],
                       "observed_order": est["observed_order"], "safety_factor": est["safety_factor"],
                       "converged": est["converged"], "values": size_grid["alternatives"]}
    return out


def _with_power_model(su, model: str):
    lab = su.lab if su.lab.power_kW is not None else dataclasses.replace(su.lab, power_model=model)
    mill = su.circuit.mill
    mill = mill if mill.power_kW is not None else dataclasses.replace(mill, power_model=model)
    return dataclasses.replace(su, lab=lab, circuit=dataclasses.replace(su.circuit, mill=mill))


def _log(q, q0) -> float:
    """|ln(q / q0)|; nan for a failed alternative (it makes the total nan: said, not hidden)."""
    return abs(math.log(q / q0)) if q > 0 else (math.nan if math.isnan(q) else math.inf)


def _safe(fun, *args):
    try:
        return fun(*args)
    except MillflowError:  # e.g. the target is not reachable under this model: said in the table
        return math.nan


#: Roache's safety factors: three grids in the asymptotic range (observed order within
#: ASYMPTOTIC_BAND of the scheme's), and two grids or outside that range.
SAFETY_THREE_GRIDS, SAFETY_TWO_GRIDS, ASYMPTOTIC_BAND = 1.25, 3.0, 0.5


def grid_error(q0: float, q_fine: float, q_coarse: float | None = None, order: float = 2.0,
               q_finer: float | None = None) -> dict:
    """Richardson's estimate of the grid error of q0 (module docstring): value (relative),
    half_width, order p, observed (or None), safety_factor, converged, how. The observed
    order comes from grids 2h, h, h/2 (``q_coarse``) or, where the classes do not pair up,
    from h, h/2, h/4 (``q_finer``)."""
    if not (math.isfinite(q0) and math.isfinite(q_fine)):
        return {"value": math.nan, "half_width": math.nan, "order": order, "observed_order": None,
                "safety_factor": SAFETY_TWO_GRIDS, "converged": math.nan, "how": "a refined prediction failed"}
    observed, grids = None, "h/2, h"
    if q_coarse is not None and math.isfinite(q_coarse) and q_fine != q0 and q_coarse != q0:
        observed, grids = math.log2(abs(q_coarse - q0) / abs(q0 - q_fine)), "h/2, h, 2h"
    elif q_finer is not None and math.isfinite(q_finer) and q_fine != q0 and q_finer != q_fine:
        observed, grids = math.log2(abs(q0 - q_fine) / abs(q_fine - q_finer)), "h/4, h/2, h"
    if observed is not None and abs(observed - order) <= ASYMPTOTIC_BAND:
        p, fs = observed, SAFETY_THREE_GRIDS
        how = (f"Richardson from grids {grids} at the observed order {observed:.3g} (the scheme's is {order:g}), "
               f"safety factor {fs:g}")
    else:
        p = order if observed is None else max(min(observed, order), 0.5)
        fs = SAFETY_TWO_GRIDS
        how = (f"Richardson from grids h/2 and h at order {p:.3g} ("
               + ("no third grid" if observed is None else f"observed order {observed:.3g} outside the asymptotic "
                  f"range of the scheme's {order:g}") + f"), safety factor {fs:g}")
    ext = q_fine + (q_fine - q0) / (2.0 ** p - 1.0)
    h = fs * abs(q0 - ext)
    return {"value": h / abs(ext), "half_width": h, "order": p, "observed_order": observed, "safety_factor": fs,
            "converged": ext, "how": how}


def contributions(su, target_p80_m, parameter_band: dict | None, refined=None, coarsened=None,
                  refined_twice=None) -> dict:
    """Each contribution's half-width and how it was found, and the total band.

    Parameters
    ----------
    su : ScaleUp at the base choices (its power models, scaling rule and grid).
    target_p80_m : float or None; the quantity is the throughput at it [t/h], else P80 [um].
    parameter_band : {"lo", "hi"} of the parameter 95 % band of the same quantity, or None.
    refined : the same ScaleUp on the grid with every class halved, or None (no grid term).
    coarsened : the same ScaleUp on the grid with pairs of classes merged, or None;
    refined_twice : the same on the grid with every class split in four (used when not
        coarsened); with neither, the grid term takes the scheme's order with the two-grid
        safety factor.
    """
    q0 = quantity(su, target_p80_m)
    rows = {}
    if parameter_band is not None:
        rows["parameters"] = {"half_width": max(parameter_band["hi"] - q0, q0 - parameter_band["lo"]),
                              "log_factor": max(_log(parameter_band["hi"], q0), _log(parameter_band["lo"], q0)),
                              "alternatives": {"lo": parameter_band["lo"], "hi": parameter_band["hi"]},
                              "how": "95 % band of the fit's covariance through the prediction"}
    base_models = {su.lab.power().get("model"), su.circuit.mill.power().get("model")}
    alts = {m: (q0 if base_models == {m} else _safe(lambda m=m: quantity(_with_power_model(su, m), target_p80_m)))
            for m in POWER_MODELS}
    rows["power_model"] = {"half_width": max(abs(v - q0) for v in alts.values() if math.isfinite(v)),
                           "log_factor": max(_log(v, q0) for v in alts.values()),
                           "alternatives": alts,
                           "how": "lab and plant under each power family; largest shift from the base"}
    other = "austin" if su.scaling == "herbst_fuerstenau" else "herbst_fuerstenau"
    q_other = _safe(lambda: quantity(dataclasses.replace(su, scaling=other), target_p80_m))
    rows["scaling_rule"] = {"half_width": abs(q_other - q0), "log_factor": _log(q_other, q0),
                            "alternatives": {su.scaling: q0, other: q_other},
                            "how": "Herbst-Fuerstenau against Austin's factors; the shift"}
    if refined is not None:
        q_fine = _safe(lambda: quantity(refined, target_p80_m))
        q_coarse = _safe(lambda: quantity(coarsened, target_p80_m)) if coarsened is not None else None
        q_finer = None
        if q_coarse is None and refined_twice is not None:
            q_finer = _safe(lambda: quantity(refined_twice, target_p80_m))
        ge = grid_error(q0, q_fine, q_coarse, _scheme_order(su), q_finer)
        h = ge["half_width"]
        alts = ({"base": q0, "halved": q_fine} | ({"doubled": q_coarse} if q_coarse is not None else {})
                | ({"quartered": q_finer} if q_finer is not None else {}))
        rows["size_grid"] = {"half_width": h, "log_factor": math.log(q0 / (q0 - h)) if h < q0 else math.inf,
                             "alternatives": alts, "how": ge["how"], "estimate": ge}
    for r in rows.values():
        r["rel"] = r["half_width"] / q0
    L = math.fsum(r["log_factor"] for r in rows.values())  # nan if an alternative failed: said in its row
    return {"quantity": "throughput_tph" if target_p80_m is not None else "p80_um", "value": q0,
            "contributions": rows, "total": {"lo": q0 * math.exp(-L), "hi": q0 * math.exp(L), "log_factor": L,
                                             "factor": math.exp(L), "how": TOTAL_RULE}}
