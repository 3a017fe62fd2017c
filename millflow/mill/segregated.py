"""Segregated flow: any residence time distribution with first-order breakage.

Each parcel of feed grinds as a batch (eq. 4) for its residence time t, which is
distributed with the exit-age density E(t) of the transport model. For first-order
breakage without classification this is exact (docs/equations.md, "segregated flow is
exact for first-order kinetics"):

    product = int_0^inf E(t) exp(K t) f dt = E_hat(A) f,             A = -K,
    hold-up = int_0^inf (1 - F(t)) exp(K t) f dt = G(A) f,   G(s) = (1 - E_hat(s)) / s,

the hold-up per unit feed rate [s] (material of age t is still inside with probability
1 - F(t)); G(0) is the mean residence time. Both are matrix functions of A evaluated
through :class:`millflow.linalg.SpectralBlocks`: V diag(E_hat(S_k)) V^-1 f on well
separated rates, and inside clusters of close rates a Taylor series whose coefficients
come from a Cauchy integral of E_hat (:func:`millflow.linalg.contour_funm`), so equal
rates are exact too.
"""
from __future__ import annotations

import numpy as np

from millflow.errors import SolverError
from millflow.linalg import SpectralBlocks, contour_funm
from rtd.base import survival_of
from rtd.base import survival_error as _survival_error

__all__ = ["decompose", "apply_function", "survival_transform", "survival_error", "segregated", "plug_flow"]

_TARGET = 1e-13


#: Cluster gaps tried for segregated flow, narrowest first (see :func:`decompose`).
SEGREGATED_GAPS = (1e-3, 0.05, 0.2)


def _feasible(blocks: SpectralBlocks) -> bool:
    """Every cluster narrow enough for one Taylor series (half-range <= 0.5 centre)."""
    for idx in blocks.clusters:
        s = blocks.S[idx]
        if s.max() - s.min() > 0.5 * (s.max() + s.min()):
            return False
    return True


def decompose(S, b, feed=None):
    """Block eigen-decomposition for segregated flow: (blocks, w, estimate).

    Gaps of :data:`SEGREGATED_GAPS` in turn; the first whose cancellation estimate is
    below 1e-13 and whose clusters are narrow enough for :func:`contour_funm` wins,
    else the feasible one with the smallest estimate (never one cluster for all
    rates: a Taylor series about one rate cannot span decades). w = X^-1 feed (None
    without a 1-D feed) and the estimate are returned so that callers reuse them.
    """
    best = None
    for gap in SEGREGATED_GAPS:
        blocks, w, est = SpectralBlocks.decompose(S, b, gap, feed=feed)
        if not _feasible(blocks):
            continue
        if best is None or est < best[2]:
            best = (blocks, w, est)
        if est <= _TARGET:
            break
    if best is None:
        raise SolverError("segregated flow: clusters of close rates are too wide for every cluster gap")
    return best


def apply_function(blocks: SpectralBlocks, fun, V, analytic_left: float = 0.0,
                   block_fun=None, errors: list | None = None, w=None) -> np.ndarray:
    """fun(A) V for V (N,) or (N, m) (SpectralBlocks.apply for several columns).

    Inside clusters ``block_fun(block)`` if given, else :func:`contour_funm` at two
    radii (0.9 and 0.7 of the distance to the singular half plane); their difference,
    mapped back through X, is appended to ``errors`` (a rounding estimate).
    """
    V = np.asarray(V, dtype=float)
    w = blocks.coordinates(V) if w is None else w
    vals = np.asarray(fun(blocks.S))  # a transform of real rates: real (complex only by type)
    vals = vals.real if np.iscomplexobj(vals) else vals.astype(float, copy=False)
    coeff = (vals if V.ndim == 1 else vals[:, np.newaxis]) * w
    delta = np.zeros_like(coeff)
    for idx, block in zip(blocks.clusters, blocks.blocks):
        if block_fun is not None:
            coeff[idx] = block_fun(block) @ w[idx]
        else:
            coeff[idx] = contour_funm(fun, block, analytic_left=analytic_left, radius_factor=0.9, v=w[idx])
            other = contour_funm(fun, block, analytic_left=analytic_left, radius_factor=0.7, v=w[idx])
            delta[idx] = np.abs(coeff[idx] - other)
    if errors is not None:  # delta is zero unless clusters went through contour_funm
        contour = blocks.clusters and block_fun is None and delta.size
        errors.append(float((np.abs(blocks.X) @ delta).max()) if contour else 0.0)
    return blocks.X @ coeff


def survival_transform(model):
    """G(s) = (1 - E_hat(s)) / s, the transform of 1 - F(t); G(0) = mean [s].

    The model's own closed form (``survival_laplace``: no cancellation, every rtd model),
    else the generic quotient, whose error :func:`survival_error` bounds.
    """
    return lambda s: survival_of(model, s)


def survival_error(model, rates) -> np.ndarray:
    """Bound of the absolute error [s] of G at each rate: a few ulp of G for the closed forms,
    eps (1 + E_hat)/s for the generic quotient (:func:`rtd.base.survival_error`)."""
    return np.asarray(_survival_error(model, np.asarray(rates, dtype=float)), dtype=float)


def segregated(S, b, feed, model, *, holdup: bool = True, blocks: SpectralBlocks | None = None):
    """Product, hold-up per unit feed rate [s] and error estimate by segregated flow.

    feed may be (N,) or (N, m); ``blocks`` a decomposition of (S, b) to reuse.
    Returns (product, holdup or None, error_estimate, info); info["blocks"] is the
    decomposition used.
    """
    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    w = cancel = None
    if blocks is None:
        blocks, w, cancel = decompose(S, b, feed if feed.ndim == 1 else None)
    # the half plane Re s > 0, not the model's own (wider) region of analyticity: there
    # |E_hat(s)| <= E_hat(Re s) <= 1 for every RTD, so the Cauchy integral cannot pick
    # up the huge values near a high-order pole (tanks in series: (1 + s tau/n)^-n)
    left = 0.0
    errors = []
    if w is None:
        w = blocks.coordinates(feed)
    product = apply_function(blocks, model.laplace, feed, left, errors=errors, w=w)
    hold = None
    if holdup:
        hold = apply_function(blocks, survival_transform(model), feed, left, errors=errors, w=w)
        # G's own evaluation error at the separated rates, mapped back through X (the
        # clusters' contour integrals are in errors[-1] already)
        delta = survival_error(model, blocks.S)
        delta = (delta if feed.ndim == 1 else delta[:, np.newaxis]) * np.abs(w)
        errors[-1] += float((np.abs(blocks.X) @ delta).max()) if delta.size else 0.0
        errors[-1] /= max(float(model.mean), 1e-300)  # hold-up error in units of tau
    scale = float(np.abs(feed).sum(axis=0).max()) if feed.size else 0.0
    if cancel is None:
        cancel = blocks.cancellation(feed if feed.ndim == 1 else None)
    error = 4.0 * cancel * max(scale, 1.0) + 8 * np.finfo(float).eps * scale + max(errors, default=0.0)
    info = {**blocks.summary(), "blocks": blocks}
    return _clip(product, error), _clip(hold, error * max(float(model.mean), 1e-300)), float(error), info


def _clip(values, error):
    """Rounding can leave values of true value ~0 at -error; set those to 0 (a mass
    change below the error estimate). Larger negative values are left visible."""
    if values is None:
        return None
    return np.where((values < 0) & (values >= -error), 0.0, values)


def plug_flow(S, b, feed, tau: float, *, holdup: bool = True, blocks: SpectralBlocks | None = None):
    """Plug flow: product exp(K tau) f and hold-up int_0^tau exp(K t) dt f [s].

    Inside clusters both use the accurate Taylor scaling and squaring of the block
    (:func:`millflow.linalg._block_expm`); the integral is the top-right block of
    exp of the augmented matrix [[-B, I], [0, 0]] tau. Returns like :func:`segregated`.
    """
    from millflow.linalg import _block_expm

    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    w = cancel = None
    if blocks is None:  # exp and its integral are exact on any cluster: the core's choice
        blocks, w, cancel = SpectralBlocks.decompose(S, b, feed=feed if feed.ndim == 1 else None)
    if w is None:
        w = blocks.coordinates(feed)

    def expm_block(B):
        return _block_expm(B, np.array([tau]))[0]

    def integral_block(B):
        p = B.shape[0]
        aug = np.zeros((2 * p, 2 * p))
        aug[:p, :p] = B
        aug[:p, p:] = -np.eye(p)
        return _block_expm(aug, np.array([tau]))[0][:p, p:]

    def integral(s):
        s = np.asarray(s, dtype=float)
        x = s * tau
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(x > 1e-8, -np.expm1(-x) / np.where(x > 0, s, 1.0), tau * (1 - 0.5 * x))
        return out

    product = apply_function(blocks, lambda s: np.exp(-np.real(s) * tau), feed, block_fun=expm_block, w=w)
    hold = apply_function(blocks, integral, feed, block_fun=integral_block, w=w) if holdup else None
    scale = float(np.abs(feed).sum(axis=0).max()) if feed.size else 0.0
    if cancel is None:
        cancel = blocks.cancellation(feed if feed.ndim == 1 else None)
    error = 4.0 * cancel * max(scale, 1.0) + 8 * np.finfo(float).eps * scale
    info = {**blocks.summary(), "blocks": blocks}
    return _clip(product, error), _clip(hold, error * tau), float(error), info


def segregated_quadrature(S, b, feed, model, *, holdup: bool = True, tol: float = 1e-10, theta=None):
    """Segregated flow by adaptive quadrature over the residence time:

        product = a f + int_0^inf E(t) exp(K t) f dt,   hold-up = int_0^inf (1 - F(t)) exp(K t) f dt,

    or, with ``theta`` (a callable of the age t [s]: slowing-down in the material's age,
    S(t) = S kappa(t), theta(t) = int_0^t kappa), exp(K theta(t)) in place of exp(K t):
    each particle breaks at the rate of its own age, so the parcel of age t is the batch
    grind at theta(t) (exact without classification for any micromixing).

    a the bypass atom of E at t = 0. exp(K t) f by :meth:`SpectralBlocks.expm_apply`,
    exact on clusters of any width (no division by rate differences), so this is the
    fallback where the eigenbasis of :func:`segregated` cancels. ``scipy.integrate.
    quad_vec`` (max norm) gives the error estimate. feed must be (N,).
    Returns like :func:`segregated`.
    """
    from scipy.integrate import quad_vec

    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    blocks = SpectralBlocks.from_rates(S, b, feed=feed)
    scale = max(float(np.abs(feed).sum()), 1e-300)

    def integrand(t):
        m = blocks.expm_apply(feed, np.array([t if theta is None else float(theta(t))]))[0]
        e = float(np.asarray(model.pdf(t)))
        if not holdup:
            return e * m
        return np.concatenate([e * m, (1.0 - float(np.asarray(model.cdf(t)))) * m])

    mean = float(model.mean)
    total = 0.0
    error = 0.0
    # split at multiples of the mean: the density and exp(K t) f vary on those scales
    edges = [0.0, 0.5 * mean, 2.0 * mean, 8.0 * mean, np.inf]
    for lo, hi in zip(edges[:-1], edges[1:]):
        part, err = quad_vec(integrand, lo, hi, epsabs=tol * scale, epsrel=0.0, norm="max", limit=400)
        total = total + part
        error += float(err)
    n = S.size
    product = total[:n] + float(getattr(model, "atom_at_zero", 0.0)) * feed
    hold = total[n:] if holdup else None
    error += 4.0 * blocks.cancellation(feed) * scale
    info = blocks.summary()
    return _clip(product, error), _clip(hold, error * mean), float(error), info
