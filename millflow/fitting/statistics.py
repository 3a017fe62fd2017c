"""Parameter statistics of a least-squares fit (eq. 9, Principle V) and model discrimination.

C = SER^2 (J^T J)^-1 with J the Jacobian of the weighted residuals at the estimate,
SER^2 = SSR / (n_data - n_params). J is computed by central finite differences of the
exact forward model, all 2p perturbed vectors in one vectorised evaluation, with a
step per parameter h_k = eps^(1/3) max(|p_k|, 0.1 (max_k - min_k), 1e-3) (the
step that balances truncation O(h^2) against rounding O(eps/h)); where a bound is
closer than h the difference is one-sided (second order, three points).

Significance: a parameter is flagged ``not significant`` when its 95 % interval
contains zero or its SEP exceeds half its value. For log-parameters (``ln_X``) the
question is whether the positive quantity X = exp(ln_X) is determined: its relative
standard error is SEP(ln_X), so ln_X is flagged when SEP(ln_X) > 0.5, and its t and p
values test X = 0 with t = X / SE(X) = 1 / SEP(ln_X). Pairs with |correlation| > 0.95
are flagged as not separately identifiable.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

__all__ = ["jacobian", "parameter_statistics", "information_criteria", "f_test", "CORR_LIMIT"]

CORR_LIMIT = 0.95
_EPS3 = np.finfo(float).eps ** (1.0 / 3.0)


def jacobian(resid_pop, theta, lower, upper):
    """Central-difference Jacobian (n_res, p) of ``resid_pop`` ((P, p) -> (P, n_res)) at theta."""
    theta = np.asarray(theta, dtype=float)
    p = theta.size
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    width = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
    h = _EPS3 * np.maximum.reduce([np.abs(theta), 0.1 * width, np.full(p, 1e-3)])
    pts, kind = [theta], []
    for k in range(p):
        e = np.zeros(p)
        e[k] = h[k]
        if theta[k] - h[k] >= lower[k] and theta[k] + h[k] <= upper[k]:
            pts += [theta + e, theta - e]
            kind.append("c")
        elif theta[k] + 2 * h[k] <= upper[k]:
            pts += [theta + e, theta + 2 * e]
            kind.append("f")
        else:
            pts += [theta - e, theta - 2 * e]
            kind.append("b")
    R = resid_pop(np.array(pts))
    r0 = R[0]
    J = np.empty((r0.size, p))
    for k in range(p):
        a, b2 = R[1 + 2 * k], R[2 + 2 * k]
        if kind[k] == "c":
            J[:, k] = (a - b2) / (2 * h[k])
        elif kind[k] == "f":
            J[:, k] = (-3 * r0 + 4 * a - b2) / (2 * h[k])
        else:
            J[:, k] = (3 * r0 - 4 * a + b2) / (2 * h[k])
    return J


def parameter_statistics(names, theta, J, ssr, n_data, lower=None, upper=None):
    """Eq. 9 statistics of the varying parameters.

    Returns a dict with ``params`` (name -> value, se, t, p_value, ci95, significant,
    reasons, at_bound), ``covariance``, ``correlation``, ``condition_number`` (of
    J^T J after scaling its columns to unit norm: the identifiability measure that
    does not depend on parameter units), ``condition_number_raw``, ``ser``, ``dof``
    and ``correlated_pairs``.
    """
    theta = np.asarray(theta, float)
    p = theta.size
    dof = n_data - p
    ser2 = ssr / dof if dof > 0 else math.nan
    JTJ = J.T @ J
    scale = np.sqrt(np.diag(JTJ))
    scale[scale == 0] = 1.0
    Js = JTJ / np.outer(scale, scale)
    sv = np.linalg.svd(Js, compute_uv=False)
    cond_scaled = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    svr = np.linalg.svd(JTJ, compute_uv=False)
    cond_raw = float(svr[0] / svr[-1]) if svr[-1] > 0 else math.inf
    try:
        inv = np.linalg.inv(Js) / np.outer(scale, scale)
        singular = not np.isfinite(inv).all() or cond_scaled > 1e14
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(JTJ)
        singular = True
    C = ser2 * inv
    se = np.sqrt(np.clip(np.diag(C), 0.0, None))
    if singular:
        se = np.full(p, math.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = C / np.outer(se, se)
    tq = float(stats.t.ppf(0.975, dof)) if dof > 0 else math.nan
    params, pairs = {}, []
    for k, name in enumerate(names):
        v, s = float(theta[k]), float(se[k])
        is_log = name.startswith("ln_")
        tval = (1.0 / s if s > 0 else math.inf) if is_log else (v / s if s > 0 else math.inf)
        pval = float(2 * stats.t.sf(abs(tval), dof)) if dof > 0 else math.nan
        ci = [v - tq * s, v + tq * s]
        reasons = []
        if is_log:
            if not s <= 0.5:
                reasons.append("relative SEP of exp(value) > 0.5")
        else:
            if ci[0] <= 0 <= ci[1]:
                reasons.append("95% interval includes 0")
            if not s <= 0.5 * abs(v):
                reasons.append("SEP > |value|/2")
        at_bound = bool(lower is not None
                        and (np.isclose(v, lower[k], atol=1e-8) or np.isclose(v, upper[k], atol=1e-8)))
        if at_bound:
            reasons.append("at a bound (statistics not valid there)")
        params[name] = {"value": v, "se": s, "t": float(tval), "p_value": pval, "ci95": ci,
                        "significant": not reasons, "reasons": reasons, "at_bound": at_bound}
    for a in range(p):
        for b in range(a + 1, p):
            if np.isfinite(corr[a, b]) and abs(corr[a, b]) > CORR_LIMIT:
                pairs.append((names[a], names[b], float(corr[a, b])))
    return {"params": params, "covariance": C, "correlation": corr, "condition_number": cond_scaled,
            "condition_number_raw": cond_raw, "ser": math.sqrt(ser2) if dof > 0 else math.nan, "dof": dof,
            "correlated_pairs": pairs, "singular": singular}


def information_criteria(ssr: float, n: int, p: int) -> dict:
    """AIC and BIC of a least-squares fit with Gaussian errors (constants dropped):
    AIC = n ln(SSR/n) + 2p, BIC = n ln(SSR/n) + p ln n; AICc adds 2p(p+1)/(n-p-1)."""
    base = n * math.log(max(ssr, 1e-300) / n)
    aicc = base + 2 * p + (2 * p * (p + 1) / (n - p - 1) if n - p - 1 > 0 else math.inf)
    return {"aic": base + 2 * p, "aicc": aicc, "bic": base + p * math.log(n)}


def f_test(ssr_small: float, p_small: int, ssr_big: float, p_big: int, n: int) -> dict:
    """F test of a nested pair: does the bigger model reduce SSR more than chance?
    F = ((SSR_s - SSR_b)/(p_b - p_s)) / (SSR_b/(n - p_b)); p from F(p_b - p_s, n - p_b)."""
    d1, d2 = p_big - p_small, n - p_big
    if d1 <= 0 or d2 <= 0:
        return {"F": math.nan, "p_value": math.nan}
    F = ((ssr_small - ssr_big) / d1) / (ssr_big / d2)
    return {"F": float(F), "p_value": float(stats.f.sf(F, d1, d2))}
