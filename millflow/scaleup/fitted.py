"""A fitted breakage model read back from a ``millflow fit --json`` result.

:class:`FittedBreakage` holds the estimate, its eq. 9 covariance and the model
description written by the fit, and evaluates S (eqs. 5, 7, 10) and b (eq. 6) for any
parameter vector at given process conditions, on the fit's grid or on another grid
(exact: the continuous forms are put on the new grid, not interpolated). The parameter
vector is decoded by the fit's own translator (:class:`millflow.fitting.translate.Translator`),
the one home of eq. 10 and of the forms' parameterisation; :meth:`FittedBreakage.rate_model`
and :meth:`FittedBreakage.distribution_model` hand the forms to a flowsheet mill.

Only what is a property of the material and the breakage mechanism can be carried to
another mill: fits with classification inside the lab mill (``screen``) or with A in
units of 1/tau (continuous fits without a tau column) are refused with the reason.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError
from millflow.inputs import read_text

__all__ = ["FittedBreakage", "FittedRate", "FittedDistribution", "load_fit", "fit_from_dict"]

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
        from millflow.scaleup.uncertainty import check_covariance

        check_covariance(C, list(self.varying), f"{src}: covariance")
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
        """Standard errors of the parameters."""
        return np.sqrt(np.diag(self.cov))

    def full(self, varying_values) -> np.ndarray:
        """Full parameter vector(s) (..., P) with the varying ones replaced."""
        v = np.asarray(varying_values, float)
        out = np.broadcast_to(self.theta, v.shape[:-1] + self.theta.shape).copy()
        out[..., self.index] = v
        return out

    @property
    def translator(self):
        """The fit's decoder of parameter vectors (:class:`millflow.fitting.translate.Translator`)."""
        t = self.__dict__.get("_translator")
        if t is None:
            from millflow.fitting.translate import Translator

            t = Translator.from_description(self.spec)
            object.__setattr__(self, "_translator", t)
        return t

    def physical(self, theta) -> np.ndarray:
        """Mask of parameter vectors (..., P) inside the physical domain of eqs. 6/7."""
        return self.translator.physical(theta)

    # ---------------------------------------------------------------- evaluation
    def check_process(self, process: dict, where: str) -> dict:
        """The process values of eq. 10, checked against the fit's columns and range."""
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

    def _process(self, process: dict) -> dict:
        return {c: float(process[c]) for c in self.spec.get("rate_process", [])}

    def rates(self, theta, x, process: dict, A_factor: float = 1.0, mu_factor: float = 1.0) -> np.ndarray:
        """Rates S [1/s] at sizes x [m] for parameter vector(s) theta.

        S [1/s] at sizes x [m] (last class the sink, S = 0) for parameter vector(s)
        theta (..., P): eq. 5 or eq. 7 (Lambda, mu) with A by eq. 10 at ``process``, A
        and mu multiplied by the given scale-up factors.
        """
        tr = self.translator
        p = tr.unpack(theta)
        S = tr.rate_at(p, self._process(process), 1, np.asarray(x, float), A_factor, mu_factor)[:, 0]
        S[..., -1] = 0.0  # the sink does not break
        return S if np.ndim(theta) > 1 else S[0]

    def frac_b(self, theta, x) -> np.ndarray:
        """Fractional b of eq. 6 at the upper edges.

        Fractional b (..., N, N) of eq. 6 at the upper edges x [m] (Austin's discrete form;
        :meth:`on_grid` gives the class averages).
        """
        tr = self.translator
        b = tr.edge_b(tr.unpack(theta), {}, 1, np.asarray(x, float))[:, 0]
        return b if np.ndim(theta) > 1 else b[0]

    def on_grid(self, theta, grid, process: dict, A_factor: float = 1.0, mu_factor: float = 1.0):
        """S [1/s] and b on ``grid`` for parameter vector(s) theta.

        (S (..., N) [1/s], b (..., N, N)) on ``grid`` (class averages on the default scheme)
        for parameter vector(s) theta, at ``process`` with the scale-up factors.
        """
        tr = self.translator
        p = tr.unpack(theta)
        S, b = tr.breakage_on_grid(p, self._process(process), 1, grid, A_factor, mu_factor)
        S, b = S[:, 0], b[:, 0]
        return (S, b) if np.ndim(theta) > 1 else (S[0], b[0])

    def cumulative(self, theta, x, y, top=None) -> np.ndarray:
        """Continuous B(x; y) [-] of eq. 6 for one parameter vector.

        Continuous B(x; y) [-] of eq. 6 at sizes x, y [m] (broadcasting) for one parameter
        vector theta (:func:`millflow.breakage.distributions.continuous_B`).
        """
        return self.translator.cumulative(theta, x, y, top)

    def rate_model(self, theta=None, process: dict | None = None, A_factor: float = 1.0,
                   mu_factor: float = 1.0) -> "FittedRate":
        """The fitted rate at ``process`` as a rate model of size (for a flowsheet mill)."""
        theta = self.theta if theta is None else np.asarray(theta, float)
        return FittedRate(self, theta, self._process(process or {}), float(A_factor), float(mu_factor))

    def distribution_model(self, theta=None) -> "FittedDistribution":
        """The fitted breakage distribution as a distribution model (for a flowsheet mill)."""
        return FittedDistribution(self, self.theta if theta is None else np.asarray(theta, float))


@dataclass(frozen=True, eq=False)
class FittedRate:
    """The rate S(x) [1/s] of a fitted breakage model at given process values.

    S(x) [1/s] of a fitted breakage model at given process values, times scale-up factors
    on A and mu: a continuous rate model (callable of the sizes [m]).
    """

    fitted: FittedBreakage
    theta: np.ndarray
    process: dict
    A_factor: float = 1.0
    mu_factor: float = 1.0

    def __call__(self, x):
        """Rates S [1/s] at sizes x [m]."""
        return self.fitted.rates(self.theta, np.asarray(x, float), self.process, self.A_factor, self.mu_factor)

    def __repr__(self):
        return (f"FittedRate({self.fitted.source}, {self.fitted.spec['rate']} form, process {self.process}, "
                f"A x {self.A_factor:.4g}, mu x {self.mu_factor:.4g})")


@dataclass(frozen=True, eq=False)
class FittedDistribution:
    """B(x; y) of a fitted breakage model (eq. 6): ``cumulative`` for class averages, ``b`` for Austin's upper edges."""

    fitted: FittedBreakage
    theta: np.ndarray

    def b(self, x):
        """Fractional b at the upper edges x [m]."""
        return self.fitted.frac_b(self.theta, np.asarray(x, float))

    __call__ = b

    def cumulative(self, x, y, top=None):
        """Continuous B(x; y) [-] at sizes x, y [m]."""
        return self.fitted.cumulative(self.theta, x, y, top)

    def __repr__(self):
        return f"FittedDistribution({self.fitted.source}, {self.fitted.spec['breakage']})"


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
