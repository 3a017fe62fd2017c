"""Replicate study of ``millflow diagnose``: does it choose the truth's class, and do the
chosen model's intervals hold the truth?

Truths, one per class of the candidate set, at the strengths where a first-order fit of the
documented batch design is biased by >= 20 % (docs/model-error.md, worked studies 2-4):

- ``linear``: first-order breakage (eqs. 5-6 at :data:`~.truths.BREAKAGE_TRUTH`);
- ``slowing_down``: kappa(t) = 1/(1 + s t/t_ref), s = 1, t_ref the last sampling time;
- ``cushioning``: S_i = S_i0 (1 + F)^(-1), F the mass fraction below the middle sieve
  (``lam_pop`` = -1 in the fitted form);
- ``aggregation``: breakage + constant-kernel aggregation, beta0 = 0.01 1/s, volumes in
  units of the finest sieve cubed.

Design (that of worked studies 2-4): batch grinding sampled at 0.5, 1, 2, 4, 8 and 16 min,
16 root-2 sieves from 4 mm, 33-class grid, feed in the top sieve interval, Gaussian noise
of sd ``sigma`` (default 0.01) on the cumulative passing. Replicate r of truth k draws its
noise from ``numpy.random.default_rng([seed, k, r])``; the config's model is first order
(:func:`~.study.study_parameters` bounds, the study's global-search settings with the
optimiser seed r), and :func:`millflow.fitting.diagnose.diagnose` ranks the candidate set
(linear, slowing-down, cushioning, aggregation) by BIC, without the leave-one-condition-out
and drift refits (they do not enter the choice).

Per truth: the fraction of replicates whose best-supported model is the truth's class, and
per parameter of the truth the fraction whose chosen model's 95 % interval holds the
truth's value. A replicate whose chosen model lacks a parameter of the truth (a wrong
class) counts as not covering it; a chosen model's extra parameter that the truth lacks
has the truth value 0 (the nesting value: s = 0, lambda = 0, beta0 = 0). Every rate comes
with its 95 % Clopper-Pearson interval (:func:`binomial_interval`).
"""
from __future__ import annotations

import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import beta as beta_dist

from millflow.errors import InputError, MillflowError

__all__ = ["TRUTH_CLASSES", "diagnose_study", "binomial_interval", "format_summary"]

#: class label -> (truth constructor name, strength, fitted extra parameter, its truth value)
TRUTH_CLASSES = {"linear": ("SlowingDownTruth", 0.0, None, None),
                 "slowing_down": ("SlowingDownTruth", 1.0, "s_slow", 1.0),
                 "cushioning": ("PopulationTruth", 1.0, "lam_pop", -1.0),
                 "aggregation": ("AggregationTruth", 0.01, "beta0", 0.01)}
#: The nesting value of each extra parameter (the linear model).
_NEST = {"s_slow": 0.0, "lam_pop": 0.0, "beta0": 0.0}
TIMES_S = tuple(30.0 * 2 ** k for k in range(6))


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Two-sided Clopper-Pearson interval of a binomial proportion k/n (exact, conservative)."""
    if n <= 0:
        return math.nan, math.nan
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(beta_dist.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta_dist.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def _truth(label, strength=None):
    from millflow.falsify import nonlinear_truths, truths
    name, default, _, _ = TRUTH_CLASSES[label]
    mod = truths if hasattr(truths, name) else nonlinear_truths
    return getattr(mod, name)(default if strength is None else strength)


def _truth_value(label, strength):
    """The fitted extra parameter's truth value at ``strength`` (cushioning: lambda = -s)."""
    _, default, extra, value = TRUTH_CLASSES[label]
    if extra is None or strength is None:
        return value
    return -strength if label == "cushioning" else strength


def _design():
    from millflow.falsify.design import batch_design
    return batch_design(list(TIMES_S))


def _one(task):
    """One replicate (runs in a worker): noisy data, diagnose, choice and coverage."""
    label, k, r, seed, sigma, clean, strength = task
    from millflow.falsify.study import FIT_DEFAULTS, study_parameters
    from millflow.falsify.truths import BREAKAGE_TRUTH
    from millflow.fitting.config import FitConfig
    from millflow.fitting.diagnose import diagnose
    from millflow.fitting.models import ModelSpec

    design = _design()
    rng = np.random.default_rng([seed, k, r])
    noisy = clean + sigma * rng.standard_normal(clean.size)
    data = design.data(noisy, design.sample_keys())
    spec = ModelSpec(mode="batch")
    cfg = FitConfig("diagnose study", data, spec, study_parameters(spec, BREAKAGE_TRUTH), design.grid,
                    {"global_search": True, **FIT_DEFAULTS, "seed": r})
    extra = TRUTH_CLASSES[label][2]
    truth = {**BREAKAGE_TRUTH, **({extra: _truth_value(label, strength)} if extra else {})}
    t0 = time.perf_counter()
    try:
        dg = diagnose(cfg, quiet=True, loco=False, drift=False, separation=False)
    except MillflowError as exc:
        return {"truth": label, "replicate": r, "error": str(exc), "runtime_s": time.perf_counter() - t0}
    st = dg.fits[dg.best].stats["params"]
    cover = {}
    for n, v in truth.items():
        lo, hi = st[n]["ci95"] if n in st else (math.nan, math.nan)
        cover[n] = bool(lo <= v <= hi)
    for n in st:
        if n in _NEST and n not in truth:  # the chosen model's extra parameter at its nesting value
            lo, hi = st[n]["ci95"]
            cover[n] = bool(lo <= _NEST[n] <= hi)
    rows = {row["model"]: row["delta_bic"] for row in dg.table}
    return {"truth": label, "replicate": r, "best": dg.best, "delta_bic": rows,
            "estimates": {n: (s["value"], s["se"], *s["ci95"]) for n, s in st.items()},
            "covered": cover, "notes": dg.notes, "runtime_s": time.perf_counter() - t0}


def diagnose_study(replicates: int = 20, *, truths=tuple(TRUTH_CLASSES), sigma: float = 0.01, seed: int = 0,
                   workers: int = 1, first: int = 0, strengths: dict | None = None, progress=None) -> dict:
    """Run the study (module docstring) on replicates ``first`` .. ``first + replicates - 1``
    of each truth (so that a run can be extended by another with the same seed);
    ``strengths`` (label -> strength) replaces a truth's default strength; returns the
    summary dict of :func:`summarize` with the raw replicate records under
    ``"replicates"``."""
    if not (isinstance(replicates, int) and replicates >= 1):
        raise InputError(f"replicates = {replicates!r}: expected an integer >= 1")
    unknown = [t for t in truths if t not in TRUTH_CLASSES]
    if unknown:
        raise InputError(f"truths {unknown}: expected some of {list(TRUTH_CLASSES)}")
    design = _design()
    tasks = []
    for label in truths:
        k = list(TRUTH_CLASSES).index(label)
        strength = (strengths or {}).get(label)
        clean = design.passing_at_sieves(_truth(label, strength).mass_fractions(design)).ravel()
        tasks += [(label, k, r, seed, sigma, clean, strength) for r in range(first, first + replicates)]
    t0 = time.perf_counter()
    records = []
    if workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            for rec in ex.map(_one, tasks):
                records.append(rec)
                if progress:
                    progress(rec)
    else:
        for task in tasks:
            records.append(_one(task))
            if progress:
                progress(records[-1])
    out = summarize(records)
    out.update({"replicates_per_truth": replicates, "first_replicate": first, "sigma": sigma, "seed": seed,
                "strengths": {label: (strengths or {}).get(label, TRUTH_CLASSES[label][1]) for label in truths},
                "workers": workers, "runtime_s": time.perf_counter() - t0,
                "design": f"batch, times {[t / 60 for t in TIMES_S]} min, 16 root-2 sieves from 4 mm, 33 classes",
                "replicates": records})
    return out


def summarize(records) -> dict:
    """Choice and coverage rates per truth (with Clopper-Pearson 95 % intervals)."""
    per = {}
    for label in dict.fromkeys(r["truth"] for r in records):
        recs = [r for r in records if r["truth"] == label]
        ok = [r for r in recs if "error" not in r]
        n = len(recs)
        chosen = sum(r["best"] == label for r in ok)
        counts = {}
        for r in ok:
            counts[r["best"]] = counts.get(r["best"], 0) + 1
        names = list(dict.fromkeys(nm for r in ok for nm in r["covered"]))
        cov = {}
        for nm in names:
            c = sum(bool(r["covered"].get(nm, False)) for r in ok if nm in r["covered"])
            m = sum(nm in r["covered"] for r in ok)
            cov[nm] = {"rate": c / m if m else math.nan, "n": m, "ci95": binomial_interval(c, m)}
        right = [r for r in ok if r["best"] == label]
        cov_right = {nm: sum(bool(r["covered"].get(nm, False)) for r in right) / len(right) if right else math.nan
                     for nm in names if all(nm in r["covered"] for r in right)}
        joint = sum(all(r["covered"].values()) for r in ok)
        per[label] = {"n": n, "failed": n - len(ok), "chosen": chosen, "choice_rate": chosen / n,
                      "choice_ci95": binomial_interval(chosen, n), "choices": counts, "coverage": cov,
                      "joint_coverage": joint / n, "joint_ci95": binomial_interval(joint, n),
                      "coverage_given_right_choice": cov_right,
                      "median_runtime_s": float(np.median([r["runtime_s"] for r in recs]))}
    return {"truths": per}


def format_summary(s: dict) -> str:
    lines = [f"{'truth':<14}{'chosen':>8}{'rate (95 % CI)':>22}  choices; coverage of the chosen model's 95 % "
             "intervals per parameter"]
    for label, t in s["truths"].items():
        lo, hi = t["choice_ci95"]
        ch = ", ".join(f"{k} {v}" for k, v in t["choices"].items())
        lines.append(f"{label:<14}{t['chosen']:>4}/{t['n']:<3}{t['choice_rate']:>8.2f} ({lo:.2f}-{hi:.2f})  {ch}"
                     + (f"; {t['failed']} failed" if t["failed"] else ""))
        cov = "  ".join(f"{n} {c['rate']:.2f}" + ("" if c["n"] == t["n"] else f" (of {c['n']})")
                        for n, c in t["coverage"].items())
        lines.append(f"{'':<14}coverage: {cov}; all at once {t['joint_coverage']:.2f}; "
                     f"median {t['median_runtime_s']:.1f} s per replicate")
        right = "  ".join(f"{n} {v:.2f}" for n, v in t["coverage_given_right_choice"].items())
        lines.append(f"{'':<14}coverage where the truth's class was chosen: {right}")
    return "\n".join(lines)
