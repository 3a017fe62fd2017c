"""Starting points of the reconciliation: stream flows derived from what the survey measured.

The reconciliation (:mod:`millflow.survey.reconcile`) is a non-linear least-squares
problem in the component flows; Gauss-Newton from a poor start can stop in a
non-physical minimum (a stream's water going to plus or minus infinity so that its
% solids is "adjusted" to 0). The start is therefore derived from the data by a
linear problem in the stream totals, the classical n-product balance:

- unknowns: the solids flow M_s and (wet) the water W_s of every stream and the water
  a_u added at units;
- each stream's class shape f_sk is fixed at its measured sieve analysis (spread over
  the classes of the common series it does not resolve in proportion to the mean
  shape of the other analyses; the mean shape where it has none);
- rows, weighted by the SD of their residual: the node balances of every size class
  through classifiers, mixers and tanks, sum_in M_s f_sk - sum_out M_s f_sk = 0 (of
  total solids where a stream at the node has no analysis, and across mills); the water
  balances; each measured solids flow, water flow and addition; each % solids c_s as
  c_s W_s - (1 - c_s) M_s = 0 (linear in the unknowns).

The flows then follow from the water meters and the % solids when no solids flow is
measured (a sump's metered water and the % solids either side of it fix the flow
through it), and from the solids meters when they are. The rows that scale with the
flows are weighted at flows first set to the median measured flow, then (three passes)
at the previous solution's flows. Stream flows the
data leave undetermined (the minimum-norm solution puts them at or below 0) start at
the median of the determined ones.
"""
from __future__ import annotations

import numpy as np

__all__ = ["derived_start", "naive_start", "stream_shapes"]


def stream_shapes(st, survey) -> tuple[np.ndarray, np.ndarray]:
    """Per stream, class mass fractions on the live classes (rows sum to 1) and whether the
    stream has an analysis; classes a stream does not resolve share its measured fraction
    in proportion to the mean shape of the analyses that are complete (or equally)."""
    K = st.K
    fr = {}
    for r, s, mask in zip(st.frac_rows, st.frac_stream, st.frac_mask):
        fr.setdefault(int(s), []).append((st.y[r], mask))
    full = [s for s, v in fr.items() if len(v) >= K - 1]
    shape = np.full(K, 1.0 / K)
    if full:
        acc = []
        for s in full:
            f = np.zeros(K)
            for val, mask in fr[s]:
                f[mask > 0] = max(val, 0.0) / mask.sum()
            f[-1] = max(1.0 - f[:-1].sum(), 0.0)
            acc.append(f)
        shape = np.mean(acc, axis=0) + 1e-6
        shape /= shape.sum()
    out = np.tile(shape, (st.S, 1))
    has = np.zeros(st.S, bool)
    for s, rows in fr.items():
        f = shape.copy()
        covered = np.zeros(K, bool)
        for val, mask in rows:
            sel = mask > 0
            f[sel] = max(val, 1e-6) * shape[sel] / shape[sel].sum()
            covered |= sel
        rest = ~covered  # the pan of the stream's own series
        if rest.any():
            f[rest] = max(1.0 - f[covered].sum(), 1e-6) * shape[rest] / max(shape[rest].sum(), 1e-300)
        out[s] = f / f.sum()
        has[s] = True
    return out, has


def _measured(survey, name, key):
    m = survey.streams.get(name)
    return None if m is None else getattr(m, key)


def naive_start(st, survey, scale: float | None = None) -> np.ndarray:
    """Measured flows and fractions where given, one typical flow elsewhere (the median
    measured solids flow, or ``scale``): the start used before the derived one, kept as a
    second start."""
    f, _ = stream_shapes(st, survey)
    measured = [m.solids for m in survey.streams.values() if m.solids]
    typical = scale if scale is not None else (float(np.median(measured)) if measured else 1.0)
    z0 = np.zeros(st.n_z)
    for s, name in enumerate(st.streams):
        M = _measured(survey, name, "solids") or typical
        z0[st.m_index(s)] = M * f[s]
        if st.wet:
            W, c = _measured(survey, name, "water"), _measured(survey, name, "solids_content")
            z0[st.w_index(s)] = W if W is not None else (M * (1 - c) / c if c else M)
    for k, u in enumerate(st.additions):
        v = survey.water_additions[u][0]
        z0[st.a_index(k)] = typical if v is None else v
    return z0


def derived_start(st, survey) -> np.ndarray | None:
    """The start of the module docstring; None when nothing absolute is measured (the
    linear problem is homogeneous: no flow scale)."""
    fs = survey.flowsheet
    f, has = stream_shapes(st, survey)
    S, K, wet = st.S, st.K, st.wet
    nA = len(st.additions) if wet else 0
    n = S + (S + nA if wet else 0)
    iM, iW, iA = (lambda s: s), (lambda s: S + s), (lambda k: 2 * S + k)
    sidx = {name: k for k, name in enumerate(st.streams)}
    err = survey.errors

    def rows(M, W):
        """(row coefficient vector, target, SD of the residual) of every start equation."""
        out = []
        tiny = 1e-6 * max(float(np.median(M)), 1e-3)  # exact relations: far tighter than any SD
        for u, unit in fs.units.items():
            if unit.type in ("feed", "product"):
                continue
            ins = [sidx[s] for s in fs.inlets(u)]
            outs = [sidx[s] for s in fs.outlets(u)]
            both = [(s, 1.0) for s in ins] + [(s, -1.0) for s in outs]
            if unit.type != "mill" and all(has[s] for s, _ in both):
                for k in range(K):
                    a = np.zeros(n)
                    var = 0.0
                    for s, sign in both:
                        a[iM(s)] += sign * f[s, k]
                        var += (M[s] * err.fraction_sd(f[s, k])) ** 2
                    out.append((a, 0.0, max(np.sqrt(var), tiny)))
            else:
                a = np.zeros(n)
                for s, sign in both:
                    a[iM(s)] += sign
                out.append((a, 0.0, tiny))
            if wet:
                a = np.zeros(n)
                for s, sign in both:
                    a[iW(s)] += sign
                if u in st.additions:
                    a[iA(st.additions.index(u))] = 1.0
                out.append((a, 0.0, tiny))
        for name, m in survey.streams.items():
            s = sidx[name]
            if m.solids is not None:
                a = np.zeros(n)
                a[iM(s)] = 1.0
                out.append((a, m.solids, m.solids_sd or tiny))
            if wet and m.water is not None:
                a = np.zeros(n)
                a[iW(s)] = 1.0
                out.append((a, m.water, m.water_sd or tiny))
            if wet and m.solids_content is not None:
                c = m.solids_content
                a = np.zeros(n)
                a[iW(s)], a[iM(s)] = c, -(1.0 - c)
                out.append((a, 0.0, max(m.solids_content_sd * (M[s] + W[s]), tiny)))
        for k, u in enumerate(st.additions if wet else []):
            v, sd = survey.water_additions[u]
            if v is not None:
                a = np.zeros(n)
                a[iA(k)] = 1.0
                out.append((a, v, sd or tiny))
        return out

    absolute = any(m.solids is not None or (wet and m.water is not None) for m in survey.streams.values()) or (
        wet and any(v is not None for v, _ in survey.water_additions.values()))
    if not absolute:
        return None
    values = [m.solids for m in survey.streams.values() if m.solids] + (
        [m.water for m in survey.streams.values() if m.water] + [v for v, _ in survey.water_additions.values() if v]
        if wet else [])
    typical = float(np.median(values)) if values else 1.0
    M, W = np.full(S, typical), np.full(S, typical)
    x = None
    for _ in range(3):
        R = rows(M, W)
        A = np.array([r[0] / r[2] for r in R])
        b = np.array([r[1] / r[2] for r in R])
        x = np.linalg.lstsq(A, b, rcond=1e-12)[0]
        M = x[:S].copy()
        ok = M > 0
        if not ok.any():
            return None
        M = np.where(ok, np.maximum(M, 0.05 * float(np.median(M[ok]))), float(np.median(M[ok])))
        W = x[S:2 * S].copy() if wet else np.zeros(S)
        if wet:
            okw = W > 0
            W[~okw] = float(np.median(W[okw])) if okw.any() else float(np.median(M))
    z0 = np.zeros(st.n_z)
    for s in range(S):
        z0[st.m_index(s)] = M[s] * f[s]
        if wet:
            z0[st.w_index(s)] = W[s]
    for k in range(nA):
        a = x[iA(k)]
        v = survey.water_additions[st.additions[k]][0]
        z0[st.a_index(k)] = a if a > 0 else (v if v is not None else float(np.median(W)))
    return z0
