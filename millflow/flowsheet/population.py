"""A linear flowsheet solved for a population of mill breakage parameter sets at once.

Monte Carlo bands and finite-difference Jacobians of a study (scale-up) solve the same
flowsheet for hundreds of parameter sets that differ only in the mills' S and b and in
their torn throughputs. For flowsheets of the kind :mod:`millflow.flowsheet.structured`
solves (mills of equal well-mixed cells without classification, every other unit a
diagonal block), the class-by-class substitution of that module is vectorised here over
the members: in class k the breakage from coarser classes into every cell of every member
is a batched product, each member's S x S system (I - G_k) x_k = s_k is solved with its
own inverse, and the cells' outputs follow. The arithmetic per member is that of
:func:`~millflow.flowsheet.structured.structured_solve`; any other flowsheet gives None
(the caller then solves member by member with :func:`millflow.flowsheet.solve.solve_at`).
"""
from __future__ import annotations

import numpy as np

from millflow.mill.transport import equal_cells

__all__ = ["solve_population"]


def _chain_cells(unit) -> int | None:
    """Number of equal well-mixed cells of a mill without classification or kinetics, else None."""
    if getattr(unit, "kinetic_nonlinear", True) or unit.classification is not None:
        return None
    return equal_cells(unit.transport, unit.transport_params)


def solve_population(fs, forms: dict, throughput: dict | None = None):
    """Flows (P, n_streams, N) [kg/s] for P members, or None when the flowsheet does not fit.

    Parameters
    ----------
    fs : Flowsheet, linear once its torn units are held at ``throughput``.
    forms : mill name -> (S (P, N), b (P, N, N)): each mill's rates and fractional breakage
        on ``fs.grid`` per member, as the unit puts its own forms there (rates per time [1/s],
        or per energy [kg/J] for a mill whose rates are per energy: S = S^E P / H then).
    throughput : torn unit -> (P,) solids throughput [kg/s] per member (mills given by their
        hold-up, tau = H / throughput); a mill with a fixed tau takes none.

    Per class k the S x S system (I - G_k) x_k = s_k differs between members only by the
    mills' gains w_k^n (w_k = 1 / (1 + tau S_k / n)) on their (outlet, inlet) pairs: it is
    solved from the member-free inverse of I - G0_k (every other unit) by the Woodbury
    identity, one r x r system per member (r the number of mill inlets).
    """
    throughput = throughput or {}
    grid = fs.grid
    N = grid.n
    names = fs.stream_names
    n_s = len(names)
    sidx = {n: k for k, n in enumerate(names)}
    P = None
    chains, diag = {}, {}
    for uname, unit in fs.units.items():
        if getattr(unit, "type", None) == "mill":
            n = _chain_cells(unit)
            if n is None or uname not in forms or getattr(unit, "needs_water", False):
                return None
            S, b = (np.asarray(v, dtype=float) for v in forms[uname])
            P = S.shape[0] if P is None else P
            F = throughput.get(uname)
            if unit.tau is not None and unit.breakage_basis != "energy":
                tau = np.full(S.shape[0], float(unit.tau))
            elif F is None:
                return None
            else:
                F = np.asarray(F, dtype=float)
                tau = float(unit.holdup) / F if unit.tau is None else np.full(S.shape[0], float(unit.tau))
            if unit.breakage_basis == "energy":  # S = S^E P / H, H = tau F
                S = S * (float(unit.power) / (tau * F))[:, None]
            s = S * (tau / n)[:, None]  # cell matrix M = I - (tau/n)(b - I) diag(S): M_kj = -b_kj s_j, M_kk = 1 + s_k
            chains[uname] = (s, b, n)
            continue
        if uname in throughput or getattr(unit, "needs_recovery", False) or getattr(unit, "nonlinear", False):
            return None
        blk, _ = unit.blocks(grid)
        if any(np.ndim(B) != 1 for B in blk.values()):
            return None
        diag[uname] = blk
    if P is None:
        return None
    G0 = np.zeros((N, n_s, n_s))
    src = np.zeros((n_s, N))
    mills, pairs = [], []
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        if uname in chains:
            s, b, n = chains[uname]
            o = sidx[fs.outlet(uname, unit.ports[0])]
            w = 1.0 / (1.0 + s)  # (P, N): 1 / M_kk
            for i in ins:
                pairs.append((o, i, w ** n))
            mills.append((s, b, n, w, o, ins, np.zeros((P, N, n))))
            continue
        so = unit.source() if hasattr(unit, "source") else {}
        for port in unit.ports:
            o = sidx[fs.outlet(uname, port)]
            if port in so:
                src[o] += so[port]
            B = diag[uname].get(port)
            if B is None:
                continue
            for i in ins:
                G0[:, o, i] += np.asarray(B, dtype=float)
    try:
        A0inv = np.linalg.inv(np.eye(n_s) - G0)  # (N, S, S): the flowsheet without its mills' gains
    except np.linalg.LinAlgError:
        return None  # a loop without a mill traps a size: the member-by-member path names it
    r = len(pairs)
    U = np.zeros((n_s, r))
    V = np.zeros((r, n_s))
    for q, (o, i, _) in enumerate(pairs):
        U[o, q], V[q, i] = 1.0, 1.0
    gains = np.stack([g for _, _, g in pairs], axis=-1) if r else np.zeros((P, N, 0))  # (P, N, r)
    eye_r = np.eye(r)
    x = np.zeros((P, n_s, N))
    with np.errstate(all="ignore"):
        for k in range(N):
            rhs = np.broadcast_to(src[:, k], (P, n_s)).copy()
            consts = []
            for _s, b, n, w, o, _ins, Q in mills:
                wk = w[:, k]
                # h_c = sum_j M_kj y_c[j] = -sum_{j<k} b_kj s_j y_c[j]; Q holds s_j y_c[j]
                h = -np.einsum("pj,pjc->pc", b[:, k, :k], Q[:, :k, :]) if k else np.zeros((P, n))
                c = np.zeros(P)
                cs = []
                for cell in range(n):  # y_c = (y_{c-1} - h_c) / M_kk: the constant part
                    c = (c - h[:, cell]) * wk
                    cs.append(c)
                rhs[:, o] += c
                consts.append(cs)
            z = rhs @ A0inv[k].T  # A0^-1 rhs, (P, S)
            if r:  # Woodbury: (A0 - U D V)^-1 = A0^-1 + A0^-1 U D (I - V A0^-1 U D)^-1 V A0^-1
                D = gains[:, k, :]  # (P, r)
                W = A0inv[k] @ U  # (S, r)
                K = eye_r - (V @ W)[None] * D[:, None, :]  # (P, r, r)
                y = np.linalg.solve(K, (z @ V.T)[..., None])[..., 0]  # (P, r)
                z = z + (y * D) @ W.T
            x[:, :, k] = z
            for (s, _b, n, w, _o, ins, Q), cs in zip(mills, consts):
                wk = w[:, k]
                inlet = z[:, ins].sum(axis=1)
                coef = np.ones(P)
                for cell in range(n):
                    coef = coef * wk
                    Q[:, k, cell] = s[:, k] * (coef * inlet + cs[cell])
    if not np.all(np.isfinite(x)):
        bad = ~np.all(np.isfinite(x), axis=(1, 2))
        x[bad] = np.nan
    return x
