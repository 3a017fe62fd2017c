"""Propagation of the fit's eq. 9 covariance to predicted quantities.

- :func:`delta_method`: Var g = J C J^T with J = dg/dtheta by central differences,
  step h_k = ``rel_step`` * SE_k (1e-3 SE by default: the truncation error is
  O(h^2 g''') ~ 1e-6 of the band width, far above the round-off of the solvers, whose
  roots are converged to ~1e-13 relative).
- :func:`monte_carlo`: draws theta ~ N(theta_hat, C), keeps those inside the physical
  domain of eqs. 6-7 (their number is reported: the distribution is then the normal
  truncated to that domain), evaluates g for each and reports percentiles.
- :func:`compare`: where the two disagree (a non-linear prediction): half-widths and
  centre shift relative to the delta half-width.

A band is the central 95 % interval: delta g_hat -+ 1.96 sd, Monte Carlo 2.5/97.5 %.
"""
from __future__ import annotations

import numpy as np

from millflow.errors import InputError, SolverError

__all__ = ["delta_method", "monte_carlo", "compare", "check_covariance", "Z95"]

Z95 = 1.959963984540054  # standard normal 97.5 % quantile


def check_covariance(C, names=None, where: str = "covariance") -> None:
    """Refuse a covariance that is not one: non-finite, not square, not symmetric (to 1e-8 of
    its scale), or with a negative variance on its diagonal (named by parameter)."""
    C = np.asarray(C, float)
    if C.ndim != 2 or C.shape[0] != C.shape[1] or not np.all(np.isfinite(C)):
        raise InputError(f"{where}: expected a finite square matrix, got shape {C.shape}")
    d = np.diag(C)
    for k in np.flatnonzero(d < 0):
        who = names[k] if names is not None else f"parameter {k + 1}"
        raise InputError(f"{where}: the variance of {who} is {d[k]:.6g} (< 0); a covariance has variances >= 0 "
                         "(a corrupted or hand-edited fit result)")
    scale = max(float(np.max(np.abs(C))), 1e-300)
    if float(np.max(np.abs(C - C.T))) > 1e-8 * scale:
        raise InputError(f"{where}: not symmetric (largest |C - C^T| {float(np.max(np.abs(C - C.T))):.3g})")


def delta_method(g, theta_v, cov, rel_step: float = 1e-3, g_pop=None):
    """g: function of the varying parameters (V,) -> (Q,) values; ``g_pop`` (optional) the
    same for many parameter vectors at once, (M, V) -> (M, Q) (all 2V + 1 points in one
    call). Returns dict value, sd, lo, hi (95 %), jacobian (Q, V), step (V,)."""
    theta_v = np.asarray(theta_v, float)
    C = np.asarray(cov, float)
    check_covariance(C)
    se = np.sqrt(np.diag(C))
    h = rel_step * np.where(se > 0, se, 1.0)
    J = np.empty((0, theta_v.size))
    if g_pop is not None:
        E = np.diag(h)
        Y = np.asarray(g_pop(np.vstack([theta_v[None], theta_v + E, theta_v - E])), float)
        if not np.all(np.isfinite(Y)):
            raise SolverError("delta method: the prediction failed at a finite-difference step of the parameters")
        g0 = Y[0]
        J = ((Y[1:1 + theta_v.size] - Y[1 + theta_v.size:]) / (2 * h[:, None])).T
    else:
        g0 = np.atleast_1d(np.asarray(g(theta_v), float))
        J = np.empty((g0.size, theta_v.size))
        for k in range(theta_v.size):
            e = np.zeros_like(theta_v)
            e[k] = h[k]
            J[:, k] = (np.atleast_1d(g(theta_v + e)) - np.atleast_1d(g(theta_v - e))) / (2 * h[k])
    var = np.einsum("qi,ij,qj->q", J, C, J)
    sd = np.sqrt(np.maximum(var, 0.0))
    return {"value": g0, "sd": sd, "lo": g0 - Z95 * sd, "hi": g0 + Z95 * sd, "jacobian": J, "step": h}


def monte_carlo(g, theta_v, cov, n: int = 1000, seed: int | None = 0, physical=None, skip_errors=(), g_pop=None):
    """Evaluate g on n draws of N(theta_v, cov). ``physical(draws) -> mask`` rejects draws
    outside the parameter domain (replaced by new draws, counted in ``rejected``);
    ``skip_errors``: exception types for draws whose prediction fails (counted in
    ``failed``, e.g. an unreachable target P80 for that draw). ``g_pop`` (optional):
    all draws in one call, (n, V) -> (n, Q), a row with a non-finite value a failed draw.
    Returns dict samples (n_ok, Q), median, mean, sd, lo, hi, rejected, failed."""
    if int(n) != n or n < 10:
        raise InputError(f"n = {n!r}: expected an integer >= 10 Monte Carlo draws")
    rng = np.random.default_rng(seed)
    C = np.asarray(cov, float)
    check_covariance(C)
    # eigen-factorisation tolerates a semi-definite C (perfectly correlated parameters)
    w, V = np.linalg.eigh(C)
    if w.min() < -1e-10 * max(w.max(), 0.0):
        raise InputError(f"covariance is not positive semi-definite (eigenvalue {float(w.min()):.3g})")
    L = V * np.sqrt(np.clip(w, 0.0, None))
    draws, rejected = [], 0
    while sum(len(d) for d in draws) < n:
        z = theta_v + rng.standard_normal((n, theta_v.size)) @ L.T
        ok = physical(z) if physical is not None else np.ones(n, bool)
        rejected += int((~ok).sum())
        draws.append(z[ok])
        if rejected > 20 * n:
            raise SolverError(f"Monte Carlo: {rejected} of the draws fall outside the physical parameter domain; "
                              "the covariance is too wide for a normal approximation")
    draws = np.concatenate(draws)[:n]
    out, failed = [], 0
    if g_pop is not None:
        Y = np.asarray(g_pop(draws), float)
        good = np.all(np.isfinite(Y), axis=1)
        failed = int((~good).sum())
        out = list(Y[good])
    else:
        for z in draws:
            try:
                out.append(np.atleast_1d(np.asarray(g(z), float)))
            except skip_errors:
                failed += 1
    if len(out) < 0.9 * n:
        raise SolverError(f"Monte Carlo: the prediction failed for {failed} of {n} draws")
    Y = np.array(out)
    lo, med, hi = np.percentile(Y, [2.5, 50, 97.5], axis=0)
    return {"samples": Y, "median": med, "mean": Y.mean(0), "sd": Y.std(0, ddof=1), "lo": lo, "hi": hi,
            "rejected": rejected, "failed": failed, "n": int(n)}


def compare(delta: dict, mc: dict, threshold: float = 0.1):
    """Relative disagreement per quantity: |width_MC - width_delta| / width_delta and
    |median_MC - value| / half-width_delta; ``nonlinear`` where either exceeds threshold."""
    wd = delta["hi"] - delta["lo"]
    wm = mc["hi"] - mc["lo"]
    with np.errstate(divide="ignore", invalid="ignore"):
        dw = np.where(wd > 0, np.abs(wm - wd) / wd, 0.0)
        shift = np.where(wd > 0, np.abs(mc["median"] - delta["value"]) / (wd / 2), 0.0)
    return {"width_rel_diff": dw, "centre_shift": shift, "nonlinear": (dw > threshold) | (shift > threshold)}
