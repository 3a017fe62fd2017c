"""Specific breakage rates S_i [1/s] on a size grid (docs/equations.md, eqs. 5, 7, 10).

A rate model is anything callable as ``model(x) -> S``: x the representative (upper)
class sizes [m] of a :class:`~millflow.grid.SizeGrid` (or the grid itself), S an
array of N first-order rates [1/s]. The last class is the sink and never breaks: every
function here returns S with S_N = 0, whatever the formula would give at x_N.
Plain functions implement the forms: the power law (eq. 5), Austin's rate with a
maximum and ball-size dependence (eq. 7), and the process-parameter power law for
its prefactor (eq. 10); small frozen dataclasses on top hold validated parameters.
A user's own function plugs in exactly like the built-in ones; pass any model through
:func:`evaluate_rates` to check its output.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from millflow.errors import BreakageError
from millflow.grid import as_sizes, class_label

__all__ = [
    "power_law_rates",
    "austin_rates",
    "power_law_rates_population",
    "austin_rates_population",
    "X0_DEFAULT",
    "process_power_law",
    "ln_process_power_law",
    "validate_rates",
    "evaluate_rates",
    "PowerLawRate",
    "AustinRate",
    "TabulatedRate",
]


#: Default reference size x0 [m] of eqs. 5 and 7: 1 mm, for every rate law (A is then
#: the rate of 1 mm particles, in 1/s).
X0_DEFAULT = 1e-3


def _finite(value, name: str, *, positive: bool = False, nonneg: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise BreakageError(f"{name} = {value!r}: expected a number") from exc
    if not np.isfinite(v):
        raise BreakageError(f"{name} = {value!r}: expected a finite number")
    if positive and v <= 0:
        raise BreakageError(f"{name} = {value!r}: expected > 0")
    if nonneg and v < 0:
        raise BreakageError(f"{name} = {value!r}: expected >= 0")
    return v


# ----------------------------------------------------------------------- validation
def validate_rates(S, x=None, *, name: str = "S") -> np.ndarray:
    """Check a rate vector: 1-D, finite, >= 0, and S_N = 0 for the sink.

    Parameters
    ----------
    S : array_like
        Specific breakage rates [1/s], coarse -> fine, length N.
    x : SizeGrid or array_like, optional
        Class sizes [m]; when given the length must match and messages show sizes.

    Returns
    -------
    numpy.ndarray
        ``S`` as float64.

    Raises
    ------
    BreakageError
        Naming the 1-based class, its size and the bad value.
    """
    xs = None if x is None else as_sizes(x)
    try:
        s = np.array(S, dtype=float)
    except (TypeError, ValueError) as exc:
        raise BreakageError(f"{name}: cannot read rates as numbers ({exc})") from exc
    if s.ndim != 1 or s.size < 1:
        raise BreakageError(f"{name}: expected a 1-D array of rates [1/s], got shape {s.shape}")
    if xs is not None and s.size != xs.size:
        raise BreakageError(f"{name}: {s.size} rates for a grid of {xs.size} classes")
    if not np.isfinite(s).all():  # locate the offender only on failure (hot path)
        bad = np.flatnonzero(~np.isfinite(s))
        raise BreakageError(f"{name}: {class_label(bad[0], xs)} has rate {float(s[bad[0]])!r} 1/s; expected finite")
    if (s < 0).any():
        bad = np.flatnonzero(s < 0)
        raise BreakageError(f"{name}: {class_label(bad[0], xs)} has rate {float(s[bad[0]])!r} 1/s; expected >= 0")
    if s[-1] != 0:
        raise BreakageError(
            f"{name}: {class_label(s.size - 1, xs)} is the sink and has rate {float(s[-1])!r} 1/s; expected S_N = 0"
        )
    return s


def evaluate_rates(model, grid) -> np.ndarray:
    """Evaluate any rate model (callable ``x -> S`` or object with ``.rates``) and check it.

    Parameters
    ----------
    model : callable or object with a ``rates(x)`` method
        Built-in dataclass or a user's function of the sizes x [m].
    grid : SizeGrid or array_like
        Class sizes [m].

    Returns
    -------
    numpy.ndarray
        Validated rates [1/s] with S_N = 0.
    """
    x = as_sizes(grid)
    fun = getattr(model, "rates", model)
    if not callable(fun):
        raise BreakageError(f"rate model {model!r} is neither callable nor has a .rates(x) method")
    return validate_rates(fun(x), x, name=f"rates of {getattr(model, '__name__', type(model).__name__)}")


# ----------------------------------------------------------------------- functional forms
def power_law_rates_population(x, A, alpha, x0=X0_DEFAULT) -> np.ndarray:
    """Eq. 5 for a population of parameter sets: S[..., i] = A (x_i / x0)^alpha, S_N = 0.

    The one implementation of eq. 5 (:func:`power_law_rates` is this with scalar
    parameters, then checked). ``A`` [1/s] (rate at x0), ``alpha`` [-] and ``x0`` [m]
    broadcast against each other to a leading shape L (e.g. (P,) members or (P, C)
    members x conditions); returns (*L, N). Nothing is validated or raised here (the
    hot loop of a fit): a member with A < 0 or a non-finite parameter gets NaN rates,
    which an optimiser reads as "outside the model's domain".
    """
    xs = as_sizes(x)
    A, alpha, x0 = (np.asarray(v, dtype=float)[..., np.newaxis] for v in (A, alpha, x0))
    with np.errstate(over="ignore", invalid="ignore"):
        S = A * (xs / x0) ** alpha
    ok = (A >= 0) & np.isfinite(alpha) & (x0 > 0)
    if not ok.all():  # (a pass over S only where some member is outside the domain)
        S = np.where(ok, S, np.nan)
    S[..., -1] = 0.0  # the sink does not break
    return S


def austin_rates_population(x, A, alpha, mu0, Lambda, xi=0.0, x_b=None, x_b0=None, eta=0.0,
                            x0=X0_DEFAULT) -> np.ndarray:
    """Eq. 7 for a population of parameter sets; see :func:`austin_rates` for the symbols.

    S = A (x/x0)^alpha (x_b0/x_b)^xi / (1 + [x / (mu0 (x_b/x_b0)^eta)]^Lambda), S_N = 0.
    The one implementation of eq. 7: every parameter (ball sizes too, e.g. one per
    condition) broadcasts to a leading shape L; returns (*L, N). Not validated: members
    outside the domain (A < 0, mu0 <= 0, Lambda < 0, non-finite) get NaN rates.
    """
    xs = as_sizes(x)
    A, alpha, mu0, Lambda, xi, eta, x0 = (np.asarray(v, dtype=float)[..., np.newaxis]
                                          for v in (A, alpha, mu0, Lambda, xi, eta, x0))
    if (x_b is None) != (x_b0 is None):
        raise BreakageError(f"x_b = {x_b!r}, x_b0 = {x_b0!r}: give both ball sizes [m] or neither")
    ball = 1.0
    if x_b is not None:
        ball = np.asarray(x_b, dtype=float)[..., np.newaxis] / np.asarray(x_b0, dtype=float)[..., np.newaxis]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        mu = mu0 * ball ** eta
        S = A * (xs / x0) ** alpha * ball ** (-xi) / (1.0 + (xs / mu) ** Lambda)
        ok = (A >= 0) & (mu0 > 0) & (Lambda >= 0) & (x0 > 0) & np.isfinite(alpha + xi + eta) & (np.asarray(ball) > 0)
    S = np.where(ok, S, np.nan)
    S[..., -1] = 0.0  # the sink does not break
    return S


def power_law_rates(x, A: float, alpha: float, x0: float = X0_DEFAULT) -> np.ndarray:
    """Power-law specific breakage rates, eq. 5: S_i = A (x_i / x0)^alpha.

    Parameters
    ----------
    x : SizeGrid or array_like
        Representative (upper) class sizes [m], coarse -> fine.
    A : float
        Rate at the reference size [1/s], >= 0.
    alpha : float
        Exponent [-] (typically 0.5 to 1.5).
    x0 : float
        Reference size [m], > 0; default 1 mm (:data:`X0_DEFAULT`): A is then the
        rate of 1 mm particles.

    Returns
    -------
    numpy.ndarray
        S [1/s], length N, with S_N = 0 for the sink.

    Examples
    --------
    >>> power_law_rates([2e-3, 1e-3, 5e-4], A=0.5, alpha=1.0, x0=1e-3)
    array([1. , 0.5, 0. ])
    """
    xs = as_sizes(x)
    A = _finite(A, "A", nonneg=True)
    alpha = _finite(alpha, "alpha")
    x0 = _finite(x0, "x0", positive=True)
    return validate_rates(power_law_rates_population(xs, A, alpha, x0), xs)


def austin_rates(x, A: float, alpha: float, mu0: float, Lambda: float, *, xi: float = 0.0,
                 x_b: float | None = None, x_b0: float | None = None, eta: float = 0.0,
                 x0: float = X0_DEFAULT) -> np.ndarray:
    """Austin's rate with a maximum and ball-size dependence, eq. 7.

    S_i = A (x_i/x0)^alpha (x_b0/x_b)^xi / (1 + [x_i / (mu0 (x_b/x_b0)^eta)]^Lambda)

    With the default ``x0 = 1e-3`` m (1 mm, as for eq. 5) A is the rate of 1 mm
    particles without the maximum term, Austin's usual convention of sizes in mm;
    ``x0 = 1`` gives eq. 7 as written with sizes in m (A in 1/s per m^alpha). To move
    A from x0 = 1 m to 1 mm, multiply it by (1e-3)^alpha.

    Parameters
    ----------
    x : SizeGrid or array_like
        Class sizes [m].
    A : float
        Rate prefactor [1/s] at x = x0 (without the maximum term), >= 0.
    alpha : float
        Small-size exponent [-].
    mu0 : float
        Size [m] at which the correction term equals 1/2 for the reference ball, > 0.
    Lambda : float
        Steepness of the fall-off above the maximum [-], >= 0.
    xi, eta : float
        Ball-size exponents of the prefactor and of mu [-].
    x_b, x_b0 : float, optional
        Ball size and reference ball size [m]; both or neither. Without them the
        ball-size factors are 1.
    x0 : float
        Reference size for alpha [m], default 1 mm (:data:`X0_DEFAULT`).

    Returns
    -------
    numpy.ndarray
        S [1/s] with S_N = 0.
    """
    xs = as_sizes(x)
    A = _finite(A, "A", nonneg=True)
    alpha = _finite(alpha, "alpha")
    mu0 = _finite(mu0, "mu0", positive=True)
    Lambda = _finite(Lambda, "Lambda", nonneg=True)
    xi = _finite(xi, "xi")
    eta = _finite(eta, "eta")
    x0 = _finite(x0, "x0", positive=True)
    if (x_b is None) != (x_b0 is None):
        raise BreakageError(f"x_b = {x_b!r}, x_b0 = {x_b0!r}: give both ball sizes [m] or neither")
    if x_b is not None:
        _finite(x_b, "x_b", positive=True)
        _finite(x_b0, "x_b0", positive=True)
    S = austin_rates_population(xs, A, alpha, mu0, Lambda, xi, x_b, x_b0, eta, x0)
    return validate_rates(S, xs)


def ln_process_power_law(ln_A0, params, exponents, reference=None):
    """Eq. 10 in logarithms: ln A = ln A0 + sum_k a_k ln(p_k / p_ref,k).

    The one implementation of eq. 10: :func:`process_power_law`, the fit's forward model
    (:mod:`millflow.fitting.models`, A and any parameter made condition-dependent) and the
    scale-up's fitted material (:mod:`millflow.scaleup.fitted`) all evaluate it here.
    Arrays broadcast, so one call covers a population of parameter sets times a set of
    conditions (shape (P, 1) exponents against (C,) process values gives (P, C)).

    Parameters
    ----------
    ln_A0 : float or array_like
        ln of the prefactor A0 [ln(1/s)] at the reference process values.
    params : mapping name -> float or array_like
        Process or design values p_k (speed fraction, ball size, ...), finite and > 0, in
        the units of ``reference``.
    exponents : mapping name -> float or array_like
        Exponents a_k [-], the same keys as ``params``.
    reference : mapping name -> float, optional
        Reference values p_ref,k (> 0; the fit uses the geometric mean over its
        conditions, which decorrelates ln A0 from the a_k). Default 1 for every k.

    Returns
    -------
    float or numpy.ndarray
        ln A [ln(1/s)], broadcast over the inputs.

    Raises
    ------
    BreakageError
        If the keys differ, or a process or reference value is not finite and > 0.

    Examples
    --------
    >>> float(ln_process_power_law(0.0, {"speed": 2.0}, {"speed": 1.5}, {"speed": 0.5}))  # 1.5 ln 4
    2.0794415416798357
    """
    if set(params) != set(exponents) or (reference is not None and set(reference) != set(params)):
        raise BreakageError(f"exponents: keys {sorted(exponents)} (and reference keys) must match params keys "
                            f"{sorted(params)}")
    ln_A = ln_A0
    for name in params:
        pk = np.asarray(params[name], dtype=float)
        ref = 1.0 if reference is None else float(reference[name])
        if not (np.all(np.isfinite(pk)) and np.all(pk > 0)):
            bad = pk if pk.ndim == 0 else pk[~(np.isfinite(pk) & (pk > 0))][0]
            raise BreakageError(f"process parameter {name} = {float(bad)!r}: expected a finite number > 0")
        if not (math.isfinite(ref) and ref > 0):
            raise BreakageError(f"reference of {name} = {ref!r}: expected a finite number > 0")
        ln_A = ln_A + np.asarray(exponents[name], dtype=float) * np.log(pk / ref)
    return ln_A


def process_power_law(A0: float, params, exponents) -> float:
    """Rate prefactor from process or design parameters, eq. 10: A = A0 prod p_k^a_k.

    Checked scalar form of :func:`ln_process_power_law` (reference values 1).

    Parameters
    ----------
    A0 : float
        Prefactor [1/s] (in whatever units make the p_k dimensionless), >= 0.
    params : sequence of float or mapping name -> float
        Process parameters p_k (speed fraction, ball density, ball size, ...), > 0.
    exponents : sequence of float or mapping name -> float
        Exponents a_k, same length (or same keys) as ``params``.

    Returns
    -------
    float
        A [1/s], to be used in eq. 5 or 7.

    Examples
    --------
    >>> process_power_law(2.0, {"speed": 0.75, "ball_mm": 40.0}, {"speed": 1.0, "ball_mm": 0.0})
    1.5
    """
    A0 = _finite(A0, "A0", nonneg=True)
    if isinstance(params, Mapping):
        if not isinstance(exponents, Mapping) or set(params) != set(exponents):
            raise BreakageError(
                f"exponents: keys {sorted(exponents) if isinstance(exponents, Mapping) else exponents!r} "
                f"must match params keys {sorted(params)}"
            )
        names = list(params)
        p = [params[k] for k in names]
        a = [exponents[k] for k in names]
    else:
        p, a = list(params), list(exponents)
        if len(p) != len(a):
            raise BreakageError(f"params has {len(p)} values but exponents has {len(a)}")
        names = [f"params[{k}]" for k in range(len(p))]
    p = {name: _finite(pk, f"process parameter {name}", positive=True) for name, pk in zip(names, p)}
    a = {name: _finite(ak, f"exponent of {name}") for name, ak in zip(names, a)}
    log_A = np.log(A0) if A0 > 0 else -np.inf
    return float(np.exp(ln_process_power_law(log_A, p, a)))


# ------------------------------------------------------------------------ dataclasses
@dataclass(frozen=True)
class PowerLawRate:
    """Eq. 5 rate model: S_i = A (x_i/x0)^alpha [1/s], S_N = 0.

    Parameters
    ----------
    A : float
        Rate at the reference size [1/s].
    alpha : float
        Exponent [-].
    x0 : float
        Reference size [m], default 1 mm (:data:`X0_DEFAULT`): A is the rate at 1 mm.

    References
    ----------
    L. G. Austin, R. R. Klimpel and P. T. Luckie, Process Engineering of Size Reduction:
    Ball Milling (SME-AIME, New York, 1984), ch. 4.

    Examples
    --------
    >>> from millflow.grid import SizeGrid
    >>> grid = SizeGrid.geometric(4e-3, 2.0, 4)  # 4, 2, 1, 0.5 mm
    >>> PowerLawRate(A=1 / 60, alpha=1.0).rates(grid) * 60  # [1/min]; the sink does not break
    array([4., 2., 1., 0.])
    """

    A: float
    alpha: float
    x0: float = X0_DEFAULT

    def __post_init__(self):
        _finite(self.A, "A", nonneg=True)
        _finite(self.alpha, "alpha")
        _finite(self.x0, "x0", positive=True)

    @classmethod
    def from_process(cls, A0, params, exponents, alpha: float, x0: float = X0_DEFAULT) -> "PowerLawRate":
        """Power law whose prefactor follows eq. 10 from process parameters."""
        return cls(process_power_law(A0, params, exponents), alpha, x0)

    def rates(self, x) -> np.ndarray:
        """S [1/s] on the sizes x [m] (or a SizeGrid)."""
        return power_law_rates(x, self.A, self.alpha, self.x0)

    __call__ = rates


@dataclass(frozen=True)
class AustinRate:
    """Eq. 7 rate model with a maximum and ball-size dependence; see :func:`austin_rates`.

    S_i = A (x_i/x0)^alpha (x_b0/x_b)^xi / (1 + [x_i / (mu0 (x_b/x_b0)^eta)]^Lambda), S_N = 0.

    Parameters
    ----------
    A : float
        Rate at the reference size x0 without the maximum term [1/s], >= 0.
    alpha : float
        Exponent of the power-law part [-].
    mu0 : float
        Size where the maximum term halves the rate [m], > 0 (at the reference ball size).
    Lambda : float
        Exponent of the maximum term [-], >= 0.
    xi, eta : float
        Ball-size exponents of A and of mu [-] (0: no ball-size dependence).
    x_b, x_b0 : float or None
        Ball and reference ball sizes [m]; both or neither.
    x0 : float
        Reference size [m], default 1 mm (as for :class:`PowerLawRate`).

    References
    ----------
    L. G. Austin, R. R. Klimpel and P. T. Luckie, Process Engineering of Size Reduction:
    Ball Milling (SME-AIME, New York, 1984), ch. 4.

    Examples
    --------
    >>> from millflow.grid import SizeGrid
    >>> grid = SizeGrid.geometric(4e-3, 2.0, 4)
    >>> S = AustinRate(A=1 / 60, alpha=1.0, mu0=2e-3, Lambda=3.0).rates(grid)
    >>> int(S.argmax()), round(float(S[1]) * 60, 12)  # the maximum at 2 mm: 2/min halved there to 1/min
    (1, 1.0)
    """

    A: float
    alpha: float
    mu0: float
    Lambda: float
    xi: float = 0.0
    x_b: float | None = None
    x_b0: float | None = None
    eta: float = 0.0
    x0: float = X0_DEFAULT

    def __post_init__(self):
        _finite(self.A, "A", nonneg=True)
        _finite(self.alpha, "alpha")
        _finite(self.mu0, "mu0", positive=True)
        _finite(self.Lambda, "Lambda", nonneg=True)
        _finite(self.xi, "xi")
        _finite(self.eta, "eta")
        _finite(self.x0, "x0", positive=True)
        if (self.x_b is None) != (self.x_b0 is None):
            raise BreakageError(f"x_b = {self.x_b!r}, x_b0 = {self.x_b0!r}: give both ball sizes [m] or neither")
        if self.x_b is not None:
            _finite(self.x_b, "x_b", positive=True)
            _finite(self.x_b0, "x_b0", positive=True)

    def _kw(self) -> dict:
        return dict(A=self.A, alpha=self.alpha, mu0=self.mu0, Lambda=self.Lambda, xi=self.xi,
                    x_b=self.x_b, x_b0=self.x_b0, eta=self.eta, x0=self.x0)

    def rates(self, x) -> np.ndarray:
        """S [1/s] on the sizes x [m] (or a SizeGrid)."""
        return austin_rates(x, **self._kw())

    __call__ = rates


@dataclass(frozen=True, eq=False)
class TabulatedRate:
    """Form-free rates: one value per class [1/s].

    Parameters
    ----------
    S : array_like
        Either N values with S_N = 0, or N - 1 values for the breaking classes (the
        sink's 0 is appended on evaluation). Finite, >= 0.
    """

    S: np.ndarray

    def __post_init__(self):
        s = np.array(self.S, dtype=float)
        # validate as if a sink 0 followed, so both accepted lengths are checked alike
        validate_rates(np.append(s, 0.0) if s.ndim == 1 else s, name="S")
        s.setflags(write=False)
        object.__setattr__(self, "S", s)

    def rates(self, x) -> np.ndarray:
        """The tabulated S [1/s] for the N classes of x (length N or N - 1 stored)."""
        xs = as_sizes(x)
        s = self.S
        if s.size == xs.size - 1:
            s = np.append(s, 0.0)
        elif s.size != xs.size:
            raise BreakageError(f"TabulatedRate has {s.size} rates; the grid has {xs.size} classes "
                                f"(expected {xs.size} or {xs.size - 1})")
        return validate_rates(s, xs)

    __call__ = rates

    def __repr__(self) -> str:
        return f"TabulatedRate(n={self.S.size}, S=[{self.S[0]:.4g} ... {self.S[-1]:.4g}] 1/s)"
