"""The scale-up prediction with its uncertainty, as one small result object.

:func:`predict_plant` evaluates a :class:`~millflow.scaleup.predict.ScaleUp` at the fit's
estimate and propagates the eq. 9 covariance (delta method, Monte Carlo or both) to:
the product PSD (cumulative passing at the grid sizes), P80, and, with a target P80, the
throughput that meets it and the specific energy there.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
import xarray as xr

from millflow.errors import MillflowError
from millflow.scaleup.uncertainty import compare, delta_method, monte_carlo

__all__ = ["ScaleupResult", "predict_plant"]


@dataclass(frozen=True)
class ScaleupResult:
    """The result of a scale-up: a Dataset with bands and its summary.

    ``dataset``: product band over ``size`` and the scalar predictions with bands
    (variables ``<q>``, ``<q>_lo``, ``<q>_hi`` per method on dim ``estimator``); ``summary``:
    the same as plain numbers (JSON-able); ``scale``: the factors, powers, hold-ups.
    """

    dataset: xr.Dataset
    summary: dict
    scale: dict


def _quantities(su, target):
    """The predicted quantities as a function of the varying parameters.

    g(theta_varying) -> [P(x_1..x_N), p80, (feed_tph, E)], the same for many vectors at
    once (g_pop: (M, V) -> (M, Q), NaN rows where a member's solve fails) and the names of
    the scalars.
    """
    names = ["p80_um"] + (["throughput_tph", "specific_energy_kWh_t"] if target is not None else [])

    def g(v):
        theta = su.fit.full(v)
        r = su.operate(theta)
        P = np.cumsum(r["product"][::-1])[::-1]
        out = [P, [r["p80_m"] * 1e6]]
        if target is not None:
            t = su.throughput_for_p80(theta, target)
            out.append([t["feed_tph"], t["specific_energy_kWh_t"]])
        return np.concatenate(out)

    def g_pop(V):
        thetas = su.fit.full(np.atleast_2d(V))
        r = su.operate_population(thetas)
        P = np.cumsum(r["product"][:, ::-1], axis=1)[:, ::-1]
        cols = [P, (r["p80_m"] * 1e6)[:, None]]
        if target is not None:
            t = su.throughput_population(thetas, target)
            cols.append(np.column_stack([t["feed_tph"], t["specific_energy_kWh_t"]]))
        return np.concatenate(cols, axis=1)
    return g, g_pop, names


def lab_energy_range(fit, su) -> list:
    """Lowest and highest specific energy [kWh/t] of the fitted lab tests.

    [lowest, highest] specific energy [kWh/t] of the fitted lab tests: P_lab t / H_lab over
    the fit's grinding times t (batch times or mean residence times, ``grinding_time_range_s``
    of the fit JSON) with the lab mill's net power and hold-up; [] when the fit does not
    record its times.
    """
    t = fit.spec.get("grinding_time_range_s") or []
    if len(t) != 2:
        return []
    f = su.factors()
    per_s = f["lab_power_kW"] / (f["lab_holdup_kg"] / 1000.0) / 3600.0  # kWh/t per second of grinding
    return [per_s * float(t[0]), per_s * float(t[1])]


def calibrated_range_notes(fit, su, p80_m: float, target_p80_m=None, energies=None) -> list[str]:
    """Where the prediction leaves what the lab data calibrated.

    A P80 (predicted or target) outside the measured sieve range, an eq. 10 process value
    outside the range of the fitted conditions, a plant specific energy per pass through the
    mill, P / F_mill (``energies``: what -> kWh/t; P tau / H, what a batch test's P t / H
    calibrates), outside the lab tests' range (:func:`lab_energy_range`).
    """
    notes = []
    lo_hi = fit.spec.get("measured_size_range_m") or []
    if len(lo_hi) == 2:
        lo, hi = lo_hi
        for what, v in (("predicted P80", p80_m), ("target P80", target_p80_m)):
            if v is not None and not lo <= v <= hi:
                side = "finer than the finest" if v < lo else "coarser than the coarsest"
                notes.append(f"{what} {v * 1e6:.4g} um is {side} sieve of the fitted lab data "
                             f"({lo * 1e6:.4g}..{hi * 1e6:.4g} um): the breakage model is extrapolated there")
    process = fit.spec.get("process") or {}
    for c in fit.spec.get("rate_process", []):
        seen = [float(p[c]) for p in process.values() if isinstance(p, dict) and c in p]
        v = (su.lab_process or {}).get(c)
        if seen and v is not None and not min(seen) <= float(v) <= max(seen):
            notes.append(f"process value {c} = {float(v):.4g} is outside the fitted conditions' range "
                         f"{min(seen):.4g}..{max(seen):.4g}: eq. 10 is extrapolated")
    rng = lab_energy_range(fit, su)
    for what, e in (energies or {}).items():
        if rng and e is not None and math.isfinite(e) and not rng[0] <= e <= rng[1]:
            side = "below" if e < rng[0] else "above"
            notes.append(f"specific energy per pass through the mill {e:.4g} kWh/t (P / mill flow) {what} is {side} "
                         f"the lab tests' range {rng[0]:.4g}..{rng[1]:.4g} kWh/t (lab net power x grinding time / "
                         "hold-up): the breakage model is extrapolated in energy")
    return notes


def predict_plant(su, target_p80_m=None, methods=("delta", "mc"), n_draws: int = 1000, seed: int = 0,
                  rel_step: float = 1e-3) -> ScaleupResult:
    """Prediction and 95 % bands; see the module docstring. ``methods`` any of "delta", "mc"."""
    t0 = time.perf_counter()
    fit = su.fit
    v0 = fit.theta[fit.index]
    g, g_pop, names = _quantities(su, target_p80_m)
    point = su.operate(fit.theta)
    res, timing = {}, {}
    for m in methods:
        t = time.perf_counter()
        if m == "delta":
            res[m] = delta_method(g, v0, fit.cov, rel_step, g_pop=g_pop)
        elif m == "mc":
            res[m] = monte_carlo(g, v0, fit.cov, n_draws, seed, physical=lambda z: fit.physical(fit.full(z)),
                                 skip_errors=(MillflowError,), g_pop=g_pop)
        else:
            raise ValueError(f"method {m!r}: expected 'delta' or 'mc'")
        timing[m] = time.perf_counter() - t
    N = su.x.size
    mlist = list(res)
    # "size" is the upper class size [m], as in every millflow Dataset; "x" its old name
    size_attrs = {"units": "m", "long_name": "upper size of class (Austin convention)"}
    ds = xr.Dataset(coords={"size": ("size", su.x, size_attrs), "x": ("size", su.x, dict(size_attrs)),
                            "size_class": ("size", np.arange(1, N + 1), {"long_name": "size class (1 = coarsest)"}),
                            "estimator": ("estimator", mlist,
                                          {"long_name": "band method (delta method or Monte Carlo)"})})
    # (the dimension is not named "method": DataArray.sel has an argument of that name)
    P0 = np.cumsum(point["product"][::-1])[::-1]
    ds["passing"] = ("size", P0, {"units": "1", "long_name": "product cumulative passing at the estimate"})
    ds["feed_passing"] = ("size", np.cumsum(su.feed[::-1])[::-1], {"units": "1", "long_name": "fresh feed passing"})
    for key, sl, unit in (("passing", slice(0, N), "1"),):
        for bound in ("lo", "hi"):
            ds[f"{key}_{bound}"] = (("estimator", "size"), np.array([res[m][bound][sl] for m in mlist]),
                                    {"units": unit, "long_name": f"95 % band ({bound}) of product passing"})
    summary = {"p80_um": point["p80_m"] * 1e6, "feed_tph": su.feed_tph, "tau_s": point["tau_s"],
               "circulating_load": point["circulating_load"], "mass_balance": point["mass_balance"],
               "power_net_kW": su.power_kW, "specific_energy_kWh_t": point["specific_energy_kWh_t"],
               "bands": {}, "timing_s": timing}
    for k, name in enumerate(names):
        q = N + k
        unit = {"p80_um": "um", "throughput_tph": "t/h", "specific_energy_kWh_t": "kWh/t"}[name]
        vals = {m: {"lo": float(res[m]["lo"][q]), "hi": float(res[m]["hi"][q])} for m in mlist}
        ds[f"{name}_lo"] = ("estimator", [vals[m]["lo"] for m in mlist], {"units": unit})
        ds[f"{name}_hi"] = ("estimator", [vals[m]["hi"] for m in mlist], {"units": unit})
        summary["bands"][name] = vals
    if target_p80_m is not None:
        tr = su.throughput_for_p80(fit.theta, target_p80_m)
        summary["target_p80_um"] = float(target_p80_m) * 1e6
        summary["throughput_tph"] = tr["feed_tph"]
        summary["throughput_residual_rel"] = tr["residual_rel"]
        summary["throughput_bracket_tph"] = list(tr["bracket_tph"])
        summary["specific_energy_at_target_kWh_t"] = tr["specific_energy_kWh_t"]
        ds["throughput_tph"] = ((), tr["feed_tph"], {"units": "t/h"})
    ds["p80_um"] = ((), point["p80_m"] * 1e6, {"units": "um"})
    if "delta" in res and "mc" in res:
        cmp = compare(res["delta"], res["mc"])
        summary["disagreement"] = {name: {"width_rel_diff": float(cmp["width_rel_diff"][N + k]),
                                          "centre_shift": float(cmp["centre_shift"][N + k]),
                                          "nonlinear": bool(cmp["nonlinear"][N + k])}
                                   for k, name in enumerate(names)}
        summary["disagreement"]["passing_max_width_rel_diff"] = float(np.max(cmp["width_rel_diff"][:N]))
    if "mc" in res:
        summary["mc"] = {"n": res["mc"]["n"], "rejected": res["mc"]["rejected"], "failed": res["mc"]["failed"]}
    if "delta" in res:
        summary["delta_step"] = {n: float(h) for n, h in zip(fit.varying, res["delta"]["step"])}
    # a particle's exposure per pass through the mill, P tau / H = P / F_mill, is what a batch
    # test's P t / H calibrates (in a closed circuit below the energy per tonne of fresh feed)
    per_pass = {f"at {su.feed_tph:.4g} t/h": su.power_kW / (point["mill_flow_kg_s"] * 3.6)}
    if target_p80_m is not None:
        per_pass[f"at the target P80 {target_p80_m * 1e6:.4g} um"] = su.power_kW / (tr["mill_flow_kg_s"] * 3.6)
    summary["specific_energy_per_pass_kWh_t"] = dict(per_pass)
    summary["lab_specific_energy_kWh_t"] = lab_energy_range(fit, su)
    summary["extrapolation"] = calibrated_range_notes(fit, su, point["p80_m"], target_p80_m, per_pass)
    for note in summary["extrapolation"]:
        warnings.warn(note, UserWarning, stacklevel=2)
    summary["runtime_s"] = time.perf_counter() - t0
    scale = {k: v for k, v in su.factors().items()}
    ds.attrs.update({"scaling": su.scaling, "power_model": scale["power_model"], "source_fit": fit.source,
                     "A_factor": float(scale["A"]), "mu_factor": float(scale["mu"])})
    return ScaleupResult(ds, summary, scale)
