"""Classifier efficiency curves: the fraction of each size sent to the coarse stream.

Every curve is a plain function of the representative sizes x [m] (a
:class:`~millflow.grid.SizeGrid` or an array) that returns c_i in [0, 1], the mass
fraction of class i reporting to the coarse product (hydrocyclone underflow, screen
oversize, air-separator rejects); 1 - c_i goes to the fine product. A classifier is
therefore linear in the feed: coarse = diag(c) feed, fine = diag(1 - c) feed, which is
how the flowsheet solver uses it. Bypass is the fraction of every size that short-cuts
to the coarse stream unclassified (for a hydrocyclone, the water split to underflow,
R_f), so the actual curve is c = bypass + (1 - bypass) c_corr with c_corr the
corrected curve (0 for fines, 1 for coarse, 1/2 at the corrected cut size d50c).

Forms implemented (x' = x/d50c):

- Whiten (1966, JKSimMet form), with optional fish-hook beta >= 0:
  to overflow E_oc = (1 + beta beta* x')(e^alpha - 1) / (e^(alpha beta* x') + e^alpha - 2),
  beta* chosen so that E_oc(1) = 1/2 (beta* = 1 for beta = 0); c_corr = 1 - E_oc.
  With beta > 0 the actual curve dips below the bypass for fine sizes (the fish-hook);
  it is clipped to [0, 1].
- Plitt (1976) / Rosin-Rammler form: c_corr = 1 - exp(-ln 2 x'^m).
- Screen: probability of a particle not passing the aperture, same Rosin-Rammler form in
  x/d50 with the sharpness m, plus ``bypass`` (fines misplaced to oversize).
- Tromp (air separators, dynamic classifiers): log-logistic c_corr = 1/(1 + x'^-m);
  sharpness kappa = d25/d75 = 3^(-2/m) of the corrected curve.

The registry :data:`CURVES` maps the names used in flowsheet files to these functions;
:func:`efficiency` looks a name up and lists the valid names when it is unknown.

References: Whiten (1974); Plitt, CIM Bull. 69 (1976) 114; Napier-Munn et al.,
Mineral Comminution Circuits (JKMRC, 1996), ch. 10.
"""
from __future__ import annotations

import math

import numpy as np

from millflow.errors import InputError
from millflow.grid import as_sizes

__all__ = ["whiten", "plitt", "screen_efficiency", "tromp", "CURVES", "efficiency", "mill_discharge_rates",
           "screen_discharge", "screen_power_discharge"]

_LN2 = math.log(2.0)


def _positive(value, name: str, curve: str) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{curve}: {name} = {value!r}; expected a finite number > 0")
    return v


def _fraction(value, name: str, curve: str, upper_open: bool = True) -> float:
    v = float(value)
    ok = math.isfinite(v) and 0.0 <= v and (v < 1.0 if upper_open else v <= 1.0)
    if not ok:
        raise InputError(f"{curve}: {name} = {value!r}; expected a fraction in [0, {'1)' if upper_open else '1]'}")
    return v


def _with_bypass(c_corr: np.ndarray, bypass: float) -> np.ndarray:
    return np.clip(bypass + (1.0 - bypass) * c_corr, 0.0, 1.0)


def _whiten_to_overflow(u: np.ndarray, alpha: float, beta: float, beta_star: float) -> np.ndarray:
    """E_oc at reduced sizes u = x/d50c, evaluated without overflow for large alpha u."""
    # divide numerator and denominator by e^alpha: (1 + b b* u)(1 - e^-a) / (e^(a(b* u - 1)) + 1 - 2 e^-a)
    ea = math.exp(-alpha)
    with np.errstate(over="ignore"):
        den = np.exp(np.minimum(alpha * (beta_star * u - 1.0), 700.0)) + 1.0 - 2.0 * ea
    return (1.0 + beta * beta_star * u) * (1.0 - ea) / den


def _whiten_beta_star(alpha: float, beta: float) -> float:
    if beta == 0.0:
        return 1.0
    f = lambda bs: float(_whiten_to_overflow(np.array(1.0), alpha, beta, bs)) - 0.5  # noqa: E731
    hi = 2.0
    while f(hi) > 0:
        hi *= 2.0
        if hi > 1e6:
            raise InputError(f"whiten: no beta* found for alpha = {alpha!r}, beta = {beta!r}")
    from scipy.optimize import brentq  # imported here: scipy.optimize loads scipy.sparse (start-up)

    return brentq(f, 1e-9, hi, xtol=1e-15, rtol=1e-15)


def whiten(x, d50c: float, alpha: float, beta: float = 0.0, bypass: float = 0.0) -> np.ndarray:
    """Whiten efficiency curve to the coarse stream (underflow), with optional fish-hook.

    Parameters
    ----------
    x : SizeGrid or array_like
        Sizes [m].
    d50c : float
        Corrected cut size [m] (> 0).
    alpha : float
        Sharpness [-] (> 0; 2-6 for hydrocyclones).
    beta : float
        Fish-hook parameter [-] (>= 0; 0 = no fish-hook).
    bypass : float
        Fraction R_f of every size short-cut to underflow [-], in [0, 1).

    Returns
    -------
    numpy.ndarray
        Fraction of each class to underflow, c = R_f + (1 - R_f)(1 - E_oc), clipped to [0, 1].

    Examples
    --------
    >>> round(float(whiten([1e-4], 1e-4, 3.0, bypass=0.2)[0]), 12)
    0.6
    """
    xs = as_sizes(x)
    d50c = _positive(d50c, "d50c", "whiten")
    alpha = _positive(alpha, "alpha", "whiten")
    beta = float(beta)
    if not (math.isfinite(beta) and beta >= 0):
        raise InputError(f"whiten: beta = {beta!r}; expected a finite number >= 0 (0 = no fish-hook)")
    bypass = _fraction(bypass, "bypass", "whiten")
    bs = _whiten_beta_star(alpha, beta)
    return _with_bypass(1.0 - _whiten_to_overflow(xs / d50c, alpha, beta, bs), bypass)


def plitt(x, d50c: float, m: float, bypass: float = 0.0) -> np.ndarray:
    """Plitt (Rosin-Rammler) efficiency curve to underflow: c_corr = 1 - exp(-ln2 (x/d50c)^m).

    Parameters: sizes x [m], corrected cut size d50c [m], sharpness m [-] (> 0; 1.5-4),
    bypass to underflow [-] in [0, 1).

    >>> round(float(plitt([2e-4], 2e-4, 3.0)[0]), 12)
    0.5
    """
    xs = as_sizes(x)
    d50c = _positive(d50c, "d50c", "plitt")
    m = _positive(m, "m", "plitt")
    bypass = _fraction(bypass, "bypass", "plitt")
    return _with_bypass(-np.expm1(-_LN2 * (xs / d50c) ** m), bypass)


def screen_efficiency(x, d50: float, m: float = 5.0, bypass: float = 0.0) -> np.ndarray:
    """Screen partition curve: fraction of each class retained on the deck (oversize).

    c = bypass + (1 - bypass)(1 - exp(-ln2 (x/d50)^m)). d50 [m] is the size retained
    with probability 1/2 (a little below the aperture); m [-] the sharpness (5-10 for
    a well operated screen); bypass [-] the undersize carried over with the oversize.
    """
    xs = as_sizes(x)
    d50 = _positive(d50, "d50", "screen")
    m = _positive(m, "m", "screen")
    bypass = _fraction(bypass, "bypass", "screen")
    return _with_bypass(-np.expm1(-_LN2 * (xs / d50) ** m), bypass)


def tromp(x, d50c: float, m: float, bypass: float = 0.0) -> np.ndarray:
    """Tromp curve of an air separator / dynamic classifier: fraction to rejects (coarse).

    c = bypass + (1 - bypass) / (1 + (d50c/x)^m): log-logistic corrected curve with cut
    size d50c [m] and exponent m [-] (sharpness kappa = d25/d75 = 3^(-2/m)); bypass [-]
    in [0, 1) is the fraction of fines carried to the rejects.

    >>> round(float(tromp([3e-5], 3e-5, 4.0, bypass=0.1)[0]), 12)
    0.55
    """
    xs = as_sizes(x)
    d50c = _positive(d50c, "d50c", "tromp")
    m = _positive(m, "m", "tromp")
    bypass = _fraction(bypass, "bypass", "tromp")
    with np.errstate(over="ignore"):
        c_corr = 1.0 / (1.0 + (d50c / xs) ** m)
    return _with_bypass(c_corr, bypass)


#: Efficiency curves by the name used in flowsheet files (``curve = "whiten"``).
CURVES = {"whiten": whiten, "plitt": plitt, "screen": screen_efficiency, "tromp": tromp}


def efficiency(curve, x, **params) -> np.ndarray:
    """Evaluate a curve given by name (a key of :data:`CURVES`) or as a callable ``f(x, **params)``.

    The result is checked to be finite and in [0, 1].
    """
    if isinstance(curve, str):
        try:
            fun = CURVES[curve]
        except KeyError:
            raise InputError(f"unknown efficiency curve {curve!r}; valid names: {', '.join(sorted(CURVES))}") from None
    elif callable(curve):
        fun = curve
    else:
        raise InputError(f"curve = {curve!r}: expected a name ({', '.join(sorted(CURVES))}) or a callable")
    try:
        c = np.asarray(fun(x, **params), dtype=float)
    except TypeError as exc:
        raise InputError(f"efficiency curve {curve!r}: bad parameters {sorted(params)} ({exc})") from exc
    if c.shape != as_sizes(x).shape or not np.all(np.isfinite(c)) or np.any((c < 0) | (c > 1)):
        raise InputError(f"efficiency curve {curve!r} must return one finite value in [0, 1] per size")
    return c


def mill_discharge_rates(c) -> np.ndarray:
    """Normalised discharge rates d_i* of a mill whose exit is a screen or grate.

    A class retained with probability c_i by the discharge screen leaves the mill
    (1 - c_i) times as fast as freely discharging material, so
    d_i* = (1 - c_i) / (1 - c_N): the finest class (the sink) discharges freely
    (d* = 1 when c_N = 0) and ``tau`` is the mean residence time of freely
    discharging material (eq. 1 and 3 of docs/equations.md).
    """
    c = np.asarray(c, dtype=float)
    free = 1.0 - c[-1]
    if free <= 0:
        raise InputError("discharge classification retains the finest class completely (c_N = 1): "
                         "nothing can leave the mill")
    return (1.0 - c) / free


# --------------------------------------------------------------- discharge through a screen
# Normalised discharge rates d_i* (eq. 1-3) of a mill whose exit is a screen, as the
# fit estimates them: vectorised over a population of parameter sets (leading axes),
# not validated (the hot loop of a fit; non-finite parameters give NaN or inf).

def screen_discharge(x, d50, n) -> np.ndarray:
    """Log-logistic screen discharge d_i* = 1 / (1 + (x_i / d50)^n), shape (*L, N).

    Material much finer than d50 [m] leaves at the mean rate (d* = 1), coarser material
    is held back until it breaks (d* -> 0); n [-] is the sharpness. It is one minus the
    corrected Tromp curve (:func:`tromp`) with the same d50 and exponent, without the
    1/(1 - c_N) scaling of :func:`mill_discharge_rates`. ``d50`` and ``n`` broadcast to
    a leading shape L (members of a population, conditions); evaluated as
    1/(1 + exp(n ln(x/d50))) with the exponent capped at 600, so nothing overflows.
    """
    xs = as_sizes(x)
    d50 = np.asarray(d50, dtype=float)[..., np.newaxis]
    n = np.asarray(n, dtype=float)[..., np.newaxis]
    with np.errstate(invalid="ignore", divide="ignore"):
        z = n * (np.log(xs) - np.log(d50))
    return 1.0 / (1.0 + np.exp(np.minimum(z, 600.0)))


def screen_power_discharge(x, n, x_ref) -> np.ndarray:
    """Power-law screen discharge d_i* = (x_i / x_ref)^-n, shape (*L, N).

    The limit of :func:`screen_discharge` for d50 far below the sizes of interest
    (then d* = (x/d50)^-n): only the combination of the rate prefactor and d50^n is
    identifiable from product samples; x_ref [m] is the size where d* = 1 (in the fit:
    the reference size x0 times the screen opening over the geometric-mean opening).
    ``n`` and ``x_ref`` broadcast to a leading shape L; the exponent is capped at
    +-600 so nothing overflows.
    """
    xs = as_sizes(x)
    n = np.asarray(n, dtype=float)[..., np.newaxis]
    x_ref = np.asarray(x_ref, dtype=float)[..., np.newaxis]
    with np.errstate(invalid="ignore", divide="ignore"):
        z = n * (np.log(xs) - np.log(x_ref))
    np.maximum(z, -600.0, out=z)  # clipped in place (a fit's population: one array, no copies)
    np.minimum(z, 600.0, out=z)
    np.negative(z, out=z)
    return np.exp(z, out=z)
