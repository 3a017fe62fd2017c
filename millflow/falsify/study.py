"""The falsification study: fit an assumed model to data from a truth with model error.

The falsification study (Principle I): how wrong are fitted kinetics when the
assumed model leaves out physics that the truth has?

For every strength of the model error a truth is built, its noiseless measurements are
computed once, and R replicates are drawn (truth + noise, seeds
``numpy.random.default_rng([seed, strength_index, replicate])``). Each replicate is fitted
with the assumed model by :func:`millflow.fitting.fit` (differential evolution + local
starts, eq. 9 statistics). Per strength and parameter the study reports

- ``bias`` = mean(estimate) - truth; ``bias_se`` = mean((estimate - truth) / SE) (the
  bias in units of the SE the fit reported); ``bias_pct``: 100 bias / |truth|, or for
  ``ln_X`` parameters the percent bias of X, 100 (exp(bias) - 1);
- ``coverage``: fraction of replicates whose reported 95 % interval holds the truth;
- ``se_ratio``: the scatter of the estimates over the mean reported SE (1 when the
  reported SE is honest);

and per strength the goodness of fit a user would have seen (mean R2 and SER, SER over
the noise sigma), residual structure (fraction of replicates in which a Wald-Wolfowitz
runs test on the residual signs rejects randomness at 5 %, mean lag-1 autocorrelation of
the residuals within samples) and the *drift*: the assumed model refitted separately to
the short and the long half of the milling times (batch) or residence times
(continuous), ln A(long) - ln A(short), in percent of A and in units of its SE. A rate
that drifts with milling time is the classical symptom of non-linear breakage.

Parameters the truth does not have (e.g. none of a perfectly mixed fit when the truth
has classification) have truth NaN: their bias and coverage are NaN, not zero.
"""
from __future__ import annotations

import math
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy.stats import norm

from millflow.errors import InputError, MillflowError, SolverError
from millflow.fitting.data import PSDData
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel, ModelSpec, Parameter, default_parameters

__all__ = ["StudyResult", "study", "study_parameters", "runs_test", "lag1", "FIT_DEFAULTS", "BOUNDS"]

#: Modest global-search settings: a 5-parameter batch fit in about a second.
FIT_DEFAULTS = {"starts": 3, "popsize": 8, "maxiter": 60, "de_tol": 1e-3}


#: Bounds of the global search of a study (gamma < beta separates the two branches of
#: eq. 6, so the breakage parameters are unique; ln_A0 is ln of A [1/s] at x0 = 1 mm).
BOUNDS = {"ln_A0": (-9.0, 0.0), "alpha": (0.2, 2.5), "phi": (0.0, 1.0), "gamma": (0.1, 2.0), "beta": (2.2, 8.0),
          "n_screen": (0.0, 6.0), "ln_mu": (-3.0, 6.0), "Lambda": (1.0, 6.0)}


def study_parameters(spec: ModelSpec, truth_params: dict, overrides: dict | None = None) -> dict:
    """Parameters of the assumed model, started at the truth's values.

    Parameters of the assumed model: :data:`BOUNDS` (else the fitting defaults), start at the
    truth's value where it has one, updated by ``overrides`` (name -> value/min/max/vary).
    """
    base = default_parameters(spec)
    overrides = dict(overrides or {})
    out = {}
    for name, par in base.items():
        lo, hi = BOUNDS.get(name, (par.min, par.max))
        v = float(truth_params.get(name, par.value))
        o = overrides.pop(name, {})
        if not isinstance(o, dict) or set(o) - {"value", "min", "max", "vary"}:
            raise InputError(f"assumed.params.{name}: expected a table with keys value, min, max, vary")
        lo, hi = float(o.get("min", lo)), float(o.get("max", hi))
        v = float(o.get("value", min(max(v, lo), hi)))
        out[name] = Parameter(name, v, lo, hi, bool(o.get("vary", True)))
    if overrides:
        raise InputError(f"assumed.params: {sorted(overrides)} are not parameters of the assumed model; "
                         f"expected {list(spec.param_names)}")
    return out


def runs_test(r) -> tuple[float, float]:
    """Wald-Wolfowitz runs test on the signs of ``r`` (zeros dropped): (z, two-sided p)."""
    s = np.sign(np.asarray(r, float))
    s = s[s != 0]
    n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
    n = n1 + n2
    if n1 == 0 or n2 == 0:
        return math.nan, math.nan
    runs = 1 + int(np.sum(s[1:] != s[:-1]))
    mu = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1.0))
    z = (runs - mu) / math.sqrt(var)
    return z, float(2 * norm.sf(abs(z)))


def lag1(r, slices) -> float:
    """Lag-1 autocorrelation of residuals, pairs taken within samples only."""
    r = np.asarray(r, float)
    num = sum(float(np.dot(r[a:b - 1], r[a + 1:b])) for a, b in zip(slices[:-1], slices[1:]))
    den = float(np.dot(r, r))
    return num / den if den > 0 else math.nan


@dataclass
class StudyResult:
    """Outcome of :func:`study`: a Dataset of estimates and their summary.

    Outcome of :func:`study`: ``dataset`` (dims strength x parameter, and strength x
    replicate x parameter for the raw estimates) and :meth:`summary`.
    """

    dataset: xr.Dataset
    runtime_s: float
    settings: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """Bias, coverage, fit statistics and drift per strength, as plain numbers (JSON-able)."""
        ds = self.dataset
        rows = []
        for k, s in enumerate(ds.strength.values):
            per = {}
            for p in ds.parameter.values:
                per[str(p)] = {v: _num(ds[v].values[k, list(ds.parameter.values).index(p)])
                               for v in ("truth", "mean_estimate", "bias", "bias_se", "bias_pct", "coverage",
                                         "se_ratio")}
            rows.append({"strength": _num(s), "parameters": per,
                         **{v: _num(ds[v].values[k]) for v in ("r2", "ser", "ser_over_sigma", "runs_reject",
                                                               "lag1", "drift_pct", "drift_se", "n_failed")}})
        return {"truth": ds.attrs["truth"], "assumed": ds.attrs["assumed"], "replicates": int(ds.sizes["replicate"]),
                "noise": ds.attrs["noise"], "design": ds.attrs["design"], "seed": int(ds.attrs["seed"]),
                "fit_options": ds.attrs["fit_options"], "runtime_s": self.runtime_s, "strengths": rows}

    def text(self) -> str:
        """The summary as lines of text."""
        s = self.summary()
        lines = [f"truth {s['truth']}, assumed {s['assumed']}, {s['replicates']} replicates, noise {s['noise']}, "
                 f"{s['runtime_s']:.1f} s"]
        for row in s["strengths"]:
            lines.append(f"strength {row['strength']:g}: R2 {_f(row['r2'])}, SER/sigma {_f(row['ser_over_sigma'])}, "
                         f"runs test rejects {_f(row['runs_reject'])}, lag-1 {_f(row['lag1'])}, "
                         f"drift of A short->long {_f(row['drift_pct'])} % ({_f(row['drift_se'])} SE), "
                         f"failed fits {row['n_failed']:g}")
            for name, p in row["parameters"].items():
                if p["truth"] is None:
                    continue
                lines.append(f"    {name:<10} truth {p['truth']:>9.4g}  bias {_f(p['bias_se']):>8} SE "
                             f"{_f(p['bias_pct']):>9} %  coverage {_f(p['coverage'])}")
        return "\n".join(lines)


def _num(v):
    v = float(v)
    return v if math.isfinite(v) else None


def _f(v):
    return "nan" if v is None else f"{v:.3g}"


def _fit_one(task):
    """One replicate: noisy data, the fit, and its diagnostics (runs in a worker)."""
    (design, keys, clean, spec, params, noise, seed, fit_opts, drift, split) = task
    rng = np.random.default_rng(seed)
    n_s = len(design.sieves_m)
    noisy = clean + noise.sample(rng, len(keys), n_s).ravel()
    data = design.data(noisy, keys)
    names = [n for n in spec.param_names if params[n].vary]
    out = {"est": np.full(len(names), np.nan), "se": np.full(len(names), np.nan),
           "lo": np.full(len(names), np.nan), "hi": np.full(len(names), np.nan),
           "r2": np.nan, "ser": np.nan, "runs_p": np.nan, "lag1": np.nan,
           "drift": (np.nan, np.nan, np.nan), "error": ""}
    try:
        model = ForwardModel(spec, data, design.grid)
        res = fit(model, params, seed=int(seed[-1]), grid_check=False, quiet=True, **fit_opts)
        for k, n in enumerate(names):
            st = res.stats["params"][n]
            out["est"][k], out["se"][k] = st["value"], st["se"]
            out["lo"][k], out["hi"][k] = st["ci95"]
        y, w = model.y, model.weights
        r = res.predicted() - y
        ybar = np.sum(w * y) / np.sum(w)
        out["r2"] = 1.0 - float(np.sum(w * r ** 2) / np.sum(w * (y - ybar) ** 2))
        out["ser"] = float(res.ser)
        out["runs_p"] = runs_test(r)[1]
        out["lag1"] = lag1(r, model.group_slices)
        if drift and "ln_A0" in names:
            out["drift"] = _drift(model, params, fit_opts, seed, split)
    except MillflowError as exc:  # a failed fit is counted and reported, not dropped
        out["error"] = str(exc)
    return out


def _drift(model, params, fit_opts, seed, split):
    """The fitted ln A0 of the long half minus that of the short half, and its SE."""
    est = []
    for part in split:
        sub = model.data.subset(part) if part and isinstance(part[0], str) else None
        if sub is None:  # batch: split by time
            t = model.data.table
            keep = (t.location == "feed") | t.time_s.isin(part)
            sub = PSDData(t[keep].reset_index(drop=True), model.data.process, model.data.source)
        m = ForwardModel(model.spec, sub, model.grid)
        r = fit(m, params, seed=int(seed[-1]), grid_check=False, quiet=True, **fit_opts)
        st = r.stats["params"]["ln_A0"]
        est.append((st["value"], st["se"]))
    (a, sa), (b, sb) = est
    d = b - a
    return 100.0 * math.expm1(d), d / math.hypot(sa, sb), d


def _split(design):
    """Short and long halves of the milling (batch) or residence times (continuous)."""
    if design.is_batch:
        t = list(design.times_s)
        h = len(t) // 2
        return (tuple(t[:h]), tuple(t[h:])) if h >= 2 and len(t) - h >= 2 else None
    tau = dict(design.process).get("tau_s")
    if tau is None or len(tau) < 4:
        return None
    order = [c for _, c in sorted(zip(tau, design.conditions))]
    h = len(order) // 2
    return tuple(order[:h]), tuple(order[h:])


def study(truth, assumed: ModelSpec, design, *, noise, strengths=None, replicates: int = 50, seed: int = 0,
          params: dict | None = None, fit_options: dict | None = None, drift_replicates: int = 10,
          workers: int = 1, progress=None) -> StudyResult:
    """Run a falsification study.

    Parameters
    ----------
    truth : a truth object (see :mod:`.truths`), or a callable strength -> truth for a sweep.
    assumed : the model that is fitted (e.g. ``ModelSpec(mode="well_mixed", tau_column="tau_s")``).
    design : :class:`~millflow.falsify.design.Design`.
    noise : :class:`~millflow.falsify.noise.GaussianNoise` or ``AR1Noise``.
    strengths : strengths of the sweep (``truth`` callable); None: ``truth`` is one truth.
    replicates : R, replicates per strength (>= 2).
    params : name -> :class:`Parameter` of the assumed model (bounds of the global
        search); default :func:`default_parameters`.
    fit_options : settings of :func:`millflow.fitting.fit` (default :data:`FIT_DEFAULTS`).
    drift_replicates : replicates (the first ones) on which the short/long refits are run.
    workers : processes (1: serial in this process).
    """
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    if not (isinstance(replicates, int) and replicates >= 2):
        raise InputError(f"replicates = {replicates!r}: expected an integer >= 2")
    if not (isinstance(workers, int) and workers >= 1):
        raise InputError(f"workers = {workers!r}: expected an integer >= 1")
    if strengths is None:
        truths = [truth]
    else:
        if not callable(truth):
            raise InputError("study: with strengths, truth must be a callable strength -> truth")
        truths = [truth(s) for s in strengths]
    params = params or study_parameters(assumed, truths[0].params)
    names = [n for n in assumed.param_names if params[n].vary]
    fit_opts = {**FIT_DEFAULTS, **(fit_options or {})}
    keys = design.sample_keys()
    split = _split(design)
    tasks = []
    for ks, tr in enumerate(truths):
        M = tr.mass_fractions(design)
        if M.shape != (len(keys), design.grid.n):
            raise SolverError(f"truth {tr.name!r} returned {M.shape}; expected {(len(keys), design.grid.n)}")
        clean = design.passing_at_sieves(M).ravel()
        for r in range(replicates):
            tasks.append((design, keys, clean, assumed, params, noise, (seed, ks, r), fit_opts,
                          split is not None and r < drift_replicates, split))
    say(f"{len(truths)} strength(s) x {replicates} replicates = {len(tasks)} fits of {len(names)} parameters")
    if workers == 1:
        outs = []
        for k, t in enumerate(tasks):
            outs.append(_fit_one(t))
            if (k + 1) % max(1, len(tasks) // 10) == 0:
                say(f"  {k + 1}/{len(tasks)} fits")
    else:
        with ProcessPoolExecutor(max_workers=workers) as ex:
            outs = list(ex.map(_fit_one, tasks, chunksize=max(1, len(tasks) // (4 * workers))))
    ds = _dataset(truths, names, outs, replicates, noise)
    ds.attrs.update({"assumed": assumed.label(), "fit_options": str(fit_opts), "seed": seed,
                     "design": _design_label(design)})
    return StudyResult(ds, time.perf_counter() - t0, {"fit_options": fit_opts, "workers": workers})


def _design_label(design) -> str:
    what = (f"times_s {list(design.times_s)}" if design.is_batch
            else f"conditions {list(design.conditions)}, process {dict(design.process)}")
    return f"{len(design.sieves_m)} sieves, grid {design.grid.n} classes, {what}"


def _dataset(truths, names, outs, R, noise) -> xr.Dataset:
    S, P = len(truths), len(names)
    shape = (S, R, P)
    est, se, lo, hi = (np.array([o[k] for o in outs]).reshape(shape) for k in ("est", "se", "lo", "hi"))
    scal = {k: np.array([o[k] for o in outs], float).reshape(S, R) for k in ("r2", "ser", "runs_p", "lag1")}
    drift = np.array([o["drift"] for o in outs], float).reshape(S, R, 3)
    failed = np.array([bool(o["error"]) for o in outs]).reshape(S, R)
    # a truth's own non-linear parameters (beta0, lam_pop, s_slow) count where the assumed model fits them
    truth = np.array([[float({**tr.params, **getattr(tr, "kinetic_truth", {})}.get(n, np.nan)) for n in names]
                      for tr in truths])
    tv = truth[:, None, :]
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        # all-NaN columns (parameters the truth lacks, failed fits) give NaN, which is the answer
        warnings.simplefilter("ignore", RuntimeWarning)
        err = est - tv
        bias = np.nanmean(err, axis=1)
        bias_se = np.nanmean(err / se, axis=1)
        is_ln = np.array([n.startswith("ln_") for n in names])
        bias_pct = np.where(is_ln, 100.0 * np.expm1(bias), 100.0 * bias / np.abs(truth))
        ok = ~failed[:, :, None] & np.isfinite(lo) & np.isfinite(hi)
        inside = (lo <= tv) & (tv <= hi)
        coverage = np.where(np.isfinite(truth), np.sum(inside & ok, axis=1) / np.maximum(np.sum(ok, axis=1), 1), np.nan)
        se_ratio = np.nanstd(est, axis=1, ddof=1) / np.nanmean(se, axis=1)
    sigma = noise.sigma
    dims2, dims3 = ("strength", "parameter"), ("strength", "replicate", "parameter")
    strength = np.array([tr.strength for tr in truths], float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        scal_mean = {k: np.nanmean(v, axis=1) for k, v in scal.items()}
        reject = np.nanmean(np.where(np.isfinite(scal["runs_p"]), scal["runs_p"] < 0.05, np.nan), axis=1)
    ds = xr.Dataset(
        {
            "truth": (dims2, truth, {"long_name": "true value (NaN: the truth has no such parameter)"}),
            "mean_estimate": (dims2, np.nanmean(est, axis=1)),
            "bias": (dims2, bias, {"long_name": "mean(estimate) - truth"}),
            "bias_se": (dims2, bias_se, {"long_name": "mean((estimate - truth) / reported SE)", "units": "SE"}),
            "bias_pct": (dims2, bias_pct, {"long_name": "bias in percent (of X for ln_X)", "units": "%"}),
            "coverage": (dims2, coverage, {"long_name": "fraction of reported 95 % intervals holding the truth"}),
            "se_ratio": (dims2, se_ratio, {"long_name": "sd of estimates / mean reported SE"}),
            "r2": ("strength", scal_mean["r2"], {"long_name": "mean R2 of cumulative passing"}),
            "ser": ("strength", scal_mean["ser"], {"long_name": "mean SER", "units": "1"}),
            "ser_over_sigma": ("strength", scal_mean["ser"] / sigma),
            "runs_reject": ("strength", reject,
                            {"long_name": "fraction of replicates where the runs test rejects at 5 %"}),
            "lag1": ("strength", scal_mean["lag1"], {"long_name": "mean lag-1 autocorrelation"}),
            "drift_pct": ("strength", _nanmean_or_nan(drift[:, :, 0]),
                          {"long_name": "A(long half) / A(short half) - 1", "units": "%"}),
            "drift_se": ("strength", _nanmean_or_nan(drift[:, :, 1]), {"units": "SE"}),
            "n_failed": ("strength", failed.sum(axis=1).astype(float)),
            "estimate": (dims3, est), "se": (dims3, se), "ci_low": (dims3, lo), "ci_high": (dims3, hi),
            "replicate_r2": (("strength", "replicate"), scal["r2"]),
            "replicate_ser": (("strength", "replicate"), scal["ser"]),
        },
        coords={"strength": strength, "parameter": names, "replicate": np.arange(R)},
        attrs={"truth": truths[0].name, "noise": repr(noise),
               "errors": "; ".join(sorted({o["error"] for o in outs if o["error"]}))[:2000]},
    )
    return ds


def _nanmean_or_nan(a):
    out = np.full(a.shape[0], np.nan)
    for k in range(a.shape[0]):
        v = a[k][np.isfinite(a[k])]
        if v.size:
            out[k] = v.mean()
    return out
