"""Which model do the data support? Fit a candidate set and rank it (Principle I).

Candidates, built from the user's fit config (its rate, breakage, transport and data):

- ``linear``: the user's model without non-linear kinetics (first-order, eq. 4/3);
- ``slowing_down`` (batch data only): S_i(t) = S_i0 / (1 + s t/t_ref);
- ``cushioning``: population-dependent rates S_i (1 + F_fines)^lambda;
- ``aggregation``: breakage + constant-kernel aggregation, beta0 [1/s];
- continuous data, alternative RTDs: mode ``well_mixed`` with ``n_tanks`` 2 and 3; mode
  ``mill`` with tanks in series n - 1 and n + 1 (perfect mixing: 2 and 3 tanks),
  recirculating cells with r fitted (``cells_r_fitted``), axial dispersion with Pe
  fitted (``axial_pe_fitted``; also for plug flow, its Pe -> infinity limit);
- continuous data without classification in the user's model: a ``screen_power``
  classification when the process table has a screen column.

The non-linear kinetics keep the user's classification and transport where the
non-linear solves take them (classification in well-mixed cells); a combination the
model refuses is left out of the set with a note.

Each candidate is fitted (:func:`millflow.fitting.estimate.fit`). A candidate with one
extra parameter that holds the linear model at a known value (the kinetics at 0; r at the
user's r; ln Pe at the user's, or large for plug flow) starts from the linear fit's
optimum with the extra parameter there and at two other values (local starts: the global
search is the linear fit's); the extra parameter's bounds are :data:`EXTRA_BOUNDS` unless
the config bounds it. The other candidates get the config's global search. Ranking: BIC
(the selection rule: consistent, so a true model in the set wins with probability -> 1)
and AICc; the leave-one-condition-out prediction RMSE where there are >= 3 conditions.
Per candidate: the drift test (ln A0 fitted to the short and the long half of the times,
batch, or of the residence times, continuous: the classical symptom of non-linear
breakage), and the residual structure (mean lag-1 autocorrelation within samples,
runs-test rejection fraction). A verdict per parameter of the user's model: "consistent"
when the best-supported model is the user's, or the parameter differs between the two by
less than 2 combined SE; otherwise "falsified: the data prefer X, under which this
parameter is Y +- SE".
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from millflow.errors import InputError, MillflowError
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel, ModelSpec, Parameter, default_parameters
from millflow.fitting.progress import reporter
from millflow.mill.transport import (cell_count, is_axial_dispersion, is_cells, is_network, is_plug, is_tanks,
                                     mode_transport)

__all__ = ["Diagnosis", "candidate_specs", "diagnose"]

#: Sobol-free fixed starts of the extra non-linear parameter (besides 0), per parameter.
_EXTRA_STARTS = {"s_slow": (0.5, 2.0), "lam_pop": (-0.5, -1.5), "beta0": (0.005, 0.02)}
#: Bounds of the extra non-linear parameter of a candidate the user's config does not
#: bound (a config that fits the parameter itself keeps its own bounds): s_slow in [0, 10]
#: (kappa down to 1/11 by t_ref); lam_pop in [-2, 0]: the candidate is fines *cushioning*
#: (rates down to 1/4 when the whole charge is fines; lambda > 0, nipping, is another
#: mechanism: fit it with kinetics = "population" and its own bounds), and one-sided like
#: the other two, so that a first-order truth's chance fluctuations towards nipping do
#: not count as evidence (with [-2, 1], 1 of 50 linear replicates chose lambda = +0.8);
#: beta0 in [0, 0.03] 1/s (at 0.03 a first-order fit of the documented designs already
#: misses by 2.8 noise levels, docs/model-error.md). A candidate whose estimate ends at
#: one of these bounds is flagged by the fit ("at bound"); widen it with [params.NAME].
EXTRA_BOUNDS = {"s_slow": (0.0, 10.0), "lam_pop": (-2.0, 0.0), "beta0": (0.0, 0.03)}


def candidate_specs(spec: ModelSpec, data) -> dict:
    """label -> ModelSpec of the candidate set for the user's ``spec`` and data."""
    base = replace(spec, kinetics=(), kinetics_params=())
    out = {"linear": base}
    batch = spec.mode == "batch"
    cls_ok = spec.classification is None
    if batch:
        out["slowing_down"] = replace(base, kinetics=("slowing_down",))
    try:  # with the user's classification where the non-linear solves take it
        out["cushioning"] = replace(base, kinetics=("population",))
        out["aggregation"] = replace(base, kinetics=("aggregation",))
    except InputError:  # a transport or classification the non-linear solves do not cover
        out.pop("cushioning", None)
    if spec.mode != "mill" and not batch and is_cells(mode_transport(spec.mode, spec.n_tanks)[0]):
        for n in (2, 3):  # a mode of well-mixed tanks: its alternatives in the number of tanks
            if n != spec.n_tanks:
                out[f"tanks_{n}"] = replace(base, n_tanks=n)
    if spec.mode == "mill":
        out.update(_transport_alternatives(base))
    if not batch and cls_ok and spec.screen_column in data.process.columns:
        try:
            out["classification"] = replace(base, classification="screen_power")
        except InputError:
            pass
    return out


def _transport_alternatives(base: ModelSpec) -> dict:
    """Alternative RTDs of a mode-"mill" model: tanks in series n - 1 and n + 1 (perfect
    mixing: 2 and 3 tanks); recirculating cells with the recirculation ratio r fitted;
    axial dispersion with the Peclet number fitted (plug flow: axial dispersion with Pe
    fitted, which holds plug flow as Pe -> infinity). A combination the mill model refuses
    (e.g. a classification placement of another transport) is left out."""
    tr, tp, fitted = base.transport, dict(base.transport_params), base.transport_fit
    specs = {}
    if is_cells(tr) and not is_network(tr):  # perfect mixing or tanks in series
        n = int(round(float(cell_count(tr, tp))))
        for m in sorted({max(n - 1, 1), n + 1} - {n}) if is_tanks(tr) else (2, 3):
            specs[f"tanks_{m}" if m > 1 else "perfect_mixing"] = dict(
                transport="tanks_in_series" if m > 1 else "perfect_mixing",
                transport_params={**{k: v for k, v in tp.items() if k != "n"}, **({"n": m} if m > 1 else {})})
    elif is_network(tr) and "r" not in fitted:
        specs["cells_r_fitted"] = dict(transport_params={k: v for k, v in tp.items() if k != "r"},
                                       transport_fit=fitted + ("r",))
    elif is_axial_dispersion(tr) and "pe" not in fitted:
        specs["axial_pe_fitted"] = dict(transport_params={k: v for k, v in tp.items() if k != "pe"},
                                        transport_fit=fitted + ("pe",))
    elif is_plug(tr):
        specs["axial_pe_fitted"] = dict(transport="axial_dispersion", transport_params={},
                                        transport_fit=fitted + ("pe",))
    out = {}
    for label, change in specs.items():
        try:
            out[label] = replace(base, **change)
        except InputError:
            pass
    return out


def _nesting_values(user: ModelSpec) -> dict:
    """Value of each extra parameter at which its candidate is the linear (user's) model:
    0 for the kinetics; the user's r and ln Pe for a fitted transport (ln Pe 6, Pe ~ 400,
    for plug flow: the candidate's nearest point to it)."""
    tp = dict(user.transport_params)
    out = {"s_slow": 0.0, "lam_pop": 0.0, "beta0": 0.0}
    if "r" in tp:
        out["r"] = float(tp["r"])
    elif is_network(user.transport):
        out["r"] = 1.0  # rtd's default recirculation ratio
    if "pe" in tp:
        out["ln_pe"] = math.log(float(tp["pe"]))
    elif is_plug(user.transport):
        out["ln_pe"] = 6.0
    return out


@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`: ``table`` (rows per candidate, best BIC first), ``fits``
    (label -> FitResult), ``verdicts`` (user parameter -> text), ``best`` (label)."""

    table: list
    fits: dict
    verdicts: dict
    best: str
    user: str
    runtime_s: float
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        fits = {label: {n: {"value": s["value"], "se": s["se"], "ci95": s["ci95"]}
                        for n, s in r.stats["params"].items()} for label, r in self.fits.items()}
        return {"best": self.best, "user_model": self.user, "table": self.table, "verdicts": self.verdicts,
                "parameters": _clean(fits), "notes": self.notes, "runtime_s": self.runtime_s}

    def text(self) -> str:
        lines = [f"{'candidate':<16}{'p':>3}{'SSR':>12}{'BIC':>10}{'dBIC':>8}{'AICc':>10}{'LOCO RMSE':>11}"
                 f"{'drift A % (SE)':>18}{'lag-1':>7}{'runs':>6}"]
        for r in self.table:
            loco = "-" if r["loco_rmse"] is None else f"{r['loco_rmse']:.4f}"
            drift = "-" if r["drift_pct"] is None else f"{r['drift_pct']:+.1f} ({r['drift_se']:+.1f})"
            lag = "-" if r["lag1"] is None else f"{r['lag1']:.2f}"
            runs = "-" if r["runs_reject"] is None else f"{r['runs_reject']:.2f}"
            lines.append(f"{r['model']:<16}{r['n_params']:>3}{r['ssr']:>12.5g}{r['bic']:>10.2f}{r['delta_bic']:>8.2f}"
                         f"{r['aicc']:>10.2f}{loco:>11}{drift:>18}{lag:>7}{runs:>6}")
        lines.append(f"best supported (BIC): {self.best}; the user's model: {self.user}")
        for r in self.table:
            if r.get("separation_lambda") is not None:
                p = r.get("repeat_choice")
                lines.append(f"  separated from {r['model']}: lambda = {r['separation_lambda']:.3g}"
                             + ("" if p is None else f", a repeat prefers {self.best} in ~{100 * p:.0f} %"))
        for name, v in self.verdicts.items():
            lines.append(f"  {name}: {v}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _clean(v):
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    return v


def _params_for(spec, user_params: dict, start: dict | None = None) -> dict:
    """The user's bounds for shared parameters, :data:`EXTRA_BOUNDS` for a candidate's
    extra non-linear parameter, defaults for the others; start values from ``start`` (a
    previous fit) where given."""
    base = default_parameters(spec)
    out = {}
    for n, par in base.items():
        if n not in user_params and n in EXTRA_BOUNDS:
            lo, hi = EXTRA_BOUNDS[n]
            par = Parameter(n, min(max(par.value, lo), hi), lo, hi, par.vary)
        p = user_params.get(n, par)
        v = float(start[n]) if start and n in start else p.value
        out[n] = Parameter(n, min(max(v, p.min), p.max), p.min, p.max, p.vary)
    return out


def _starts(extra: str, nest: float) -> tuple:
    """Local starts of a nested candidate's extra parameter: the nesting value first."""
    if extra in _EXTRA_STARTS:
        return (nest,) + _EXTRA_STARTS[extra]
    if extra == "r":
        return (nest, 0.25 * nest, 4.0 * nest) if nest > 0 else (0.0, 0.5, 2.0)
    return (nest, nest - 2.0, nest - 4.0)  # ln_pe: towards more back-mixing


def _fit_candidate(model, params, linear_theta, optimizer, extra, nest=0.0):
    """A nested candidate (one extra parameter, the linear model at ``nest``): local fits
    from the linear optimum with the extra parameter at ``nest`` and at fixed starts; the
    best start is refitted once more with the profile intervals (which the other starts
    do not need). Any other candidate: the config's global search."""
    if linear_theta is None or not extra:
        return fit(model, params, grid_check=False, quiet=True, **optimizer)
    best, last_error = None, None
    for v in _starts(extra, nest):
        par = _with_start(params, {**linear_theta, extra: v})
        try:
            r = fit(model, par, global_search=False, starts=1, grid_check=False, quiet=True, profile=False)
        except MillflowError as exc:
            last_error = f"{extra} = {v:g}: {exc}"
            continue
        if best is None or r.ssr < best.ssr:
            best = r
    if best is None:
        raise InputError(f"no start of the candidate could be fitted (last start, {last_error})")
    par = _with_start(params, {n: s["value"] for n, s in best.stats["params"].items()})
    try:
        final = fit(model, par, global_search=False, starts=1, grid_check=False, quiet=True)
    except MillflowError:
        return best
    return final if final.ssr <= best.ssr * (1 + 1e-9) else best


def _with_start(params, start):
    """``params`` with the values of ``start`` (clipped to the bounds) where it has one."""
    return {n: (Parameter(n, min(max(float(start[n]), q.min), q.max), q.min, q.max, q.vary) if n in start else q)
            for n, q in params.items()}


def _drift(model, params, optimizer, result):
    """ln A0 on the long half minus the short half (batch: times; continuous: tau), in %
    and in SE; None where the data have no such halves."""
    from millflow.fitting.data import PSDData
    spec = model.spec
    if "ln_A0" not in result.stats["params"]:
        return None, None
    t = model.data.table
    if spec.mode == "batch":
        if model._nonlinear is not None and "slowing_down" in spec.kinetics:
            # kappa(t) keeps its reference time: a half of the data must not redefine s
            spec = replace(spec, kinetics_params={**dict(spec.kinetics_params), "t_ref_s": model._nonlinear.t_ref})
        times = sorted({g[2] for g in model.groups})
        h = len(times) // 2
        if h < 2 or len(times) - h < 2:
            return None, None
        halves = []
        for part in (times[:h], times[h:]):
            keep = (t.location == "feed") | t.time_s.isin(part)
            halves.append(ForwardModel(spec, PSDData(t[keep].reset_index(drop=True), model.data.process,
                                                     model.data.source), model.grid))
    else:
        if not spec.tau_column or len(model.conditions) < 4:
            return None, None
        tau = model.data.process.loc[model.conditions, spec.tau_column].to_numpy(float)
        order = [c for _, c in sorted(zip(tau, model.conditions))]
        h = len(order) // 2
        halves = [model.for_conditions(order[:h]), model.for_conditions(order[h:])]
    est = []
    start = {n: s["value"] for n, s in result.stats["params"].items()}
    for m in halves:
        r = fit(m, _params_for(spec, params, start), global_search=False, starts=1, grid_check=False, quiet=True,
                profile=False)
        s = r.stats["params"]["ln_A0"]
        est.append((s["value"], s["se"]))
    (a, sa), (b, sb) = est
    return 100.0 * math.expm1(b - a), (b - a) / math.hypot(sa, sb)


def diagnose(cfg, *, progress=None, quiet: bool = False, loco: bool = True, drift: bool = True,
             separation: bool = True, candidates=None) -> Diagnosis:
    """Fit the candidate set of a fit config (:class:`~millflow.fitting.config.FitConfig`)
    and rank it; see the module docstring. ``loco=False`` skips the leave-one-condition-out
    refits, ``drift=False`` the drift refits, ``separation=False`` the noise-free refits
    of :func:`separation` (none of them changes the ranking by BIC, the choice, or the
    candidates' estimates and intervals). ``candidates``: labels to fit (default all;
    ``linear`` and the user's model are always fitted)."""
    from millflow.fitting.statistics import information_criteria
    from millflow.fitting.validate import condition_rmse

    say = reporter(progress, quiet, "diagnose")
    t0 = time.perf_counter()
    user_spec = cfg.spec
    specs = candidate_specs(user_spec, cfg.data)
    user_label = next((k for k, s in specs.items() if s == user_spec), None)
    if user_label is None:  # the user's own non-linear model joins the set
        user_label = "user: " + "+".join(user_spec.kinetics)
        specs[user_label] = user_spec
    kinetics_left_out = user_spec.classification is not None and "aggregation" not in specs
    if candidates is not None:
        unknown = sorted(set(candidates) - set(specs))
        if unknown:
            raise InputError(f"diagnose: candidates {unknown} are not in the set for this config; expected some of "
                             f"{list(specs)}")
        specs = {k: v for k, v in specs.items() if k in set(candidates) | {"linear", user_label}}
    grid = cfg.model().grid
    fits, rows, notes = {}, [], []
    if kinetics_left_out:
        notes.append(f"non-linear candidates (cushioning, aggregation) take classification in well-mixed cells "
                     f"only; the model's classification ({user_spec.classification}, transport "
                     f"{user_spec.transport or user_spec.mode}) keeps them out of the set")
    linear_theta = None
    nest = _nesting_values(user_spec)
    order = ["linear"] + [k for k in specs if k != "linear"]
    for label in order:
        spec = specs[label]
        model = cfg.model(spec, grid)
        params = _params_for(spec, cfg.params)
        extra = [n for n in spec.param_names if n not in specs["linear"].param_names]
        nested = extra[0] if len(extra) == 1 and extra[0] in nest else None
        say(f"fitting {label} ({len(params)} parameters)")
        try:
            res = _fit_candidate(model, params, linear_theta, cfg.optimizer, nested, nest.get(nested, 0.0))
        except MillflowError as exc:
            notes.append(f"{label}: not fitted ({exc})")
            continue
        if label == "linear":
            linear_theta = {n: s["value"] for n, s in res.stats["params"].items()}
        fits[label] = res
        ic = information_criteria(res.ssr, res.n_data, res.n_params)
        loco_rmse = None
        if loco and len(model.conditions) >= 3:
            errs = []
            for c in model.conditions:
                train = [x for x in model.conditions if x != c]
                start = {n: s["value"] for n, s in res.stats["params"].items()}
                r = fit(model.for_conditions(train), _params_for(spec, params, start), global_search=False, starts=1,
                        grid_check=False, quiet=True, profile=False)
                errs.extend(condition_rmse(model.for_conditions([c]), r.theta).values())
            loco_rmse = float(np.sqrt(np.mean(np.square(errs))))
        d_pct, d_se = None, None
        if drift:
            try:
                d_pct, d_se = _drift(model, cfg.params, cfg.optimizer, res)
            except MillflowError:
                pass
        rs = res.stats.get("residuals") or {}
        rows.append({"model": label, "label": spec.label(), "n_params": res.n_params, "ssr": res.ssr,
                     "bic": ic["bic"], "aicc": ic["aicc"], "aic": ic["aic"], "loco_rmse": loco_rmse,
                     "drift_pct": d_pct, "drift_se": d_se, "lag1": _f(rs.get("mean_lag1")),
                     "runs_reject": _f(rs.get("runs_reject_fraction"))})
    if not rows:
        raise InputError("diagnose: no candidate could be fitted; " + "; ".join(notes))
    rows.sort(key=lambda r: r["bic"])
    for r in rows:
        r["delta_bic"] = r["bic"] - rows[0]["bic"]
        r["delta_aicc"] = r["aicc"] - min(x["aicc"] for x in rows)
    best = rows[0]["model"]
    if len(next(iter(fits.values())).model.conditions) < 3:
        notes.append("leave-one-condition-out prediction needs >= 3 conditions: not computed")
    if separation:
        say("separation of the close candidates on this design")
        for label, sep in _separation(fits, rows).items():
            row = next(r for r in rows if r["model"] == label)
            row.update(separation_lambda=sep["lambda"], repeat_choice=sep["repeat_choice"])
            if sep["repeat_choice"] is not None and sep["repeat_choice"] < REPEAT_CHOICE_WARN:
                notes.append(f"this design separates {best} from {label} weakly: {label} fitted to {best}'s "
                             f"noise-free prediction leaves lambda = {sep['lambda']:.3g} noise variances, so a "
                             f"repeat of the experiment would prefer {best} in about "
                             f"{100 * sep['repeat_choice']:.0f} % of repeats; more sampling times or conditions "
                             "where the two differ would separate them")
    verdicts = _verdicts(fits, user_label, best)
    return Diagnosis(_clean(rows), fits, verdicts, best, user_label, time.perf_counter() - t0, notes)


#: Candidates within this BIC of the best are checked by :func:`separation`.
SEPARATION_DBIC = 10.0
#: Below this repeat-choice probability diagnose says the design separates two models weakly.
REPEAT_CHOICE_WARN = 0.9


def separation(best, other) -> dict:
    """How far a design separates two fitted models: the noise-free refit of one to the other.

    ``other`` (a :class:`~millflow.fitting.estimate.FitResult` on the same data) is refitted
    to ``best``'s prediction without noise, from its own estimate. Its weighted SSR over
    the noise variance of ``best``'s fit, sigma^2 = SSR_best / (n - p_best), is the
    non-centrality lambda of the likelihood-ratio statistic between the two on this design
    (asymptotically, the data drawn from ``best``'s estimate). The probability that a
    repeat of the experiment prefers ``best`` by BIC, approximately: with as many
    parameters, Phi(sqrt(lambda)/2) (the difference of the two SSRs / sigma^2 is then
    about N(lambda, 4 lambda)); with k fewer in ``other``, P(chi'^2_k(lambda) > k ln n);
    None when ``other`` has more parameters (it may hold ``best``).

    Returns
    -------
    dict
        ``lambda`` [-] and ``repeat_choice`` (probability, or None).
    """
    import copy

    from scipy.stats import ncx2, norm

    n, k = best.n_data, best.n_params - other.n_params
    sigma2 = best.ssr / max(n - best.n_params, 1)
    target = best.model.predict(best.theta)
    model = copy.copy(other.model)
    model.y = target
    refit = fit(model, other.params, global_search=False, starts=1, grid_check=False, quiet=True, profile=False)
    lam = refit.ssr / sigma2 if sigma2 > 0 else math.inf
    if k < 0:
        return {"lambda": lam, "repeat_choice": None}
    p = float(norm.cdf(math.sqrt(lam) / 2)) if k == 0 else float(ncx2.sf(k * math.log(n), k, lam))
    return {"lambda": lam, "repeat_choice": p}


def _separation(fits, rows) -> dict:
    """:func:`separation` of the best candidate from each candidate within :data:`SEPARATION_DBIC`."""
    best = fits[rows[0]["model"]]
    out = {}
    for r in rows[1:]:
        other = fits.get(r["model"])
        if other is None or r["delta_bic"] > SEPARATION_DBIC or other.n_params > best.n_params:
            continue
        if other.model.y.shape != best.model.y.shape:
            continue
        try:
            out[r["model"]] = separation(best, other)
        except MillflowError:
            continue
    return out


def _f(v):
    return None if v is None or not math.isfinite(v) else float(v)


def _verdicts(fits, user, best) -> dict:
    if user not in fits:
        return {}
    out = {}
    us = fits[user].stats["params"]
    bs = fits[best].stats["params"]
    for n, s in us.items():
        if best == user:
            out[n] = f"consistent with the best-supported model ({best}): {s['value']:.4g} +- {s['se']:.2g}"
            continue
        if n not in bs:
            out[n] = f"falsified: the data prefer {best}, which has no parameter {n}"
            continue
        b = bs[n]
        diff = abs(s["value"] - b["value"])
        comb = math.hypot(s["se"], b["se"])
        if math.isfinite(comb) and diff <= 2 * comb:
            out[n] = (f"consistent with the best-supported model ({best}): {s['value']:.4g} +- {s['se']:.2g} here, "
                      f"{b['value']:.4g} +- {b['se']:.2g} there")
        else:
            out[n] = (f"falsified: the data prefer {best}, under which this parameter is {b['value']:.4g} +- "
                      f"{b['se']:.2g} (here {s['value']:.4g} +- {s['se']:.2g})")
    return out
