"""What every rtd model shares: the error types, parameter checks and the RTDModel base.

A module of its own so that the model modules (:mod:`rtd.models`, :mod:`rtd.axial`,
:mod:`rtd.compartments`, :mod:`rtd.compose`) import it and not each other in a circle.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np


class RTDError(ValueError):
    """Base class of rtd errors: a parameter, data value or option is unusable."""


class ParameterError(RTDError):
    """A model parameter is outside its valid range (the message names it)."""


def memory_budget_bytes() -> float:
    """Largest array an rtd computation may allocate: ``RTD_MEMORY_BUDGET_GB`` GiB (default 4)."""
    import os

    raw = os.environ.get("RTD_MEMORY_BUDGET_GB", "4")
    try:
        gib = float(raw)
    except ValueError:
        raise ParameterError(f"RTD_MEMORY_BUDGET_GB = {raw!r}: expected a number of GiB") from None
    return gib * 2.0**30


def check_memory(nbytes: float, what: str) -> None:
    """Refuse, before allocating, an array larger than the memory budget, saying its size."""
    budget = memory_budget_bytes()
    if nbytes > budget:
        raise ParameterError(f"{what} would need {nbytes / 2**30:.3g} GiB, above the memory budget of "
                             f"{budget / 2**30:.3g} GiB (RTD_MEMORY_BUDGET_GB); use fewer cells or times")


def _as_float(model: str, name: str, value, expected: str) -> float:
    """float(value), or a ParameterError naming the parameter (None, a list, a string)."""
    if isinstance(value, bool):
        raise ParameterError(f"{model}: {name} = {value!r}; expected {expected}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{model}: {name} = {value!r}; expected {expected}") from None


def check_positive(model: str, name: str, value) -> float:
    """Return ``value`` as float, or raise ParameterError if it is not finite and > 0."""
    value = _as_float(model, name, value, "a finite number > 0")
    if not (math.isfinite(value) and value > 0.0):
        raise ParameterError(f"{model}: {name} = {value!r}; expected a finite number > 0")
    return value


def check_fraction(model: str, name: str, value, upper_open: bool = False) -> float:
    """Return ``value`` as float, or raise ParameterError if it is not in [0, 1]."""
    value = _as_float(model, name, value, "a fraction in [0, 1]")
    ok = math.isfinite(value) and 0.0 <= value and (value < 1.0 if upper_open else value <= 1.0)
    if not ok:
        upper = "1)" if upper_open else "1]"
        raise ParameterError(f"{model}: {name} = {value!r}; expected a fraction in [0, {upper}")
    return value


def as_time(t) -> np.ndarray:
    """Times as a float array (any shape)."""
    return np.asarray(t, dtype=float)


def as_s(s) -> tuple[np.ndarray, bool]:
    """Transform variable as an array and whether it was real (result is then real)."""
    arr = np.asarray(s)
    if np.iscomplexobj(arr):
        return arr.astype(complex), False
    return arr.astype(float), True


def generic_survival(model, s):
    """(1 - E_hat(s))/s of any model with ``laplace`` and ``mean``; ``mean`` at s = 0."""
    s_arr, real = as_s(s)
    zero = s_arr == 0
    safe = np.where(zero, 1.0, s_arr)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (1.0 - np.asarray(model.laplace(safe))) / safe
    out = np.where(zero, float(model.mean), out)
    return (out.real if real else out)[()]


def survival_error(model, s):
    """Bound of the absolute rounding error of ``survival_laplace`` at real s >= 0.

    Closed forms (``exact_survival``): every term is non-negative for s >= 0, so the value
    keeps a relative error of a few tens of ulp (32 eps |G|). The generic quotient: eps (1 +
    |E_hat|)/s from the subtraction, amplified by 1/s (4 eps for the rounding of E_hat).
    """
    s = np.asarray(s, dtype=float)
    G = np.abs(np.asarray(survival_of(model, s), dtype=complex))
    eps = np.finfo(float).eps
    if getattr(model, "exact_survival", False):
        return 32 * eps * G
    with np.errstate(divide="ignore", invalid="ignore"):
        E = np.abs(np.asarray(model.laplace(s)))
        return np.where(s > 0, 4 * eps * (1 + E) / np.where(s > 0, s, 1.0), 32 * eps * G)


def survival_of(model, s):
    """``model.survival_laplace(s)`` where the model has it, else the generic quotient."""
    fun = getattr(model, "survival_laplace", None)
    return fun(s) if fun is not None else generic_survival(model, s)


def clog1p(z):
    """log(1 + z) for complex z without numpy's cancellation for small |z|.

    log|1 + z| = log1p(2 Re z + |z|^2)/2, arg(1 + z) = atan2(Im z, 1 + Re z).
    """
    z = np.asarray(z, dtype=complex)
    x, y = z.real, z.imag
    return 0.5 * np.log1p(2 * x + x * x + y * y) + 1j * np.arctan2(y, 1 + x)


@dataclass(frozen=True)
class RTDModel:
    """Common interface of every RTD model (one level of inheritance only).

    Subclasses define ``pdf``, ``cdf``, ``laplace``, ``mean``, ``variance`` and
    ``analytic_for_re_s_greater_than``; ``param_names`` lists the parameters that
    :func:`rtd.fit` may vary, ``fixed_by_default`` those it keeps fixed unless asked.
    """

    param_names: ClassVar[tuple[str, ...]] = ()
    fixed_by_default: ClassVar[tuple[str, ...]] = ()

    @property
    def params(self) -> dict[str, float]:
        """Parameters by name (a new dict)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name in self.param_names}

    def replace(self, **changes) -> "RTDModel":
        """A copy with some parameters changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @property
    def atom_at_zero(self) -> float:
        """Probability mass leaving at t = 0 (bypass); not part of ``pdf``."""
        return 0.0

    #: True when :meth:`survival_laplace` is evaluated without cancellation (a closed form
    #: of (1 - E_hat(s))/s); False for the generic quotient, which loses eps/(|s| mean).
    exact_survival: ClassVar[bool] = False

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s, the transform of 1 - F(t) [time]; G(0) = mean.

        Generic form: the quotient itself, which cancels for |s| mean << 1 (absolute error
        ~ eps (1 + |E_hat|)/|s|); the models of this package override it with closed forms
        (``exact_survival``).
        """
        return generic_survival(self, s)

    def moments_from_transform(self, h: float | None = None) -> tuple[float, float]:
        """Mean and variance from finite differences of log E_hat at s = 0 (a check)."""
        h = h or 1e-4 / self.mean
        lp = np.log(np.array([self.laplace(-h), self.laplace(0.0), self.laplace(h)]))
        mean = -(lp[2] - lp[0]) / (2 * h)
        var = (lp[2] - 2 * lp[1] + lp[0]) / h**2
        return float(mean), float(var)
