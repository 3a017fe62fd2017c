"""Least-squares fitting of RTD models to tracer curves, with parameter statistics.

The data are modelled as c(t) = A g(t; p), g the model's E(t) (pulse), F(t) (step) or
its convolution with a measured inlet curve, and A a free scale (tracer area or
plateau), so that no prior normalisation error enters the estimates. Parameters start
from the moments of the curve (each model's ``from_moments``), are bounded, and are
found by ``scipy.optimize.least_squares`` (positive parameters in logs). Statistics
follow eq. 9: residuals r = model - data, SSR = sum r^2, SER^2 = SSR/(n - p),
C = SER^2 (J^T J)^-1 with J the Jacobian in the natural parameters (central
differences at the estimate), standard errors sqrt(diag C), 95 % intervals with
Student's t, AIC = n ln(SSR/n) + 2p, BIC = n ln(SSR/n) + p ln n (p counts A).
"""
from __future__ import annotations

import dataclasses
import inspect
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from rtd.compartments import RecirculatingCells
from rtd.models import PlugFlow, RTDError
from rtd.names import ALIASES, TRANSPORTS, canonical_name
from rtd.tracer import TracerCurve, TracerError, check_tracer, convolve_inlet, moments, step_moments

#: Model names for :func:`fit`: every canonical name and alias of :mod:`rtd.names`
#: -> (class, fixed keywords).
MODELS = {name: (entry.cls, dict(entry.fixed))
          for name, entry in [*TRANSPORTS.items(), *((a, TRANSPORTS[c]) for a, c in ALIASES.items())]}

# (lower, upper, fitted in logs) per parameter name; tau bounds scale with the mean
BOUNDS = {
    "tau": (1e-6, 1e3, True),
    "n": (1.0, 1e5, False),
    "pe": (1e-3, 1e6, True),
    "r": (0.0, 1e4, False),
    "dead": (0.0, 0.99, False),
    "bypass": (0.0, 0.99, False),
}


@dataclass(frozen=True, eq=False)
class FitResult:
    """Estimates and statistics of one fit (eq. 9); ``to_dict`` gives the JSON form."""

    model: object
    names: tuple
    values: np.ndarray
    se: np.ndarray
    correlation: np.ndarray
    scale: float
    scale_se: float
    ssr: float
    ser: float
    r2: float
    aic: float
    bic: float
    n_data: int
    n_params: int
    t: np.ndarray
    data: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    kind: str = "pulse"
    success: bool = True
    message: str = ""
    nfev: int = 0
    notes: tuple = field(default_factory=tuple)
    time_unit: str = ""

    #: Seconds per time unit of the data (a TracerCurve's ``time_unit``).
    SECONDS: ClassVar[dict] = {"s": 1.0, "min": 60.0, "h": 3600.0}

    def model_in_seconds(self):
        """The fitted model with its times in seconds (millflow's unit).

        The fitted model with its times in seconds (millflow's unit): tau scaled from the
        data's ``time_unit``; refused when the data's times carried no unit.
        """
        f = self.SECONDS.get(self.time_unit)
        if f is None:
            raise RTDError(f"the fitted times carry no unit (time_unit = {self.time_unit!r}); fit a TracerCurve "
                           "read from a CSV with time_s, time_min or time_h, or scale tau yourself")
        return self.model.replace(tau=self.model.tau * f)
    inlet: np.ndarray | None = None

    def curve(self, t) -> np.ndarray:
        """Fitted curve A g(t) at any times (needs the data times when an inlet was used)."""
        return self.scale * _curve(self.model, np.asarray(t, float), self.kind, self.inlet)

    @property
    def params(self) -> dict:
        """All model parameters {name: (value, se)}; se is None for fixed ones."""
        out = {k: (v, None) for k, v in self.model.params.items()}
        for k, v, s in zip(self.names, self.values, self.se):
            out[k] = (float(v), float(s))
        return out

    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Confidence interval value -/+ t_{(1+level)/2, n-p} se."""
        i = self.names.index(name)
        from scipy import stats  # on first use: scipy.stats costs a command's start-up

        half = stats.t.ppf(0.5 + level / 2, self.n_data - self.n_params) * self.se[i]
        return float(self.values[i] - half), float(self.values[i] + half)

    @property
    def lack_of_fit(self) -> dict:
        """Residual diagnostics and whether the model fails to describe the curve.

        Wald-Wolfowitz runs test on the residual signs (few runs: residuals in long
        same-sign stretches, a shape the model misses) and the lag-1 autocorrelation.
        ``flag`` is True when R^2 < 0.9 or the runs test rejects randomness at p < 1e-3
        (with residuals above rounding, SER > 1e-9 of the peak):
        the standard errors then describe the wrong model and understate the error.
        """
        r = np.asarray(self.residuals, float)
        signs = r[r != 0] > 0
        n1, n2 = int(signs.sum()), int((~signs).sum())
        runs = 1 + int(np.count_nonzero(signs[1:] != signs[:-1])) if signs.size else 0
        n = n1 + n2
        if n1 and n2 and n > 2:
            mu = 1 + 2.0 * n1 * n2 / n
            var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1))
            z = (runs - mu) / math.sqrt(var) if var > 0 else 0.0
            p = math.erfc(abs(z) / math.sqrt(2))
        else:
            mu, z, p = float("nan"), float("nan"), float("nan")
        rc = r - r.mean()
        den = float(rc @ rc)
        lag1 = float(rc[1:] @ rc[:-1]) / den if den > 0 else float("nan")
        reasons = []
        if math.isfinite(self.r2) and self.r2 < 0.9:
            reasons.append(f"R^2 {self.r2:.3g} < 0.9")
        # the runs test means something only above rounding: exact data leave residuals
        # of a few ulp whose signs follow the arithmetic, not the model
        above_rounding = self.ser > 1e-9 * float(np.max(np.abs(self.data)))
        if math.isfinite(p) and p < 1e-3 and runs < mu and above_rounding:
            reasons.append(f"runs test: {runs} runs of residual signs where {mu:.1f} are expected (p {p:.1e})")
        return {"flag": bool(reasons), "reasons": reasons, "runs": runs, "expected_runs": mu, "runs_z": z,
                "runs_p": p, "lag1_autocorrelation": lag1}

    def to_dict(self) -> dict:
        """{"model", "params": {name: {"value", "se"}}, "ssr", "ser", "r2", "aic", "bic", ...}."""
        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)
        return {
            "model": repr(self.model),
            "params": {k: {"value": num(v), "se": num(s)} for k, (v, s) in self.params.items()},
            "scale": {"value": num(self.scale), "se": num(self.scale_se)},
            "ssr": num(self.ssr), "ser": num(self.ser), "r2": num(self.r2),
            "aic": num(self.aic), "bic": num(self.bic),
            "n_data": self.n_data, "n_params": self.n_params, "kind": self.kind, "time_unit": self.time_unit,
            "notes": list(self.notes),
            "lack_of_fit": {k: (num(v) if isinstance(v, float) else v) for k, v in self.lack_of_fit.items()},
        }

    def summary(self) -> str:
        """Readable table of estimates, standard errors and fit statistics."""
        lines = [f"{self.model!r}  ({self.kind} data, {self.n_data} points)"]
        for k, (v, s) in self.params.items():
            if s is None:
                tail = " (fixed)"
            else:
                tail = f" +/- {s:.3g} (se)" if math.isfinite(s) else " (se not available)"
            lines.append(f"  {k:<7s} = {v:.6g}{tail}")
        lines.append(f"  SSR {self.ssr:.4g}  SER {self.ser:.4g}  R^2 {self.r2:.6f}  "
                     f"AIC {self.aic:.2f}  BIC {self.bic:.2f}")
        lines += [f"  note: {n}" for n in self.notes]
        lof = self.lack_of_fit
        if lof["flag"]:
            lines.append(f"  warning: lack of fit ({'; '.join(lof['reasons'])}): the model does not describe "
                         "this curve and its standard errors are not to be trusted")
        return "\n".join(lines)


def resolve_model(model, **fixed):
    """A model class and fixed keyword arguments from a name, class or instance."""
    if isinstance(model, str):
        cls, kw = MODELS[canonical_name(model)]
        return cls, {**kw, **fixed}, None
    if isinstance(model, type):
        return model, dict(fixed), None
    if hasattr(model, "params") and hasattr(type(model), "from_moments"):
        return type(model), dict(fixed), model
    raise RTDError(f"model {model!r}: expected a name ({', '.join(TRANSPORTS)} or an alias), "
                   "an rtd model class or instance")


def _start(cls, kw, instance, mom, guess):
    """Initial model: from moments (fixed values from ``kw``/instance) or the instance."""
    if instance is not None and guess == "model":
        return instance
    sig = inspect.signature(cls.from_moments).parameters
    args = {k: v for k, v in kw.items() if k in sig}
    if instance is not None:
        args.update({k: getattr(instance, k) for k in sig if k not in ("mean", "variance")
                     and hasattr(instance, k) and k not in kw})
    return cls.from_moments(mom.mean, mom.variance, **args)


def _curve(model, t, kind, inlet):
    if inlet is not None and isinstance(model, PlugFlow):
        # a pure delay: shift the linearly interpolated inlet, smooth in tau (the
        # piecewise-constant convolution would be flat between sampling times)
        area = np.trapezoid(inlet, t)
        return np.interp(t - model.tau, t, inlet, left=0.0, right=0.0) / area
    if inlet is not None:
        return convolve_inlet(model.cdf, t, inlet)
    return model.pdf(t) if kind == "pulse" else model.cdf(t)


def fit(model, t, c=None, *, kind: str | None = None, inlet=None, vary=None,
        scale: float | None = None, guess: str = "moments", tail="auto",
        **fixed) -> FitResult:
    """Fit an RTD model to a tracer curve by least squares in the time domain.

    Parameters
    ----------
    model : str, model class or model instance
        A name (``"cstr", "plug", "tis", "ad-closed", "ad-open", "cells"``), a class, or
        an instance (its non-varied parameters are kept; ``guess="model"`` also starts
        from its values).
    t, c : arrays or TracerCurve
        Times [any unit; tau comes out in it] and concentrations; or a TracerCurve as
        ``t`` (its kind and inlet are used).
    kind : {"pulse", "step"}
        E-curve or F-curve data.
    inlet : array, optional
        Measured inlet concentration on the same times: fit the convolution.
    vary : sequence of str, optional
        Parameters to fit (default: all but the model's ``fixed_by_default``).
    scale : float, optional
        Known A (tracer area of a pulse, plateau of a step) instead of fitting it: then
        a bypass (missing area) becomes identifiable.
    **fixed
        Fixed parameter values, e.g. ``n=4`` for ``"cells"``.

    Returns
    -------
    FitResult
    """
    unit = getattr(t, "time_unit", "") or ""
    t, c, kind, inlet, notes = _unpack(t, c, kind, inlet)
    cls, kw, instance = resolve_model(model, **fixed)
    mom = moments(t, c, tail) if kind == "pulse" else step_moments(t, c)
    if mom.note:
        notes.append(mom.note)
    if inlet is not None:  # moments add under convolution: the vessel's are the difference
        im = moments(t, np.asarray(inlet, float), tail=False)
        mom = type(mom)(mom.area, max(mom.mean - im.mean, 1e-3 * mom.mean),
                        max(mom.variance - im.variance, 1e-2 * mom.variance))
    start = _start(cls, kw, instance, mom, guess)
    names = tuple(vary) if vary is not None else tuple(
        k for k in start.param_names if k not in start.fixed_by_default and k not in fixed)
    bad = [k for k in names if k not in start.param_names or k not in BOUNDS]
    if bad or (isinstance(start, RecirculatingCells) and "n" in names):
        raise RTDError(f"vary = {list(names)}: cannot fit {bad or ['n']}; expected names among "
                       f"{[k for k in start.param_names if k in BOUNDS]} (the number of cells "
                       "is an integer: fix it with n=... and compare fits)")
    if cls is PlugFlow and inlet is None:
        return dataclasses.replace(_plug_by_moments(start, t, c, kind, mom, notes), time_unit=unit)
    # The fit is scale-free: solve for c / peak (so curves in any concentration unit, 1e-90
    # or 1e90, meet the same bounds and tolerances) and return A, SSR, SER, AIC, BIC, data,
    # fitted curve and residuals in the data's units.
    k = float(np.max(np.abs(c)))
    res = _least_squares(start, names, t, c / k, kind, inlet, mom, notes, None if scale is None else scale / k)
    res = dataclasses.replace(res, time_unit=unit)
    if k == 1.0:
        return res
    shift = 2 * res.n_data * math.log(k)  # n ln(SSR/n) grows by n ln k^2
    return dataclasses.replace(res, scale=res.scale * k, scale_se=res.scale_se * k, ssr=res.ssr * k * k,
                               ser=res.ser * k, aic=res.aic + shift, bic=res.bic + shift, data=res.data * k,
                               fitted=res.fitted * k, residuals=res.residuals * k)


def _unpack(t, c, kind, inlet):
    """Checked (t, c, kind, inlet, notes) from arrays or a TracerCurve."""
    notes = []
    if isinstance(t, TracerCurve):
        curve = t
        t, c = curve.t, curve.c
        kind = kind or curve.kind
        inlet = curve.inlet if inlet is None else inlet
        notes += list(curve.notes)
    kind = kind or "pulse"
    if kind not in ("pulse", "step"):
        raise TracerError(f"kind = {kind!r}; expected 'pulse' or 'step'")
    if inlet is not None and kind != "pulse":
        raise TracerError("an inlet curve is only used with pulse data", "inlet")
    t, c = check_tracer(t, c, kind, inlet=inlet)
    return t, c, kind, inlet, notes


def _least_squares(start, names, t, c, kind, inlet, mom, notes, scale=None) -> FitResult:
    free = scale is None  # the scale A is fitted unless given
    n_par = len(names) + free
    if t.size <= n_par:
        raise TracerError(f"{t.size} data points for {n_par} parameters ({', '.join(names)}"
                          f"{', scale' if free else ''}); expected more points than parameters")
    extra = [(True, 1e-12, np.inf, _scale0(start, t, c, kind, inlet))] if free else []
    spec = [(BOUNDS[k][2], BOUNDS[k][0] * (mom.mean if k == "tau" else 1),
             BOUNDS[k][1] * (mom.mean if k == "tau" else 1), getattr(start, k)) for k in names]
    logs, lo, hi, x0 = (np.array(col, dtype=float) for col in zip(*(spec + extra)))
    logs = logs.astype(bool)
    x0 = np.clip(x0, lo + 1e-12 * np.abs(lo), hi)

    def to_x(z):
        return np.where(logs, np.exp(z), z)

    def predict(x):
        model = start.replace(**dict(zip(names, x[:len(names)])))
        return (x[-1] if free else scale) * _curve(model, t, kind, inlet)

    def resid(z):
        return predict(to_x(z)) - c

    with np.errstate(divide="ignore"):
        zlo, zhi, z0 = (np.where(logs, np.log(v), v) for v in (lo, hi, x0))
    z0 = np.clip(z0, zlo, zhi)
    from scipy import optimize  # here, not at module level (start-up)

    sol = optimize.least_squares(resid, z0, bounds=(zlo, zhi), method="trf",
                                 x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    x = to_x(sol.x)
    fitted = predict(x)
    jac = _jacobian(predict, x, lo, hi)
    model = start.replace(**dict(zip(names, x[:len(names)])))
    res = _result(model, names, x, jac, t, c, fitted, kind, sol, notes, scale)
    return res if inlet is None else dataclasses.replace(res, inlet=np.asarray(inlet, float))


def _scale0(model, t, c, kind, inlet) -> float:
    """Scale A minimising the residual for the starting shape (a linear fit)."""
    g = _curve(model, t, kind, inlet)
    den = float(g @ g)
    return float(g @ c) / den if den > 0 else float(np.max(c))


def _jacobian(predict, x, lo, hi) -> np.ndarray:
    """D model / d parameters (natural units) by central differences, one-sided at bounds."""
    cols = []
    for i, xi in enumerate(x):
        h = 1e-6 * max(abs(xi), 1e-8)
        up, dn = min(xi + h, hi[i]), max(xi - h, lo[i])
        xp, xm = x.copy(), x.copy()
        xp[i], xm[i] = up, dn
        cols.append((predict(xp) - predict(xm)) / (up - dn))
    return np.column_stack(cols)


def _result(model, names, x, jac, t, c, fitted, kind, sol, notes, scale) -> FitResult:
    """Statistics of eq. 9 at the estimate x (model parameters, then the scale if free)."""
    r = fitted - c
    n, p = c.size, x.size
    ssr = float(r @ r)
    ser = math.sqrt(ssr / (n - p))
    jtj = jac.T @ jac
    try:
        cov = ser**2 * np.linalg.inv(jtj)
    except np.linalg.LinAlgError:
        cov = np.full((p, p), np.nan)
    if not np.all(np.isfinite(cov)) or np.linalg.cond(jtj) > 1e14:
        notes = notes + ["J^T J is (nearly) singular: some parameters are not identifiable "
                         "from these data; standard errors are unreliable"]
    se = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    sst = float(np.sum((c - c.mean())**2))
    ll = n * math.log(ssr / n) if ssr > 0 else -np.inf
    k = len(names)
    a, a_se = (float(x[-1]), float(se[-1])) if scale is None else (float(scale), 0.0)
    return FitResult(model, tuple(names), x[:k], se[:k], corr, a, a_se,
                     ssr, ser, 1 - ssr / sst, ll + 2 * p, ll + p * math.log(n), n, p, t, c,
                     fitted, r, kind, bool(sol.success), str(sol.message), int(sol.nfev),
                     tuple(notes))


def _plug_by_moments(model, t, c, kind, mom, notes) -> FitResult:
    """Plug flow has no shape to fit on pulse data: tau is the first moment."""
    notes = notes + ["plug flow: tau is the mean residence time from the moments; no "
                     "least squares (E is a delta), se not available"]
    fitted = mom.area * _curve(model, t, kind, None)
    r = fitted - c
    n, ssr = c.size, float(r @ r)
    ll = n * math.log(ssr / n) if ssr > 0 else -np.inf
    sst = float(np.sum((c - c.mean())**2))
    return FitResult(model, ("tau",), np.array([model.tau]), np.array([np.nan]),
                     np.full((1, 1), np.nan), mom.area, float("nan"), ssr,
                     math.sqrt(ssr / max(n - 2, 1)), 1 - ssr / sst, ll + 4, ll + 2 * math.log(n),
                     n, 2, t, c, fitted, r, kind, True, "moments", 0, tuple(notes))


def compare(models, t, c=None, **kwargs) -> list[FitResult]:
    """Fit several candidate models to the same data; results sorted by AIC (best first)."""
    results = [fit(m, t, c, **kwargs) for m in models]
    return sorted(results, key=lambda res: res.aic)
