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
- **size grid**: the prediction on the grid with every class halved in log size; the method
  is first order in the class width, so the base grid's error is about twice its change,
  half-width 2 |q_fine - q0|.

Each contribution is also stated as a log factor l: the largest |ln(q / q0)| over its
alternatives (parameters: the band's ends; the size grid, whose sign is not known from one
refinement: ln(q0 / (q0 - h)), the larger side). A shift of -50 % is a factor 2. The
**total band** adds these log factors linearly, L = sum l, and is [q0 e^-L, q0 e^L]:
a conservative bound that stays positive (the model-form spreads are ranges of plausible
models, not probabilities, so they are not combined in quadrature with the parameter band).
"""
from __future__ import annotations

import dataclasses
import math

from millflow.errors import MillflowError
from millflow.scaleup.power import POWER_MODELS

__all__ = ["quantity", "contributions", "TOTAL_RULE"]

TOTAL_RULE = ("total = [q0 / F, q0 F], F = exp(sum of each contribution's log factor): parameter 95 % band, "
              "power model, scaling rule and size grid added linearly in log (a conservative bound; model-form "
              "spreads are ranges, not probabilities)")


def quantity(su, target_p80_m=None) -> float:
    """The reported prediction: throughput [t/h] at the target P80, or P80 [um] at the feed rate."""
    if target_p80_m is not None:
        return float(su.throughput_for_p80(su.fit.theta, target_p80_m)["feed_tph"])
    return float(su.operate(su.fit.theta)["p80_m"] * 1e6)


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


def contributions(su, target_p80_m, parameter_band: dict | None, refined=None) -> dict:
    """Each contribution's half-width and how it was found, and the total band.

    Parameters
    ----------
    su : ScaleUp at the base choices (its power models, scaling rule and grid).
    target_p80_m : float or None; the quantity is the throughput at it [t/h], else P80 [um].
    parameter_band : {"lo", "hi"} of the parameter 95 % band of the same quantity, or None.
    refined : the same ScaleUp on the grid with every class halved, or None (no grid term).
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
        h = 2.0 * abs(q_fine - q0)
        rows["size_grid"] = {"half_width": h, "log_factor": math.log(q0 / (q0 - h)) if h < q0 else math.inf,
                             "alternatives": {"base": q0, "halved": q_fine},
                             "how": "classes halved in log size; first order, so the base error ~ 2 x the change"}
    for r in rows.values():
        r["rel"] = r["half_width"] / q0
    L = math.fsum(r["log_factor"] for r in rows.values())  # nan if an alternative failed: said in its row
    return {"quantity": "throughput_tph" if target_p80_m is not None else "p80_um", "value": q0,
            "contributions": rows, "total": {"lo": q0 * math.exp(-L), "hi": q0 * math.exp(L), "log_factor": L,
                                             "factor": math.exp(L), "how": TOTAL_RULE}}
