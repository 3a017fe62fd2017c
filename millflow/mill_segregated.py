"""Segregated flow: any residence time distribution with first-order breakage.

Each parcel of feed grinds as a batch (eq. 4) for its residence time t, which is
distributed with the exit-age density E(t) of the transport model. For first-order
breakage without classification this is exact (EQUATIONS.md, "segregated flow is
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

import math

import numpy as np

from millflow.errors import SolverError
from millflow.linalg import DEFAULT_CLUSTER_GAP, SpectralBlocks, contour_funm

__all__ = ["decompose", "apply_function", "survival_transform", "segregated", "plug_flow"]

_TARGET = 1e-13


def decompose(S, b, feed=None) -> SpectralBlocks:
    """Block eigen-decomposition with the narrowest cluster gap that is accurate.

    Gaps 0.05 then 0.2 (never one cluster for everything: a Taylor series about the
    mean rate converges only for clusters narrower than the distance to the
    singularities of E_hat); the one with the smaller cancellation estimate wins.
    """
    best = None
    for gap in (DEFAULT_CLUSTER_GAP, 0.2):
        blocks = SpectralBlocks.from_rates(S, b, gap=gap)
        est = blocks.cancellation(feed)
        if best is None or est < best[1]:
            best = (blocks, est)
        if est <= _TARGET:
            break
    return best[0]


def apply_function(blocks: SpectralBlocks, fun, V, analytic_left: float = 0.0,
                   block_fun=None) -> np.ndarray:
    """fun(A) V for V (N,) or (N, m) (SpectralBlocks.apply for several columns).

    Inside clusters ``block_fun(block)`` if given, else :func:`contour_funm`."""
    V = np.asarray(V, dtype=float)
    w = blocks.coordinates(V)
    vals = np.real(np.asarray(fun(blocks.S), dtype=complex))
    coeff = (vals if V.ndim == 1 else vals[:, np.newaxis]) * w
    for idx, block in zip(blocks.clusters, blocks.blocks):
        if block_fun is not None:
            fb = block_fun(block)
        else:
            fb = contour_funm(fun, block, analytic_left=analytic_left)
        coeff[idx] = fb @ w[idx]
    return blocks.X @ coeff


def survival_transform(model):
    """G(s) = (1 - E_hat(s)) / s, the transform of 1 - F(t); G(0) = mean [s]."""
    m1 = float(model.mean)
    m2 = float(model.variance) + m1 * m1

    def G(s):
        s = np.asarray(s)
        small = np.abs(s) * m1 < 1e-5
        safe = np.where(small, 1.0, s)
        out = (1.0 - np.asarray(model.laplace(safe))) / safe
        # two Taylor terms: relative error ~ (|s| m1)^2 < 1e-10 times m3/m1^3
        return np.where(small, m1 - 0.5 * m2 * s, out)

    return G


def analytic_left_of(model) -> float:
    """Left edge of the half plane where the model's transform is analytic (<= 0)."""
    value = getattr(model, "analytic_for_re_s_greater_than", 0.0)
    try:
        value = float(value)
    except (TypeError, ValueError):
        return 0.0
    return min(value, 0.0) if not math.isnan(value) else 0.0


def segregated(S, b, feed, model, *, holdup: bool = True, blocks: SpectralBlocks | None = None):
    """Product, hold-up per unit feed rate [s] and error estimate by segregated flow.

    feed may be (N,) or (N, m); ``blocks`` a decomposition of (S, b) to reuse.
    Returns (product, holdup or None, error_estimate, info); info["blocks"] is the
    decomposition used.
    """
    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    if blocks is None:
        blocks = decompose(S, b, feed if feed.ndim == 1 else None)
    # the half plane Re s > 0, not the model's own (wider) region of analyticity: there
    # |E_hat(s)| <= E_hat(Re s) <= 1 for every RTD, so the Cauchy integral cannot pick
    # up the huge values near a high-order pole (tanks in series: (1 + s tau/n)^-n)
    left = 0.0
    try:
        product = apply_function(blocks, model.laplace, feed, left)
        hold = apply_function(blocks, survival_transform(model), feed, left) if holdup else None
    except SolverError:
        # clusters too wide for the Taylor series: rebuild with the narrowest gap
        blocks = SpectralBlocks.from_rates(S, b, gap=DEFAULT_CLUSTER_GAP)
        product = apply_function(blocks, model.laplace, feed, left)
        hold = apply_function(blocks, survival_transform(model), feed, left) if holdup else None
    scale = float(np.abs(feed).sum(axis=0).max()) if feed.size else 0.0
    cancel = blocks.cancellation(feed if feed.ndim == 1 else None)
    error = 4.0 * cancel * max(scale, 1.0) + 8 * np.finfo(float).eps * scale
    info = {"cluster_gap": float(blocks.gap), "cluster_sizes": [int(c.size) for c in blocks.clusters],
            "blocks": blocks}
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
    if blocks is None:
        blocks = decompose(S, b, feed if feed.ndim == 1 else None)

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

    product = apply_function(blocks, lambda s: np.exp(-np.real(s) * tau), feed, block_fun=expm_block)
    hold = apply_function(blocks, integral, feed, block_fun=integral_block) if holdup else None
    scale = float(np.abs(feed).sum(axis=0).max()) if feed.size else 0.0
    cancel = blocks.cancellation(feed if feed.ndim == 1 else None)
    error = 4.0 * cancel * max(scale, 1.0) + 8 * np.finfo(float).eps * scale
    info = {"cluster_gap": float(blocks.gap), "cluster_sizes": [int(c.size) for c in blocks.clusters],
            "blocks": blocks}
    return _clip(product, error), _clip(hold, error * tau), float(error), info
