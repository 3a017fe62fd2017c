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

__all__ = ["jacobian", "parameter_statistics", "cluster_robust_covariance", "residual_structure",
           "information_criteria", "f_test", "CORR_LIMIT", "SE_RATIO_FLAG"]

CORR_LIMIT = 0.95
_EPS3 = np.finfo(float).eps ** (1.0 / 3.0)


def jacobian(resid_pop, theta, lower, upper, noise: float | None = None):
    """Central-difference Jacobian (n_res, p) of ``resid_pop`` ((P, p) -> (P, n_res)) at theta.

    Step h = noise^(1/3) x max(|theta|, 0.1 x width, 1e-3): the optimum of a central
    difference whose function values carry relative noise ``noise`` (machine epsilon by
    default, exact solves; an adaptive ODE solve's tolerance otherwise, since its error
    is not smooth in the parameters). Where the solve fails at one side of a central
    difference (or at the far point of a one-sided one), that column falls back to the
    first-order difference on the side that was solved; where both fail it stays
    non-finite (the caller sees it).
    """
    theta = np.asarray(theta, dtype=float)
    p = theta.size
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    width = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
    step = _EPS3 if noise is None else float(noise) ** (1.0 / 3.0)
    h = step * np.maximum.reduce([np.abs(theta), 0.1 * width, np.full(p, 1e-3)])
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
    ok = np.isfinite(R).all(axis=1)
    for k in range(p):
        a, b2 = R[1 + 2 * k], R[2 + 2 * k]
        oka, okb = ok[1 + 2 * k], ok[2 + 2 * k]
        if kind[k] == "c":
            if oka and okb:
                J[:, k] = (a - b2) / (2 * h[k])
            else:  # one side's solve failed (a non-linear mill at an extreme): the other side, first order
                J[:, k] = (a - r0) / h[k] if oka else (r0 - b2) / h[k]
        elif kind[k] == "f":
            J[:, k] = (-3 * r0 + 4 * a - b2) / (2 * h[k]) if okb else (a - r0) / h[k]
        else:
            J[:, k] = (3 * r0 - 4 * a + b2) / (2 * h[k]) if okb else (r0 - a) / h[k]
    return J


#: A fit is flagged when the cluster-robust SE exceeds eq. 9's by more than this factor.
SE_RATIO_FLAG = 1.5
#: ... and only from at least this many samples (clusters): with fewer, the sandwich's
#: meat is a sum of a handful of outer products and its ratio to eq. 9 scatters by a
#: factor of ~2 either way even for independent residuals (Cameron and Miller 2015, sec.
#: VI: "few clusters"). A ratio below 1 is never evidence of correlation: positively
#: correlated residuals within a sample inflate the sandwich, they do not shrink it.
ROBUST_MIN_CLUSTERS = 10


def cluster_robust_covariance(J, r, clusters, n_params: int):
    """Sample-clustered sandwich covariance (CR1) of least-squares estimates.

    C = c (J^T J)^-1 [sum_g (J_g^T r_g)(J_g^T r_g)^T] (J^T J)^-1, c = G/(G-1) (n-1)/(n-p),
    G clusters (samples: the residuals of one sieve curve are correlated with each other,
    not with other samples). Valid whatever the within-sample correlation; needs G well
    above 1. Returns (C, G). Liang and Zeger (1986); Cameron and Miller (2015).
    """
    J = np.asarray(J, float)
    r = np.asarray(r, float)
    ids = np.asarray(clusters)
    uniq = np.unique(ids)
    G, n = uniq.size, r.size
    bread = np.linalg.pinv(J.T @ J)
    scores = np.array([J[ids == g].T @ r[ids == g] for g in uniq])
    meat = scores.T @ scores
    c = (G / (G - 1.0)) * ((n - 1.0) / (n - n_params)) if G > 1 and n > n_params else math.nan
    return c * bread @ meat @ bread, G


def residual_structure(r, clusters) -> dict:
    """Structure of the residuals: lag-1 autocorrelation and a runs test, per sample.

    Per sample: lag-1 autocorrelation of the residuals and a Wald-Wolfowitz runs test of
    their signs (few runs: same-sign stretches the model misses). Summary: the mean lag-1
    autocorrelation and the fraction of samples whose runs test rejects at p < 0.05.
    """
    r = np.asarray(r, float)
    ids = np.asarray(clusters)
    per = []
    for g in np.unique(ids):
        e = r[ids == g]
        ec = e - e.mean()
        den = float(ec @ ec)
        lag1 = float(ec[1:] @ ec[:-1]) / den if den > 0 and e.size > 2 else math.nan
        s = e[e != 0] > 0
        n1, n2 = int(s.sum()), int((~s).sum())
        runs = 1 + int(np.count_nonzero(s[1:] != s[:-1])) if s.size else 0
        n = n1 + n2
        if n1 and n2 and n > 2:
            mu = 1 + 2.0 * n1 * n2 / n
            var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n * n * (n - 1))
            p = float(stats.norm.cdf((runs - mu) / math.sqrt(var))) if var > 0 else math.nan  # one-sided: few runs
        else:
            p = math.nan
        per.append({"sample": int(g), "n": int(e.size), "lag1": lag1, "runs": runs, "runs_p": p})
    lag = [d["lag1"] for d in per if math.isfinite(d["lag1"])]
    tested = [d for d in per if math.isfinite(d["runs_p"])]
    return {"mean_lag1": float(np.mean(lag)) if lag else math.nan,
            "runs_reject_fraction": (sum(d["runs_p"] < 0.05 for d in tested) / len(tested)) if tested else math.nan,
            "per_sample": per}


def parameter_statistics(names, theta, J, ssr, n_data, lower=None, upper=None, residuals=None, clusters=None):
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
    C9, se9 = C, se
    # Eq. 9 assumes independent residuals; neighbouring sieves of one cumulative curve are
    # not. The default covariance keeps eq. 9's correlations and raises each SE to the
    # sample-clustered sandwich SE where that is larger: D C9 D, D = max(1, se_cl/se_9).
    robust, G, ratio = None, 0, np.ones(p)
    if residuals is not None and clusters is not None and not singular and dof > 0:
        C_cl, G = cluster_robust_covariance(J, residuals, clusters, p)
        if G >= 3 and np.all(np.isfinite(C_cl)):
            se_cl = np.sqrt(np.clip(np.diag(C_cl), 0.0, None))
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(se9 > 0, se_cl / se9, 1.0)
            D = np.maximum(1.0, ratio)
            C = C9 * np.outer(D, D)
            se = se9 * D
            robust = {"se": se_cl, "ratio": ratio, "clusters": G}
    kind = ("eq. 9 with each SE raised to the sample-clustered sandwich (CR1) SE where larger"
            if robust is not None else "eq. 9")
    # intervals and p: t with the residual dof, or G - 1 where the cluster-robust SE was used
    dof_t = min(dof, G - 1) if robust is not None and np.any(ratio > 1) else dof
    tq = float(stats.t.ppf(0.975, dof_t)) if dof_t > 0 else math.nan
    params, pairs = {}, []
    for k, name in enumerate(names):
        v, s = float(theta[k]), float(se[k])
        is_log = name.startswith("ln_")
        # ln_X: X = exp(ln_X) > 0 by construction, so no null hypothesis is meaningful
        # (ln X = 0 would test X = 1 in whatever units): t and p are omitted (None)
        tval = None if is_log else (v / s if s > 0 else math.inf)
        pval = None if is_log else (float(2 * stats.t.sf(abs(tval), dof_t)) if dof_t > 0 else math.nan)
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
        flags = list(reasons)
        if robust is not None and G >= ROBUST_MIN_CLUSTERS and ratio[k] > SE_RATIO_FLAG:
            flags.append(f"cluster-robust SE {ratio[k]:.2g} x eq. 9 from {G} samples "
                         "(residuals correlated within samples)")
        params[name] = {"value": v, "se": s, "t": None if tval is None else float(tval), "p_value": pval,
                        "ci95": ci, "significant": not reasons, "reasons": reasons, "at_bound": at_bound,
                        "se_eq9": float(se9[k]), "se_cluster": None if robust is None else float(robust["se"][k]),
                        "covariance": kind, "flags": flags}
    for a in range(p):
        for b in range(a + 1, p):
            if np.isfinite(corr[a, b]) and abs(corr[a, b]) > CORR_LIMIT:
                pairs.append((names[a], names[b], float(corr[a, b])))
    out = {"params": params, "covariance": C, "covariance_eq9": C9, "covariance_kind": kind,
           "correlation": corr, "condition_number": cond_scaled,
           "condition_number_raw": cond_raw, "ser": math.sqrt(ser2) if dof > 0 else math.nan, "dof": dof,
           "dof_intervals": dof_t, "correlated_pairs": pairs, "singular": singular,
           "clusters": G, "se_ratio_max": float(np.max(ratio)) if robust is not None else math.nan,
           "se_ratio_flag": bool(robust is not None and G >= ROBUST_MIN_CLUSTERS and np.any(ratio > SE_RATIO_FLAG))}
    if residuals is not None and clusters is not None:
        out["residuals"] = residual_structure(residuals, clusters)
    return out


def information_criteria(ssr: float, n: int, p: int) -> dict:
    """AIC, AICc and BIC of a least-squares fit with Gaussian errors.

    AIC and BIC of a least-squares fit with Gaussian errors (constants dropped):
    AIC = n ln(SSR/n) + 2p, BIC = n ln(SSR/n) + p ln n; AICc adds 2p(p+1)/(n-p-1).
    """
    base = n * math.log(max(ssr, 1e-300) / n)
    aicc = base + 2 * p + (2 * p * (p + 1) / (n - p - 1) if n - p - 1 > 0 else math.inf)
    return {"aic": base + 2 * p, "aicc": aicc, "bic": base + p * math.log(n)}


def f_test(ssr_small: float, p_small: int, ssr_big: float, p_big: int, n: int) -> dict:
    """F test of a nested pair of models.

    F test of a nested pair: does the bigger model reduce SSR more than chance?
    F = ((SSR_s - SSR_b)/(p_b - p_s)) / (SSR_b/(n - p_b)); p from F(p_b - p_s, n - p_b).
    """
    d1, d2 = p_big - p_small, n - p_big
    if d1 <= 0 or d2 <= 0:
        return {"F": math.nan, "p_value": math.nan}
    F = ((ssr_small - ssr_big) / d1) / (ssr_big / d2)
    return {"F": float(F), "p_value": float(stats.f.sf(F, d1, d2))}
