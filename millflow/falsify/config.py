"""The TOML configuration of ``millflow falsify``; every key is checked (unknown keys are
refused, types checked) and every error is one line naming the key.

```toml
replicates = 50          # R per strength
seed = 0
workers = 1              # processes
drift_replicates = 10    # replicates refitted on short and long halves

[truth]
type = "tanks_in_series" # tanks_in_series | axial_dispersion | recirculating_cells |
                         # classification | slowing_down | aggregation | population |
                         # assumed (no model error)
# aggregation: strength = beta0 [1/s]; kernel = "constant" (sum, product, shear);
#   x_ref_um = reference size of the kernel's volumes (default the finest sieve)
# population: strength = cushioning exponent; fines_um (default the middle sieve)
# (sizes and times in any unit: x_ref_mm, fines_mm, tau_h, top_size_mm, ...)
# either, continuous designs: n_tanks = 3 (tanks in series instead of perfect mixing)
strengths = [1, 2, 3, 5] # or strength = 3; n cells, Pe, n_screen, slowing-down s
r = 1.0                  # recirculating_cells back-flow ratio
[truth.params]           # breakage parameters of the truth (default BREAKAGE_TRUTH)
ln_A0 = -4.09

[assumed]                # the fitted model: ModelSpec keys
mode = "well_mixed"      # batch designs: "batch"
# kinetics = "aggregation"   # or population, slowing_down, a list: fit the non-linear model
# [assumed.kinetics_params]  # kernel, x_ref_um, fines_um, w, kappa, t_ref_min (defaults match the truths')
[assumed.params.alpha]   # bounds of the global search
min = 0.2
max = 2.5

[design]
tau_s = [30, 60, 120, 240, 480]     # continuous (tau_<unit>: _s, _min, _h), or times_<unit> (batch)
top_size_um = 4000
n_sieves = 16
sieve_ratio = 1.4142135623730951
grid_per_sieve = 2

[noise]
kind = "gaussian"        # or "ar1" (with rho)
sigma = 0.01             # on cumulative passing

[fit]                    # millflow.fitting.fit settings
starts = 3
popsize = 8
maxiter = 60
```

Keys with a dimension carry their unit in the name and are read through
:func:`millflow.inputs.quantity` (the reader of every user file): ``tau_<time>``,
``times_<time>``, ``top_size_<length>``, ``x_ref_<length>``, ``fines_<length>``, with the
units of :data:`millflow.inputs.UNITS`. A key written without its unit (``tau = [...]``)
or with an unknown one (``top_size_cm``) is one error line naming the key.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass

from millflow.errors import InputError
from millflow.inputs import UNITS, quantity, read_text
from millflow.falsify.design import batch_design, continuous_design
from millflow.falsify.noise import make_noise
from millflow.falsify.nonlinear_truths import AggregationTruth, PopulationTruth
from millflow.falsify.study import study_parameters
from millflow.falsify.truths import (BREAKAGE_TRUTH, LinearTruth, SlowingDownTruth, classification_truth,
                                     is_rtd_truth, rtd_truth)
from millflow.fitting.models import ModelSpec
from millflow.mill.transport import is_network

__all__ = ["StudyConfig", "load_config", "parse_config", "TRUTH_TYPES"]

TRUTH_TYPES = ("tanks_in_series", "axial_dispersion", "recirculating_cells", "classification", "slowing_down",
               "aggregation", "population", "assumed")
_NUM = (int, float)
_TOP = {"replicates": int, "seed": int, "workers": int, "drift_replicates": int,
        "truth": dict, "assumed": dict, "design": dict, "noise": dict, "fit": dict}
_TRUTH = {"type": str, "strength": _NUM, "strengths": list, "r": _NUM, "params": dict, "n_screen": _NUM,
          "kernel": str, "n_tanks": int}
_ASSUMED = {"mode": str, "rate": str, "breakage": str, "classification": str, "n_tanks": int, "transport": str,
            "transport_params": dict, "where": str, "params": dict, "kinetics": (str, list), "kinetics_params": dict}
_DESIGN = {"n_sieves": int, "sieve_ratio": _NUM, "grid_per_sieve": int}
#: Keys with a unit in their name: base -> (dimension, a list of values, zero allowed).
_TRUTH_UNITS = {"x_ref": ("length", False, False), "fines": ("length", False, False)}
_DESIGN_UNITS = {"tau": ("time", True, False), "times": ("time", True, True), "top_size": ("length", False, False)}
_NOISE = {"kind": str, "sigma": _NUM, "rho": _NUM}
_FIT = {"starts": int, "popsize": int, "maxiter": int, "de_tol": _NUM, "global_search": bool}


@dataclass
class StudyConfig:
    truth: object            # callable strength -> truth
    strengths: list
    assumed: ModelSpec
    design: object
    noise: object
    params: dict
    replicates: int
    seed: int
    workers: int
    drift_replicates: int
    fit_options: dict
    source: str

    def run(self, progress=None):
        from millflow.falsify.study import study
        return study(self.truth, self.assumed, self.design, noise=self.noise, strengths=self.strengths,
                     replicates=self.replicates, seed=self.seed, params=self.params, fit_options=self.fit_options,
                     drift_replicates=self.drift_replicates, workers=self.workers, progress=progress)


def _check(table: dict, schema: dict, where: str, src: str, units: dict | None = None) -> tuple[dict, dict]:
    """(table, quantities): plain keys checked against ``schema`` (name -> type), keys with a
    unit (``units``: base -> (dimension, list, zero allowed)) read in SI through
    :func:`millflow.inputs.quantity` (base -> value, None when absent); any other key is
    refused in one line naming it."""
    used: set = set()
    values = {}
    for base, (dim, many, zero) in (units or {}).items():
        v = quantity(table, base, dim, f"{src}: {where[:-1]}", None, allow_zero=zero, array=many, used=used)
        if v is not None and many:
            key = next(k for k in used if k.startswith(base + "_") and k[len(base) + 1:] in UNITS[dim])
            if not isinstance(table[key], list) or not table[key]:
                raise InputError(f"{src}: {where}{key} = {table[key]!r}: expected a non-empty list of numbers")
            v = [float(e) for e in v]
        values[base] = v
    for key, val in table.items():
        if key in used:
            continue
        if key not in schema:
            known = sorted(schema) + [f"{b}_<unit>" for b in (units or {})]
            raise InputError(f"{src}: unknown key {where}{key}; expected one of {known}")
        typ = schema[key]
        ok = isinstance(val, typ) and not (isinstance(val, bool) and typ is not bool)
        if not ok:
            want = " or ".join(t.__name__ for t in (typ if isinstance(typ, tuple) else (typ,)))
            raise InputError(f"{src}: {where}{key} = {val!r}: expected {want}")
        if isinstance(val, float) and not math.isfinite(val):
            raise InputError(f"{src}: {where}{key} = {val!r}: expected a finite number")
    return table, values


def _numbers(vals, key: str, src: str) -> list:
    if not vals or not all(isinstance(v, _NUM) and not isinstance(v, bool) and math.isfinite(v) for v in vals):
        raise InputError(f"{src}: {key} = {vals!r}: expected a non-empty list of finite numbers")
    return [float(v) for v in vals]


def load_config(path) -> StudyConfig:
    try:
        raw = tomllib.loads(read_text(path, "config"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from exc
    return parse_config(raw, str(path))


def parse_config(raw: dict, src: str = "<config>") -> StudyConfig:
    _check(raw, _TOP, "", src)
    for key in ("truth", "assumed", "design", "noise"):
        if key not in raw:
            raise InputError(f"{src}: missing table [{key}]")
    tr, tru = _check(raw["truth"], _TRUTH, "truth.", src, _TRUTH_UNITS)
    asm, _ = _check(raw["assumed"], _ASSUMED, "assumed.", src)
    des, desu = _check(raw["design"], _DESIGN, "design.", src, _DESIGN_UNITS)
    noi, _ = _check(raw["noise"], _NOISE, "noise.", src)
    fopt, _ = _check(raw.get("fit", {}), _FIT, "fit.", src)
    for key in ("replicates", "workers", "drift_replicates"):
        if key in raw and raw[key] < (2 if key == "replicates" else 0 if key == "drift_replicates" else 1):
            raise InputError(f"{src}: {key} = {raw[key]!r}: expected an integer >= "
                             f"{2 if key == 'replicates' else 0 if key == 'drift_replicates' else 1}")
    if "seed" in raw and not 0 <= raw["seed"] < 2**31:  # numpy's SeedSequence takes non-negative entries,
        # and the seed is stored as an attribute of the netCDF (classic format: 32-bit integers)
        raise InputError(f"{src}: seed = {raw['seed']!r}: expected a whole number 0 .. 2**31 - 1")
    for key in ("starts", "popsize", "maxiter"):
        if key in fopt and fopt[key] < 1:
            raise InputError(f"{src}: fit.{key} = {fopt[key]!r}: expected an integer >= 1")

    # design
    times, taus = desu["times"], desu["tau"]
    if (times is None) == (taus is None):
        raise InputError(f"{src}: [design] needs exactly one of times_<unit> (batch: times_s, times_min, ...) or "
                         f"tau_<unit> (continuous: tau_s, tau_min, ...); got "
                         f"{sorted(k for k in des if k.startswith(('times_', 'tau_')))}")
    top = desu["top_size"]
    kw = {"top_m": 4000e-6 if top is None else top, "n_sieves": des.get("n_sieves", 16),
          "sieve_ratio": float(des.get("sieve_ratio", 2 ** 0.5)), "grid_per_sieve": des.get("grid_per_sieve", 2)}
    ttype = tr.get("type")
    if ttype not in TRUTH_TYPES:
        raise InputError(f"{src}: truth.type = {ttype!r}: expected one of {list(TRUTH_TYPES)}")
    if times is not None:
        design = batch_design(times, **kw)
    else:
        extra = {"screen_mm": [1.0] * len(taus)} if ttype == "classification" else None
        design = continuous_design(taus, extra_process=extra, **kw)

    # assumed model
    akw = {k: v for k, v in asm.items() if k not in ("params", "kinetics", "kinetics_params")}
    if "kinetics" in asm:  # the fit config's reader: units in the key names (x_ref_um, fines_um, t_ref_min)
        from millflow.fitting.config import _kinetics
        akw["kinetics"], akw["kinetics_params"] = _kinetics(asm, f"{src}: assumed")
    elif "kinetics_params" in asm:
        raise InputError(f"{src}: assumed.kinetics_params given without assumed.kinetics")
    if not design.is_batch and akw.get("mode", "batch") != "batch":
        akw["tau_column"] = "tau_s"
    if akw.get("mode", "batch") == "batch" and not design.is_batch:
        raise InputError(f"{src}: assumed.mode = 'batch' needs design.times_<unit> (times_s, times_min, times_h)")
    if design.is_batch and akw.get("mode", "batch") != "batch":
        raise InputError(f"{src}: assumed.mode = {akw['mode']!r} needs design.tau_s (or tau_min, tau_h: a "
                         "continuous design)")
    if akw.get("classification") in ("screen", "screen_power") and "screen_mm" not in dict(design.process):
        raise InputError(f"{src}: assumed.classification needs truth.type = 'classification' (which adds a "
                         "screen_mm column to the design)")
    assumed = ModelSpec(**akw)

    # truth
    tparams = {**BREAKAGE_TRUTH, **tr.get("params", {})}
    for k, v in tr.get("params", {}).items():
        if k not in BREAKAGE_TRUTH:
            raise InputError(f"{src}: unknown key truth.params.{k}; expected one of {sorted(BREAKAGE_TRUTH)} "
                             "(eq. 5 at x0 = 1 mm, eq. 6)")
        if not isinstance(v, _NUM) or isinstance(v, bool) or not math.isfinite(v):
            raise InputError(f"{src}: truth.params.{k} = {v!r}: expected a finite number")
    if "strength" in tr and "strengths" in tr:
        raise InputError(f"{src}: give truth.strength or truth.strengths, not both")
    if ttype == "assumed":
        strengths = [0.0]
        if "strength" in tr or "strengths" in tr:
            raise InputError(f"{src}: truth.type = 'assumed' has no strength (no model error)")
    else:
        if "strength" not in tr and "strengths" not in tr:
            raise InputError(f"{src}: truth.strength or truth.strengths is required for truth.type = {ttype!r}")
        strengths = _numbers(tr["strengths"], "truth.strengths", src) if "strengths" in tr else [float(tr["strength"])]
    if "r" in tr and not (is_rtd_truth(ttype) and is_network(ttype)):
        raise InputError(f"{src}: truth.r is only for truth.type = 'recirculating_cells'")
    if "n_screen" in tr and not is_rtd_truth(ttype):
        raise InputError(f"{src}: truth.n_screen (classification inside an RTD mill) is only for RTD truths")
    if (is_rtd_truth(ttype) or ttype == "classification") and design.is_batch:
        raise InputError(f"{src}: truth.type = {ttype!r} needs a continuous design (design.tau_<unit>: tau_s, "
                         "tau_min, tau_h)")
    if ttype == "slowing_down" and not design.is_batch:
        raise InputError(f"{src}: truth.type = 'slowing_down' needs a batch design (design.times_<unit>: "
                         "times_s, times_min, times_h)")
    if "n_tanks" in tr and (ttype not in ("aggregation", "population") or design.is_batch):
        raise InputError(f"{src}: truth.n_tanks is only for truth.type = 'aggregation' or 'population' with a "
                         "continuous design")
    for key, only in (("kernel", "aggregation"), ("x_ref", "aggregation"), ("fines", "population")):
        given = tr.get(key) if key == "kernel" else tru[key]
        if given is not None and ttype != only:
            name = key if key == "kernel" else next(k for k in tr if k.startswith(key + "_"))
            raise InputError(f"{src}: truth.{name} is only for truth.type = {only!r}")
    if "n_screen" in tr:
        screens = {"screen_mm": [1.0] * len(design.conditions)}
        design = continuous_design(list(dict(design.process)["tau_s"]), extra_process=screens, **kw)
    truth = _truth_factory(ttype, tparams, tr, tru, assumed, src)
    for s in strengths:  # build once here, so that bad strengths fail before any fit
        truth(s)

    noise = make_noise(noi.get("kind", "gaussian"), float(noi.get("sigma", 0.01)),
                       float(noi["rho"]) if "rho" in noi else None)
    params = study_parameters(assumed, tparams, asm.get("params", {}))
    return StudyConfig(truth, strengths, assumed, design, noise, params, raw.get("replicates", 50),
                       raw.get("seed", 0), raw.get("workers", 1), raw.get("drift_replicates", 10), fopt, src)


def _truth_factory(ttype, tparams, tr, sizes, assumed, src):
    """strength -> truth of ``truth.type``; ``sizes`` holds x_ref and fines in m (or None)."""
    if is_rtd_truth(ttype):
        n_screen = tr.get("n_screen")
        return lambda s: rtd_truth(ttype, s, tparams, r=float(tr.get("r", 1.0)),
                                   classification="screen_power" if n_screen is not None else None,
                                   n_screen=n_screen)
    if ttype == "classification":
        return lambda s: classification_truth(s, tparams)
    if ttype == "slowing_down":
        return lambda s: SlowingDownTruth(s, tparams)
    if ttype == "aggregation":
        kernel = tr.get("kernel", "constant")
        x_ref = sizes["x_ref"]
        return lambda s: AggregationTruth(s, tparams, kernel=kernel, x_ref_m=x_ref, n_tanks=tr.get("n_tanks", 1))
    if ttype == "population":
        fines = sizes["fines"]
        return lambda s: PopulationTruth(s, tparams, fines_m=fines, n_tanks=tr.get("n_tanks", 1))
    missing = [n for n in assumed.param_names if n not in tparams]
    if missing:
        raise InputError(f"{src}: truth.type = 'assumed' needs truth.params {missing}")
    return lambda s: LinearTruth(assumed, tparams, name="assumed", strength=0.0)
