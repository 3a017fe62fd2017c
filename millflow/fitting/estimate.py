"""Global least-squares estimation (Principle V): checks, global search, multi-start, polish.

:func:`fit` minimises SSR = sum w (model - data)^2 over the varying parameters:

1. *Checks before any optimisation*: more data than varying parameters, data not
   all zero, and a finite model at the lower and upper bounds, the box centre and
   up to 64 corners of the box (:class:`~millflow.errors.InputError` otherwise).
2. *Global search*: scipy's ``differential_evolution`` with the whole population
   evaluated in one vectorised model call (``vectorized=True``).
3. *Multi-start local least squares*: scipy's ``least_squares`` (trust-region
   reflective, bounds) from the DE optimum and from scrambled-Sobol space-filling
   starts; Jacobians by central differences, all perturbations in one model call.
4. *Polish* the best solution with tight tolerances.

The best solutions of the different starts are kept: ``spread`` is the largest
relative difference, over parameters, between the best solution and any other start
that reaches the same SSR (within 1 %). A large spread at equal SSR means the data
do not determine the parameters (non-uniqueness); starts stuck at higher SSR are
local minima, shown in ``solutions``. Statistics follow eq. 9 (:mod:`.statistics`),
and the SSR is re-evaluated on a grid refined once more (Principle IV).
"""
from __future__ import annotations

import itertools
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import differential_evolution, least_squares
from scipy.stats import qmc

from millflow.errors import InputError, MillflowError, SolverError
from millflow.fitting.forward import ForwardModel
from millflow.fitting.spec import FORWARD_TOL, Parameter, default_parameters
from millflow.fitting.progress import reporter
from millflow.mill.transport import is_axial
from millflow.fitting.statistics import information_criteria, jacobian, parameter_statistics

__all__ = ["FitResult", "fit", "compare_models", "SAME_SSR_RTOL"]

#: Starts whose SSR is within this relative tolerance of the best count as equally good.
SAME_SSR_RTOL = 1e-2


@dataclass
class FitResult:
    """Outcome of :func:`fit`, lmfit-like: parameters with statistics and diagnostics."""

    model: ForwardModel
    params: dict            # name -> Parameter at the estimate (fixed ones included)
    stats: dict             # eq. 9 statistics of the varying parameters
    ssr: float
    n_data: int
    n_params: int
    starts: int
    spread: float
    solutions: list         # [(ssr, {name: value}), ...] best first, one per start
    nfev: int
    runtime_s: float
    grid_check: dict = field(default_factory=dict)
    message: str = ""
    error_estimate: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)  # what the fit met and worked around (e.g. failed solves)

    @property
    def ser(self) -> float:
        """Standard error of regression, sqrt(SSR / (n - p))."""
        return self.stats["ser"]

    @property
    def theta(self) -> np.ndarray:
        """The estimate as a vector in the order of ``model.param_names``."""
        return np.array([self.params[n].value for n in self.model.param_names])

    @property
    def criteria(self) -> dict:
        """Information criteria (AIC, AICc, BIC) of the fit."""
        return information_criteria(self.ssr, self.n_data, self.n_params)

    def predicted(self) -> np.ndarray:
        """Predicted values at the estimate, in the order of the data."""
        return self.model.predict(self.theta)

    def rmse_by_condition(self, model: ForwardModel | None = None) -> dict:
        """RMSE of cumulative passing per condition at every measured row (unweighted)."""
        m = model or self.model
        r = m.predict_cum(self.theta) - m.y_cum
        return {c: float(np.sqrt(np.mean(r[m.condition_of_value == c] ** 2))) for c in m.conditions}

    def to_dict(self) -> dict:
        """The fit as the JSON-able dict ``millflow fit --json`` prints."""
        out = {"model": self.model.spec.label(), "params": {}, "fixed": {}}
        for name, par in self.params.items():
            if name in self.stats["params"]:
                s = self.stats["params"][name]
                out["params"][name] = {k: _jsonable(s.get(k)) for k in
                                       ("value", "se", "t", "p_value", "ci95", "significant", "reasons",
                                        "se_eq9", "se_cluster", "covariance", "at_bound", "flags",
                                        "start_range", "grid_dependent", "ci95_wald")}
            else:
                out["fixed"][name] = par.value
        out.update({
            "ssr": self.ssr, "ser": _jsonable(self.ser), "n_data": self.n_data, "n_params": self.n_params,
            "starts": self.starts, "spread": _jsonable(self.spread),
            "condition_number": _jsonable(self.stats["condition_number"]),
            "covariance_kind": self.stats.get("covariance_kind", "eq. 9"),
            "se_ratio_max": _jsonable(self.stats.get("se_ratio_max", math.nan)),
            "se_ratio_flag": bool(self.stats.get("se_ratio_flag", False)),
            "residual_structure": {k: _jsonable(v) for k, v in self.stats.get("residuals", {}).items()
                                   if k != "per_sample"},
            "correlated_pairs": [list(p) for p in self.stats["correlated_pairs"]],
            "correlation": {"names": list(self.stats["params"]),
                            "matrix": _jsonable(np.round(self.stats["correlation"], 4).tolist())},
            "criteria": {k: _jsonable(v) for k, v in self.criteria.items()},
            "grid_check": {k: _jsonable(v) for k, v in self.grid_check.items()},
            "error_estimate": _jsonable_tree(self.error_estimate),
            "solutions": [{"ssr": s, "params": p} for s, p in self.solutions[:10]],
            "rmse_by_condition": self.rmse_by_condition(),
            "nfev": self.nfev, "runtime_s": self.runtime_s, "notes": list(self.notes),
            # eq. 9 covariance at full precision and what is needed to evaluate the fitted
            # model in another mill (millflow scaleup)
            "covariance": {"names": list(self.stats["params"]),
                           "matrix": _jsonable(np.asarray(self.stats["covariance"]).tolist())},
            "model_spec": self.model.describe(),
        })
        return out

    def summary(self) -> str:
        """The fit as a table of text: statistics and one row per parameter."""
        lines = [f"model: {self.model.spec.label()}",
                 f"n_data {self.n_data}, n_params {self.n_params}, SSR {self.ssr:.6g}, SER {self.ser:.4g}, "
                 f"starts {self.starts}, spread {self.spread:.3g}, "
                 f"condition number {self.stats['condition_number']:.3g}",
                 f"{'parameter':<16}{'value':>12}{'SEP':>11}{'p':>10}   95% interval          flags"]
        for name, s in self.stats["params"].items():
            lo, hi = s["ci95"]
            flag = "; ".join(s["reasons"]) if s["reasons"] else "ok"
            flag = "; ".join(s.get("flags", s["reasons"])) or "ok"
            pv = "-" if s["p_value"] is None else f"{s['p_value']:.2g}"
            lines.append(f"{name:<16}{s['value']:>12.5g}{s['se']:>11.3g}{pv:>10}   "
                         f"[{lo:.4g}, {hi:.4g}]  {flag}")
        for name, par in self.params.items():
            if name not in self.stats["params"]:
                lines.append(f"{name:<16}{par.value:>12.5g}   (fixed)")
        lines.append(f"SEP and intervals: {self.stats.get('covariance_kind', 'eq. 9')}"
                     + (f" ({self.stats['clusters']} samples)" if self.stats.get("clusters") else "")
                     + "; p omitted for ln_X parameters (X > 0 by construction: no meaningful null)")
        vc = self.stats.get("variance_components")
        if vc:
            lines.append(f"weights: tracer rows x{vc['tracer_weight']:.3g} from the variance components (residual SD "
                         f"tracer {vc['sd']['tracer']:.3g}, sieves {vc['sd']['psd']:.3g})")
        if self.stats.get("se_ratio_flag"):
            lines.append(f"flag: cluster-robust SEs up to {self.stats['se_ratio_max']:.2g}x eq. 9's, from "
                         f"{self.stats['clusters']} samples: residuals are correlated within samples; eq. 9 alone "
                         "would overstate the precision")
        rs = self.stats.get("residuals")
        if rs:
            lines.append(f"residuals: mean lag-1 autocorrelation within samples {rs['mean_lag1']:.2f}; runs test "
                         f"rejects randomness (p < 0.05) in {100 * rs['runs_reject_fraction']:.0f} % of samples")
        for a, b, c in self.stats["correlated_pairs"]:
            lines.append(f"correlation {a} / {b} = {c:+.3f} (> 0.95: not separately identifiable)")
        if self.grid_check:
            g = self.grid_check
            if "skipped" in g:
                lines.append(f"grid check skipped: {g['skipped']}")
            else:
                lines.append(f"grid check: SSR {g['ssr']:.6g} on {g['n']} classes; on {g['n_refined']} classes "
                             f"{g['ssr_refined']:.6g} at the same parameters (change {g['relative_change']:.2e}), "
                             f"{g['ssr_refit']:.6g} re-fitted (change {g['relative_change_refit']:.2e}, largest "
                             f"parameter shift {g['max_param_shift_in_se']:.2g} SEP)")
        ee = self.error_estimate
        if ee:
            gr, so = ee["grid"], ee["solver"]
            shown = "not estimated" if gr.get("value") is None else f"{gr['value']:.2g} SE"
            lines.append(f"error estimate: grid {shown} ({gr['method']}); solver {so['value']:.1e} relative "
                         f"({so['method']})")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


def _jsonable_tree(v):
    """A nested dict of plain values, numbers made JSON-able (NaN -> None)."""
    if isinstance(v, dict):
        return {k: _jsonable_tree(e) for k, e in v.items()}
    return _jsonable(v) if isinstance(v, (float, np.floating)) else v


def _jsonable(v):
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


#: Relative noise of a mill prediction that goes through the axial finite volumes: the
#: refinement stops at the first grid whose estimate is below FORWARD_TOL, so where that
#: grid changes with a parameter the product and hold-up jump by up to FORWARD_TOL and the
#: axial profiles (finest-grid values) by ~10 FORWARD_TOL (measured 8.5e-5 at Pe 5.29).
AXIAL_PREDICTION_NOISE = 10 * FORWARD_TOL


def prediction_noise(model) -> float | None:
    """The relative noise of ``model``'s predictions the finite-difference Jacobian must step over.

    The model's own ``fd_noise`` (machine epsilon for exact solves, the ODE tolerance for
    non-linear kinetics), raised to :data:`AXIAL_PREDICTION_NOISE` for a mill on a
    plug-flow or axial-dispersion transport: with the step for exact solves (1e-5 of the
    range) one such jump made a derivative 60 x too large and SE(ln Pe) 20 x too small
    (z = +31 in a coverage study).
    """
    noise = getattr(model, "fd_noise", None)
    spec = getattr(model, "spec", None)
    transport = getattr(spec, "transport", None)
    if getattr(spec, "mode", None) == "mill" and transport is not None and is_axial(transport, open_vessel=False):
        return max(float(noise or 0.0), AXIAL_PREDICTION_NOISE)
    return noise


class _Problem:
    """The varying parameters of a model as one vector, with vectorised residuals."""

    def __init__(self, model: ForwardModel, params: dict):
        self.model = model
        names = model.param_names
        missing = [n for n in names if n not in params]
        if missing:
            raise InputError(f"parameters {missing} have no value; expected all of {list(names)}")
        self.full = np.array([params[n].value for n in names], float)
        self.idx = np.array([k for k, n in enumerate(names) if params[n].vary], dtype=int)
        self.names = [names[k] for k in self.idx]
        self.lower = np.array([params[n].min for n in self.names], float)
        self.upper = np.array([params[n].max for n in self.names], float)
        self.fd_noise = prediction_noise(model)
        self.base_sw = np.sqrt(model.weights)
        self.row_factor = 1.0  # variance components re-weight rows (see _variance_components)
        self.sw = self.base_sw
        self.nfev = 0
        self.notes = []

    def expand(self, z):
        z = np.atleast_2d(z)
        th = np.tile(self.full, (z.shape[0], 1))
        th[:, self.idx] = z
        return th

    def resid_pop(self, z):
        self.nfev += np.atleast_2d(z).shape[0]
        return (self.model.predict(self.expand(z)) - self.model.y) * self.sw

    def resid(self, z):
        return self.resid_pop(z)[0]

    def ssr_pop(self, zT):  # differential_evolution's vectorised call: (p, S) -> (S,)
        r = self.resid_pop(np.asarray(zT).T)
        out = np.einsum("ij,ij->i", r, r)
        return np.where(np.isfinite(out), out, 1e300)

    def jac(self, z):
        return jacobian(self.resid_pop, z, self.lower, self.upper, self.fd_noise)


def check_problem(model: ForwardModel, params: dict) -> _Problem:
    """Check a problem before any optimisation (see module docstring).

    A model with
    non-linear kinetics whose steady or batch solve fails at some corners (e.g. Newton's
    iteration cap where the parameters make the mill extreme) is not refused for it: the
    fit goes on, those points count as infeasible, and ``prob.notes`` says so; the box
    centre or the start values must be solvable, and non-finite values without a failed
    solve (the model undefined there) are refused as for any model.
    """
    prob = _Problem(model, params)
    p, n = prob.idx.size, model.n_data
    if p == 0:
        raise InputError("no parameter varies; set vary = true for at least one")
    if p >= n:
        raise InputError(f"{p} varying parameters but only {n} measured values: need more data than parameters")
    if np.all(model.y == 0):
        raise InputError(f"{model.data.source}: every measured value is zero; there is nothing to fit")
    if not np.any(model.weights > 0):
        raise InputError("every weight is zero; there is nothing to fit")
    lo, hi = prob.lower, prob.upper
    pts = [lo, hi, 0.5 * (lo + hi), np.clip(prob.full[prob.idx], lo, hi)]
    corners = list(itertools.product([0, 1], repeat=p)) if p <= 6 else \
        np.random.default_rng(0).integers(0, 2, size=(64, p)).tolist()
    for c in corners:
        pts.append(np.where(np.array(c) == 1, hi, lo))
    pts = np.array(pts)
    nonlinear = getattr(model, "_nonlinear", None)
    failures = getattr(nonlinear, "failures", None)
    if failures is not None:
        failures.clear()
    try:
        R = prob.resid_pop(pts)
        bad = ~np.isfinite(R).all(axis=1)
    except MillflowError as exc:
        raise InputError(f"the model cannot be evaluated inside the bounds: {exc}") from exc
    except (FloatingPointError, ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(f"the model cannot be evaluated inside the bounds: {exc}") from exc
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        where = ", ".join(f"{nm}={v:.4g}" for nm, v in zip(prob.names, pts[k]))
        if failures and not (bad[2] and bad[3]):
            prob.notes.append(f"the non-linear solve failed at {int(bad.sum())} of {len(pts)} points checked in "
                              f"the bounds (e.g. {where}: {failures[-1]}); the fit went on with them infeasible")
        else:
            raise InputError(f"the model gives non-finite values at a corner of the bounds ({where}); "
                             "narrow the bounds of these parameters")
    if failures is not None:
        failures.clear()
    prob.nfev = 0
    return prob


def _local(prob: _Problem, z0, tight: bool = False):
    # the tight pass asks no more than the predictions resolve: 1e-12 for the exact
    # solves, the loose 1e-8 where an ODE tolerance (fd_noise) limits them
    noise = float(getattr(prob, "fd_noise", 0.0) or 0.0)
    tol = (1e-12 if noise < 1e-12 else 1e-8) if tight else 1e-8
    z0 = np.clip(z0, prob.lower, prob.upper)
    try:
        r = least_squares(prob.resid, z0, jac=prob.jac, bounds=(prob.lower, prob.upper), method="trf",
                          x_scale="jac", ftol=tol, xtol=tol, gtol=tol, max_nfev=200 if tight else 60)
    except ValueError as exc:  # a start (or a step's Jacobian) where the model cannot be solved
        if "not finite" not in str(exc) and "infs or NaNs" not in str(exc):
            raise
        return z0, math.inf
    return r.x, float(2 * r.cost)


def fit(model: ForwardModel, params: dict | None = None, *, global_search: bool = True, starts: int = 20,
        popsize: int = 15, maxiter: int = 200, seed: int = 0, de_tol: float = 1e-3, grid_check: bool = True,
        progress=None, quiet: bool = False, profile: bool = True) -> FitResult:
    """Fit a :class:`ForwardModel`; see the module docstring for the steps.

    Parameters
    ----------
    model : the compiled forward model (data, conditions and grid are in it).
    params : name -> :class:`Parameter` (start values, bounds, vary); default
        :func:`default_parameters` of the model's spec.
    global_search : run differential evolution first (``False``: local starts only).
    profile : compute profile-likelihood intervals for parameters at or across a bound
        (``False`` where only the estimate and its prediction are used: validation folds).
    starts : number of local least-squares starts: the DE optimum (if any) and
        ``starts - 1`` scrambled-Sobol points (or the given values and Sobol points
        without global search). ``starts=1, global_search=False`` is one local fit
        from the given values.
    popsize, maxiter, seed, de_tol : differential-evolution settings.
    grid_check : re-evaluate the SSR on ``model.grid.refine(2)``.
    progress, quiet : a callable taking each stage's message; by default (None) the stages
        go to stderr once the fit has taken more than 2 s (:mod:`millflow.fitting.progress`);
        ``quiet=True`` silences them.
    """
    say = reporter(progress, quiet, "fit")
    t0 = time.perf_counter()
    params = params or default_parameters(model.spec)
    prob = check_problem(model, params)
    lo, hi = prob.lower, prob.upper
    p = prob.idx.size
    candidates = []
    if global_search:
        say(f"differential evolution over {p} parameters (population {popsize * p})")
        de = differential_evolution(prob.ssr_pop, list(zip(lo, hi)), popsize=popsize, maxiter=maxiter, tol=de_tol,
                                    seed=seed, polish=False, vectorized=True, updating="deferred",
                                    init="latinhypercube")
        say(f"  DE: SSR {de.fun:.6g} after {de.nit} generations")
        candidates.append(de.x)
    else:
        candidates.append(prob.full[prob.idx])
    n_sobol = max(starts - 1, 0)
    if n_sobol:
        with warnings.catch_warnings():  # balance needs 2^m points; any count is fine here
            warnings.simplefilter("ignore", UserWarning)
            sob = qmc.Sobol(p, scramble=True, seed=seed).random(n_sobol)
        candidates += list(qmc.scale(sob, lo, hi)) if np.all(hi > lo) else []
    sols = []
    for k, z0 in enumerate(candidates):
        z, s = _local(prob, z0)
        sols.append((s, z))
        if k % 5 == 4 or k == len(candidates) - 1:
            say(f"  local starts {k + 1}/{len(candidates)}: best SSR {min(x[0] for x in sols):.6g}")
    sols.sort(key=lambda t: t[0])
    infeasible = sum(not math.isfinite(x[0]) for x in sols)
    sols = [x for x in sols if math.isfinite(x[0])]
    if not sols:
        last = getattr(getattr(model, "_nonlinear", None), "failures", None)
        raise SolverError(f"no start of the fit could be solved ({len(candidates)} starts)"
                          + (f"; last failure: {last[-1]}" if last else ""))
    if infeasible:
        prob.notes.append(f"{infeasible} of {len(candidates)} starts could not be solved and were dropped")
    zb, sb = _local(prob, sols[0][1], tight=True)
    if sb > sols[0][0]:
        zb, sb = sols[0][1], sols[0][0]
    components = _variance_components(prob, zb)
    if components is not None:  # the tracer rows re-weighted by their own noise: re-fit from here
        zb, sb = components.pop("z"), components.pop("ssr")
        sols = [(float(prob.resid(z) @ prob.resid(z)), z) for _, z in sols]
        sols.sort(key=lambda t: t[0])
        say(f"  variance components: tracer rows weighted x{components['tracer_weight']:.3g} (SD tracer "
            f"{components['sd']['tracer']:.3g}, sieves {components['sd']['psd']:.3g})")
    spread = _spread(sols, zb, sb, lo, hi)
    theta = prob.expand(zb)[0]
    J = prob.jac(zb)
    st = parameter_statistics(prob.names, zb, J, sb, model.n_data, lo, hi, residuals=prob.resid(zb),
                              clusters=model.sample_ids())
    if components is not None:
        st["variance_components"] = components
    fitted = {n: Parameter(n, float(v), params[n].min, params[n].max, params[n].vary)
              for n, v in zip(model.param_names, theta)}
    gc = _grid_check(model, params, theta, zb, sb, st, prob.row_factor) if grid_check else {}
    ee = error_estimate(model, gc)
    _flag_parameters(st, gc, sols, prob.names, model.n_data)
    if profile:
        _profile_intervals(prob, zb, sb, st, model.n_data)
    names = prob.names
    solutions = [(float(s), {n: float(v) for n, v in zip(names, z)}) for s, z in sols]
    say(f"done: SSR {sb:.6g}, spread {spread:.3g}, {time.perf_counter() - t0:.1f} s")
    return FitResult(model, fitted, st, sb, model.n_data, p, len(candidates), spread, solutions, prob.nfev,
                     time.perf_counter() - t0, gc, error_estimate=ee, notes=list(prob.notes))


def error_estimate(model: ForwardModel, gc: dict) -> dict:
    """The fit's error split by source: solver and size grid.

    The fit's error split by source: ``solver`` (relative error of the predicted values from
    the forward solves) and ``grid`` (how far the parameters are from those of the continuous
    model, in SE: from the re-fit on the grid refined 2x in ln x, Richardson's estimate at the
    scheme's order p, times the safety factor of :func:`millflow.grid.richardson`):

        grid = F_s 2^p / (2^p - 1) max_k |theta_k,fine - theta_k| / SE_k.
    """
    from millflow.grid import SAFETY_FACTOR

    if not (hasattr(model, "solver_accuracy") and hasattr(model, "grid_order")):
        return {}  # a model of its own (e.g. a survey's circuit) states its errors itself
    acc, how = model.solver_accuracy()
    out = {"solver": {"value": acc, "unit": "relative (predicted values)", "method": how}}
    order, why = model.grid_order()
    if order is None:
        out["grid"] = {"value": 0.0, "unit": "SE", "method": why}
    elif not gc or "skipped" in gc:
        out["grid"] = {"value": None, "unit": "SE",
                       "method": "not estimated (" + (gc.get("skipped") if gc else "grid check off") + ")"}
    else:
        shift = gc["max_param_shift_in_se"]
        factor = SAFETY_FACTOR * 2.0 ** order / (2.0 ** order - 1.0)
        out["grid"] = {"value": factor * shift if math.isfinite(shift) else None, "unit": "SE",
                       "shift_in_se": shift, "order": order,
                       "method": (f"re-fit on the grid refined 2x in ln x ({gc['n_refined']} classes): largest "
                                  f"parameter shift {shift:.3g} SE; Richardson at order {order} ({why}) with "
                                  f"safety factor {SAFETY_FACTOR:g}: {factor:.3g} x the shift")}
    return out


#: Variance components: at most this many re-weighted fits, stopped when the tracer weight
#: changes by less than VC_RTOL.
VC_ITERATIONS = 4
VC_RTOL = 0.02


def _variance_components(prob: _Problem, z) -> dict | None:
    """Tracer rows and sieve rows weighted by their own noise (iteratively re-weighted LS).

    Tracer F(t) and cumulative passing come from different instruments with different
    noise. One pooled SER in eq. 9 gives the tracer-determined parameters (tau, Pe) the
    sieves' smaller noise: in a joint fit with tracer SD 0.01 and sieve SD 0.005 their
    95 % intervals covered 80 %, the SD of their z-scores 1.5. Each group's variance is
    estimated from its residuals with its share of the fitted degrees of freedom,
    sigma_g^2 = SSR_g / (n_g - sum_(i in g) h_ii) (h the hat matrix of the weighted
    Jacobian: REML-like), the tracer rows are re-weighted by sigma_psd^2 / sigma_tracer^2
    and the fit polished again, until the weight changes by less than 2 %. Only when the
    model has both tracer and sieve rows and the user gave no ``kind_weights`` for the
    tracer. Returns None, or the components with the re-fitted ``z`` and ``ssr``.
    """
    model = prob.model
    kinds = np.asarray(getattr(model, "data_kind", []), dtype=object)
    tracer = kinds == "tracer"
    if kinds.size != model.n_data or not tracer.any() or tracer.all() or "tracer" in model.kind_weights:
        return None
    weight, history = 1.0, []
    for _ in range(VC_ITERATIONS):
        r = prob.resid(z)
        J = prob.jac(z)
        h = np.einsum("ij,ji->i", J, np.linalg.pinv(J.T @ J) @ J.T)  # leverages
        sd = {}
        for name, rows in (("tracer", tracer), ("psd", ~tracer)):
            dof = rows.sum() - h[rows].sum()
            sd[name] = math.sqrt(float(r[rows] @ r[rows]) / dof) / math.sqrt(weight if name == "tracer" else 1.0) \
                if dof > 0 else math.nan
        if not (np.isfinite(sd["tracer"]) and np.isfinite(sd["psd"]) and sd["tracer"] > 0 and sd["psd"] > 0):
            return None
        new = (sd["psd"] / sd["tracer"]) ** 2
        history.append(new)
        change = abs(new / weight - 1.0)
        prob.row_factor = np.where(tracer, math.sqrt(new), 1.0)
        prob.sw = prob.base_sw * prob.row_factor
        weight = new
        z, ssr = _local(prob, z, tight=True)
        if change < VC_RTOL:
            break
    r = prob.resid(z)
    return {"z": z, "ssr": float(r @ r), "tracer_weight": weight, "sd": sd, "weights_history": history,
            "method": "tracer and sieve rows weighted by their own residual variance (REML-like dof), "
                      "re-fitted until the weight changes < 2 %"}


def _grid_check(model, params, theta, zb, sb, st, row_factor=1.0) -> dict:
    """Principle IV: the SSR and the estimate on the grid refined twice.

    Principle IV: SSR on ``grid.refine(2)`` at the estimate, and after a local re-fit
    there, with the largest parameter change in units of its SEP.
    """
    try:
        fine = model.with_grid(model.grid.refine(2))
    except InputError as exc:
        return {"skipped": str(exc)}
    prob = _Problem(fine, params)
    prob.row_factor = row_factor  # the same weights as the fit (variance components)
    prob.sw = prob.base_sw * row_factor
    r = prob.resid(zb)
    s_same = float(r @ r)
    z2, s2 = _local(prob, zb)
    se = np.array([st["params"][n]["se"] for n in prob.names])
    with np.errstate(divide="ignore", invalid="ignore"):
        shifts = np.abs(z2 - zb) / se
    shift = float(np.nanmax(shifts)) if np.all(se > 0) else math.nan
    return {"n": model.n, "n_refined": fine.n, "ssr": sb, "ssr_refined": s_same,
            "relative_change": abs(s_same - sb) / max(sb, 1e-300), "ssr_refit": s2,
            "relative_change_refit": abs(s2 - sb) / max(sb, 1e-300), "max_param_shift_in_se": shift,
            "param_shift_in_se": {n: float(v) for n, v in zip(prob.names, shifts)}}


def _profile_intervals(prob: _Problem, zb, sb: float, st: dict, n_data: int) -> None:
    """95 % profile-likelihood intervals for parameters at or across a bound.

    95 % profile-likelihood intervals for the parameters whose symmetric interval
    crosses a bound or that sit at one: {v : min over the others of SSR(v) <= SSR_best
    (1 + D^2 F_{1,nu,0.95} / (n - p))}, D the parameter's SE inflation for correlated
    residuals (1 under eq. 9) and nu the degrees of freedom of the symmetric intervals
    (n - p, or G - 1 where the cluster-robust SE was used: where the SSR is quadratic the
    profile interval is then the symmetric one), found by bisection to 1e-3 of the range
    and clipped to the bounds; asymmetric where the likelihood is. Stored as ``ci95``
    (the symmetric one stays as ``ci95_wald``) with a flag saying so.
    """
    from scipy import stats as _stats

    p = len(prob.names)
    dof = n_data - p
    if dof <= 0 or p < 1:
        return
    dof_i = st.get("dof_intervals", dof)
    for k, name in enumerate(prob.names):
        s = st["params"][name]
        lo_b, hi_b = float(prob.lower[k]), float(prob.upper[k])
        lo_w, hi_w = s["ci95"]
        if not (s.get("at_bound") or lo_w < lo_b or hi_w > hi_b) or not math.isfinite(s["se"]):
            continue
        infl = s["se"] / s["se_eq9"] if s.get("se_eq9") else 1.0
        limit = sb * (1 + infl ** 2 * float(_stats.f.ppf(0.95, 1, dof_i)) / dof)
        sub_prob = _Problem.__new__(_Problem)
        sub_prob.__dict__.update(prob.__dict__)
        keep = np.array([j for j in range(p) if j != k], dtype=int)
        sub_prob.idx, sub_prob.names = prob.idx[keep], [prob.names[j] for j in keep]
        sub_prob.lower, sub_prob.upper = prob.lower[keep], prob.upper[keep]
        sub_prob.full = prob.expand(zb)[0].copy()
        others = np.asarray(zb, float)[keep]

        start = {"z": others}

        def profile(v, sub_prob=sub_prob, k=k, keep=keep, start=start, limit=limit, others=others):
            sub_prob.full[prob.idx[k]] = v
            if keep.size == 0:
                r = sub_prob.resid(np.zeros(0))
                return float(r @ r)
            z, ssr = _local(sub_prob, start["z"])
            if ssr > limit and start["z"] is not others:
                # a continuation start from far along the profile can strand the local fit
                # (ill-conditioned models): the estimate's own values are the other start
                z2, ssr2 = _local(sub_prob, others)
                if ssr2 < ssr:
                    z, ssr = z2, ssr2
            if np.all(np.isfinite(z)) and ssr <= limit:
                start["z"] = z  # continuation: the next point starts from this optimum
            return ssr

        ends = []
        for bound in (lo_b, hi_b):
            start["z"] = others
            f_bound = profile(bound) - limit
            if f_bound <= 0:
                ends.append(bound)  # the data cannot exclude the bound: the interval reaches it
                continue
            # the crossing of SSR(v) = limit between the estimate (SSR = sb, below) and the
            # bound (above): regula falsi with the Illinois modification on the known end
            # values (superlinear, each step one profile fit), to 1e-3 of the range
            x0, f0, x1, f1 = float(zb[k]), sb - limit, float(bound), f_bound
            tol = 1e-3 * (hi_b - lo_b)
            for _ in range(60):
                x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
                f2 = profile(x2) - limit
                if f2 * f1 < 0:
                    x0, f0 = x1, f1
                else:
                    f0 *= 0.5
                x1, f1 = x2, f2
                if abs(x1 - x0) <= tol or f2 == 0:
                    break
            ends.append(x1)
        s["ci95_wald"] = [lo_w, hi_w]
        s["ci95"] = [min(ends), max(ends)]
        s["flags"].append(f"95 % interval from the profile likelihood [{min(ends):.4g}, {max(ends):.4g}] "
                          "(the symmetric one crosses a bound)")


#: A parameter that moves more than this many SE when the grid is refined is "grid-dependent".
GRID_SHIFT_FLAG_SE = 1.0


def _flag_parameters(st: dict, gc: dict, sols, names, n_data: int) -> None:
    """Make the grid check and the multi-start search act on each parameter's flags.

    - grid-dependent: the re-fit on the refined grid moves it by more than
      GRID_SHIFT_FLAG_SE standard errors (the discretisation error is not negligible);
    - not unique over starts: starts whose SSR lies inside the joint 95 % confidence
      region of the best, SSR <= SSR_best (1 + p/(n - p) F_{p, n-p, 0.95}) (they fit
      equally well within the noise), span more than 2 SE of the parameter. Its range
      over those starts is reported as ``start_range``.
    """
    from scipy import stats as _stats

    for n, shift in gc.get("param_shift_in_se", {}).items():
        if math.isfinite(shift) and shift > GRID_SHIFT_FLAG_SE:
            st["params"][n]["flags"].append(f"grid-dependent (moves {shift:.2g} SE when the grid is refined)")
            st["params"][n]["grid_dependent"] = True
    p = len(names)
    if not sols or n_data <= p:
        return
    best = sols[0][0]
    limit = best * (1 + p / (n_data - p) * float(_stats.f.ppf(0.95, p, n_data - p)))
    within = np.array([z for s, z in sols if s <= limit])
    for k, n in enumerate(names):
        lo, hi = float(within[:, k].min()), float(within[:, k].max())
        s = st["params"][n]
        s["start_range"] = [lo, hi]
        s["starts_within_noise"] = int(len(within))
        if math.isfinite(s["se"]) and hi - lo > 2 * s["se"]:
            s["flags"].append(f"not unique over starts (equally good fits range {lo:.4g} to {hi:.4g})")


def _spread(sols, zb, sb, lo, hi) -> float:
    """Largest relative parameter difference between the best and equally good starts."""
    scale = np.maximum(np.abs(zb), 1e-3 * (hi - lo))
    worst = 0.0
    for s, z in sols:
        if s <= sb * (1 + SAME_SSR_RTOL) + 1e-300:
            worst = max(worst, float(np.max(np.abs(z - zb) / scale)))
    return worst


def compare_models(models: dict, params: dict | None = None, **fit_kwargs) -> dict:
    """Fit several candidate models to the same data and rank them.

    Parameters
    ----------
    models : label -> :class:`ForwardModel` (same data and conditions).
    params : label -> parameter dict (optional, defaults per model).

    Returns
    -------
    dict with ``fits`` (label -> FitResult), ``table`` (rows sorted by AIC with ssr,
    n_params, aic, bic, delta_aic) and ``f_tests`` (for every pair whose parameter
    names are nested: the F statistic and p value of the bigger model).
    """
    from millflow.fitting.statistics import f_test

    ys = {label: m.y.tobytes() for label, m in models.items()}
    if len(set(ys.values())) > 1:
        raise InputError("compare_models: the candidate models must be fitted to the same data values")
    fit_kwargs.setdefault("quiet", True)  # one fit per candidate: their stages are not news
    fits = {label: fit(m, (params or {}).get(label), **fit_kwargs) for label, m in models.items()}
    rows = []
    for label, r in fits.items():
        c = r.criteria
        rows.append({"model": label, "ssr": r.ssr, "n_params": r.n_params, "aic": c["aic"], "bic": c["bic"]})
    rows.sort(key=lambda d: d["aic"])
    for d in rows:
        d["delta_aic"] = d["aic"] - rows[0]["aic"]
    tests = []
    for a, b in itertools.permutations(fits, 2):
        na, nb = set(fits[a].stats["params"]), set(fits[b].stats["params"])
        if na < nb:
            n = fits[a].n_data
            res = f_test(fits[a].ssr, fits[a].n_params, fits[b].ssr, fits[b].n_params, n)
            tests.append({"small": a, "big": b, **res})
    return {"fits": fits, "table": rows, "f_tests": tests}
