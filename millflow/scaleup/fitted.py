"""A fitted breakage model read back from a ``millflow fit --json`` result.

:class:`FittedBreakage` holds the estimate, its eq. 9 covariance and the model
description written by the fit, and evaluates S (eqs. 5, 7, 10) and b (eq. 6) for any
parameter vector at given process conditions, on the fit's grid or on another grid
(exact: the functional forms are evaluated at the new sizes, not interpolated).

Only what is a property of the material and the breakage mechanism can be carried to
another mill: fits with classification inside the lab mill (``screen``) or with A in
units of 1/tau (continuous fits without a tau column) are refused with the reason.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from millflow.breakage.distributions import breakage_population
from millflow.breakage.rates import austin_rates_population, ln_process_power_law, power_law_rates_population
from millflow.errors import InputError
from millflow.inputs import read_text

__all__ = ["FittedBreakage", "load_fit", "fit_from_dict"]

_RATES = ("power", "austin")
_BREAKAGES = ("normalized", "single")


@dataclass(frozen=True)
class FittedBreakage:
    """Estimate, covariance and model description of a breakage fit.

    Attributes
    ----------
    names : all parameter names (spec order); ``varying`` the ones with covariance.
    theta : (P,) estimate in ``names`` order.
    cov : (V, V) eq. 9 covariance of the varying parameters (``varying`` order).
    spec : the ``model_spec`` dict of the fit JSON.
    source : file name for messages.
    """

    names: tuple
    theta: np.ndarray
    varying: tuple
    cov: np.ndarray
    spec: dict
    source: str = "fit"

    def __post_init__(self):
        s, src = self.spec, self.source
        if s.get("rate") not in _RATES:
            raise InputError(f"{src}: model_spec.rate = {s.get('rate')!r}: scale-up supports {list(_RATES)}")
        if s.get("breakage") not in _BREAKAGES:
            raise InputError(f"{src}: model_spec.breakage = {s.get('breakage')!r}: scale-up supports "
                             f"{list(_BREAKAGES)} (a fixed b matrix is not stored in the fit JSON)")
        if s.get("classification") is not None:
            raise InputError(f"{src}: model_spec.classification = {s['classification']!r}: classification inside "
                             "the lab mill is not a material property; refit without it or give the plant's "
                             "classification in the plant file")
        if s.get("mode") != "batch" and not s.get("tau_column"):
            raise InputError(f"{src}: model_spec.mode = {s.get('mode')!r} without tau_column: A is then "
                             "A*tau (dimensionless) and cannot be carried to another mill")
        if s.get("param_process"):
            raise InputError(f"{src}: model_spec.param_process = {s['param_process']!r}: scale-up supports "
                             "process dependence of A only (eq. 10 on A)")
        C = np.asarray(self.cov, float)
        if C.shape != (len(self.varying),) * 2 or not np.all(np.isfinite(C)):
            raise InputError(f"{src}: covariance has shape {C.shape} or non-finite entries; expected a finite "
                             f"({len(self.varying)}, {len(self.varying)}) matrix")
        object.__setattr__(self, "cov", C)
        object.__setattr__(self, "theta", np.asarray(self.theta, float))

    # ------------------------------------------------------------------ accessors
    @property
    def x(self) -> np.ndarray:
        """Upper class sizes of the fit's grid [m]."""
        return np.asarray(self.spec["grid_upper_m"], float)

    @property
    def index(self) -> np.ndarray:
        """Positions of the varying parameters in ``names``."""
        return np.array([self.names.index(n) for n in self.varying], int)

    @property
    def se(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def full(self, varying_values) -> np.ndarray:
        """Full parameter vector(s) (..., P) with the varying ones replaced."""
        v = np.asarray(varying_values, float)
        out = np.broadcast_to(self.theta, v.shape[:-1] + self.theta.shape).copy()
        out[..., self.index] = v
        return out

    def physical(self, theta) -> np.ndarray:
        """Mask of parameter vectors (..., P) inside the physical domain of eqs. 6/7."""
        t = np.atleast_2d(theta)
        p = {n: t[:, k] for k, n in enumerate(self.names)}
        ok = p["gamma"] > 0
        if self.spec["breakage"] == "normalized":
            ok &= (p["phi"] >= 0) & (p["phi"] <= 1) & (p["beta"] > 0)
        if self.spec["rate"] == "austin":
            ok &= p["Lambda"] > 0
        return ok

    # ---------------------------------------------------------------- evaluation
    def check_process(self, process: dict, where: str) -> dict:
        cols = self.spec.get("rate_process", [])
        missing = [c for c in cols if c not in process]
        if missing:
            raise InputError(f"{where}: missing process values {missing} (the fit's eq. 10 uses {cols})")
        out = {}
        for c in cols:
            v = float(process[c])
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"{where}.{c} = {v!r}: expected a finite number > 0")
            out[c] = v
        return out

    def rates(self, theta, x, process: dict, A_factor: float = 1.0, mu_factor: float = 1.0) -> np.ndarray:
        """S [1/s] at sizes x [m] (last class the sink, S = 0) for parameter vector(s)
        theta (..., P): eq. 5 or eq. 7 (Lambda, mu) with A by eq. 10 at ``process``, A
        and mu multiplied by the given scale-up factors."""
        t = np.atleast_2d(np.asarray(theta, float))
        p = {n: t[:, k] for k, n in enumerate(self.names)}
        cols = self.spec.get("rate_process", [])  # eq. 10 at the plant's process values
        lnA = ln_process_power_law(p["ln_A0"] + math.log(A_factor), {c: float(process[c]) for c in cols},
                                   {c: p[f"a_{c}"] for c in cols},
                                   {c: float(self.spec["process_ref"][c]) for c in cols})
        x0 = float(self.spec["x0_m"])
        A = np.exp(np.minimum(lnA, 600.0))
        if self.spec["rate"] == "austin":  # eq. 7 (mu scaled by the scale-up factor)
            mu0 = np.exp(p["ln_mu"]) * x0 * mu_factor
            S = austin_rates_population(x, A, p["alpha"], mu0, p["Lambda"], x0=x0)
        else:  # eq. 5
            S = power_law_rates_population(x, A, p["alpha"], x0)
        return S if np.ndim(theta) > 1 else S[0]

    def frac_b(self, theta, x) -> np.ndarray:
        """Fractional b (..., N, N) of eq. 6 at sizes x [m] (normalised: B_ij depends on
        x_{i-1}/x_j only, carried unchanged between mills), from
        :func:`millflow.breakage.distributions.breakage_population`."""
        t = np.atleast_2d(np.asarray(theta, float))
        p = {n: t[:, k] for k, n in enumerate(self.names)}
        x = np.asarray(x, float)
        if self.spec["breakage"] == "single":
            b = breakage_population(x, 1.0, p["gamma"], p["gamma"], kind="b")
        else:
            b = breakage_population(x, p["phi"], p["gamma"], p["beta"], kind="b")
        return b if np.ndim(theta) > 1 else b[0]

    def cumulative(self, theta, x, y) -> np.ndarray:
        """Continuous B(x; y) [-] of eq. 6 at sizes x, y [m] (broadcasting) for one parameter
        vector theta (:func:`millflow.breakage.distributions.continuous_B`)."""
        from millflow.breakage.distributions import continuous_B

        p = dict(zip(self.names, np.asarray(theta, float)))
        if self.spec["breakage"] == "single":
            return continuous_B(x, y, 1.0, p["gamma"], p["gamma"])
        return continuous_B(x, y, p["phi"], p["gamma"], p["beta"])


def load_fit(path) -> FittedBreakage:
    """Read a ``millflow fit --json`` result; one-line InputError naming what is missing."""
    src = str(path)
    try:
        d = json.loads(read_text(path, "fit result (JSON)"))
    except json.JSONDecodeError as exc:
        raise InputError(f"{src}: not JSON ({exc.msg} at line {exc.lineno})") from None
    return fit_from_dict(d, src)


def fit_from_dict(d: dict, src: str = "fit") -> FittedBreakage:
    """:func:`load_fit` for an already parsed fit result (``FitResult.to_dict()``)."""
    if not isinstance(d, dict) or "params" not in d:
        raise InputError(f"{src}: not a 'millflow fit --json' result (no 'params')")
    if not isinstance(d.get("covariance"), (dict, type(None))):
        raise InputError(f"{src}: covariance: expected a table with 'names' (the varying parameters) and "
                         "'matrix' (a list of rows), as 'millflow fit --json' writes it")
    if "covariance" not in d or not d["covariance"] or d["covariance"].get("matrix") is None:
        raise InputError(f"{src}: fit result has no 'covariance' (eq. 9); rerun 'millflow fit --json' with this "
                         "version of millflow")
    if "model_spec" not in d:
        raise InputError(f"{src}: fit result has no 'model_spec'; rerun 'millflow fit --json' with this version")
    spec = d["model_spec"]
    if not isinstance(spec, dict) or not _strings(spec.get("param_names")):
        raise InputError(f"{src}: model_spec.param_names: expected a list of parameter names")
    names = tuple(spec["param_names"])
    params, fixed = d["params"], d.get("fixed", {})
    if not isinstance(params, dict) or not isinstance(fixed, dict):
        raise InputError(f"{src}: params and fixed: expected tables of parameter -> value")
    values = {}
    for k, v in params.items():
        values[k] = _finite(v.get("value") if isinstance(v, dict) else None, f"{src}: params.{k}.value")
    for k, v in fixed.items():
        values[k] = _finite(v, f"{src}: fixed.{k}")
    missing = [n for n in names if n not in values]
    if missing:
        raise InputError(f"{src}: parameters {missing} have no value")
    cov = d["covariance"]
    if not isinstance(cov, dict) or not _strings(cov.get("names")) or not isinstance(cov.get("matrix"), list):
        raise InputError(f"{src}: covariance: expected a table with 'names' (the varying parameters) and "
                         "'matrix' (a list of rows), as 'millflow fit --json' writes it")
    unknown = [n for n in cov["names"] if n not in names]
    if unknown or len(set(cov["names"])) != len(cov["names"]):
        raise InputError(f"{src}: covariance.names {cov['names']}: expected distinct names among the model's "
                         f"parameters {list(names)}")
    try:
        C = np.array([[math.nan if v is None else v for v in row] for row in cov["matrix"]], float)
    except (TypeError, ValueError):
        raise InputError(f"{src}: covariance.matrix: expected a square list of lists of numbers") from None
    fitted = FittedBreakage(names, np.array([values[n] for n in names], float), tuple(cov["names"]), C, spec, src)
    try:
        inside = bool(fitted.physical(fitted.theta)[0])
    except KeyError as exc:
        raise InputError(f"{src}: parameter {exc.args[0]!r} missing for model_spec rate = {spec.get('rate')!r}, "
                         f"breakage = {spec.get('breakage')!r}") from None
    if not inside:
        shown = ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, fitted.theta) if n in ("phi", "gamma", "beta",
                                                                                       "Lambda"))
        raise InputError(f"{src}: the fitted breakage parameters ({shown}) are outside eqs. 6/7's domain "
                         "(0 <= phi <= 1, gamma, beta, Lambda > 0); such a fit cannot be scaled up")
    return fitted


def _strings(v) -> bool:
    return isinstance(v, list) and all(isinstance(e, str) for e in v)


def _finite(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise InputError(f"{where} = {v!r}: expected a finite number")
    return float(v)
