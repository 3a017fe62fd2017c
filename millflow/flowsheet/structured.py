"""Linear flowsheets whose mills are chains of equal well-mixed cells, solved class by class
without forming any mill's N x N transfer matrix.

A mill of n equal well-mixed cells (perfect mixing: n = 1; tanks in series with integer n,
no classification) sends its feed through n triangular solves with one cell matrix
M = I - (tau / n) (b - I) diag(S) (:func:`millflow.mill.cells.solve_cells`); its transfer
matrix P = M^-n costs O(n N^3) to form. Ordered size-major, the flowsheet is block lower
triangular (:mod:`millflow.flowsheet.solve`), so it can be solved coarse class first: in
class k the breakage from coarser classes into each cell, h_c = M[k, :k] y_c[:k], is known,
every cell's output is affine in the mill's inlet (y_c = y_{c-1} / M_kk - h_c / M_kk), and
the S x S system (I - G_k) x_k = s_k + (those constants) gives the class-k flows of every
stream. Cost O(n N^2) arithmetic plus O(N) small steps, memory O(n N) per mill: the cells'
outputs are the same triangular substitution as the dense path, summed in another order.
Everything else (applicability, diagnostics) is decided before; any other flowsheet takes
the sparse LU of :func:`millflow.flowsheet.solve.assemble`.
"""
from __future__ import annotations

import math
import time
from collections.abc import Mapping

import numpy as np

from millflow.linalg import breakage_matrix

__all__ = ["cell_chain", "structured_solve"]


def cell_chain(unit, grid, throughput=None, water=None):
    """(M (N, N) cell matrix, n cells, tau [s]) of a mill of n equal well-mixed cells without
    classification at the given (torn) solids throughput and water [kg/s], or None when the
    mill is anything else."""
    if getattr(unit, "type", None) != "mill" or getattr(unit, "kinetic_nonlinear", True) \
            or unit.classification is not None:
        return None
    params = dict(unit.transport_params)
    if unit.transport == "perfect_mixing" and not params:
        n = 1
    elif unit.transport == "tanks_in_series" and set(params) == {"n"} \
            and float(params["n"]).is_integer() and params["n"] >= 1:
        n = int(params["n"])
    else:
        return None
    tau = unit.residence_time(throughput, water)
    S, b = unit.breakage_functions(grid, tau, throughput)
    M = np.eye(S.size) - breakage_matrix(S, b) * (tau / n)
    return M, n, tau


class _LazyBlocks(Mapping):
    """A mill's blocks ({"out": P}) built on first use (reports read only classifiers' blocks)."""

    def __init__(self, unit, grid, state):
        self._unit, self._grid, self._state, self._blocks = unit, grid, state, None

    def _get(self):
        if self._blocks is None:
            self._blocks = self._unit.blocks(self._grid, **self._state)[0]
        return self._blocks

    def __getitem__(self, key):
        return self._get()[key]

    def __iter__(self):
        return iter(("out",))

    def __len__(self):
        return 1


def structured_solve(fs, state=None):
    """(flows (S, N), solver info, blocks, infos) of a linear flowsheet whose every block is
    diagonal except cell-chain mills; None when some unit does not fit. ``state`` maps a torn
    unit to its torn inlet values (as :func:`millflow.flowsheet.solve._unit_blocks`)."""
    state = state or {}
    t0 = time.perf_counter()
    grid = fs.grid
    N = grid.n
    names = fs.stream_names
    S_ = len(names)
    sidx = {n: k for k, n in enumerate(names)}
    chains, blocks, infos = {}, {}, {}
    for uname, unit in fs.units.items():
        if getattr(unit, "type", None) == "mill":
            t1 = time.perf_counter()
            chain = cell_chain(unit, grid, **state.get(uname, {}))
            if chain is None:
                return None
            chains[uname] = chain
            infos[uname] = {"runtime_s": time.perf_counter() - t1}
            continue
        blk, inf = unit.blocks(grid, **state.get(uname, {}))
        if any(np.ndim(B) != 1 for B in blk.values()):
            return None
        blocks[uname], infos[uname] = blk, inf
    # diagonal gains of every class (mills: M_kk^-n) and constant sources
    G = np.zeros((N, S_, S_))
    src = np.zeros((S_, N))
    mills = []
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        if uname in chains:
            M, n, tau = chains[uname]
            o = sidx[fs.outlet(uname, unit.ports[0])]
            w = 1.0 / np.diagonal(M)
            for i in ins:
                G[:, o, i] += w ** n
            mills.append((uname, M, n, w, o, ins, np.zeros((N, n))))  # Y[k, c]: cell c's output
            continue
        s = unit.source() if hasattr(unit, "source") else {}
        for port in unit.ports:
            o = sidx[fs.outlet(uname, port)]
            if port in s:
                src[o] += s[port]
            B = blocks[uname].get(port)
            if B is None:
                continue
            for i in ins:
                G[:, o, i] += np.asarray(B, dtype=float)
    try:
        Ainv = np.linalg.inv(np.eye(S_)[None] - G)
    except np.linalg.LinAlgError:
        return None  # the sparse path names the loop that traps a size
    amplification = float(np.max(np.abs(Ainv))) if np.all(np.isfinite(Ainv)) else math.inf
    if not amplification < 1e10:  # a loop gain within ~1e-10 of 1 (the sparse path's pivot test)
        return None
    x = np.zeros((S_, N))
    srcT = np.ascontiguousarray(src.T)
    for k in range(N):
        rhs = srcT[k].copy()
        consts = []
        for _, M, n, w, o, _ins, Y in mills:
            wk = float(w[k])
            c, cs = 0.0, []
            if k:
                for hc in (M[k, :k] @ Y[:k]).tolist():  # y_c = (y_{c-1} - h_c) / M_kk: constant part
                    c = (c - hc) * wk
                    cs.append(c)
            else:
                cs = [0.0] * n
            rhs[o] += c
            consts.append(cs)
        xk = Ainv[k] @ rhs
        x[:, k] = xk
        xl = xk.tolist()
        for (_, _M, _n, w, _o, ins, Y), cs in zip(mills, consts):
            inlet = math.fsum([xl[i] for i in ins])
            wk = float(w[k])
            coef, row = 1.0, []
            for c in cs:
                coef *= wk
                row.append(coef * inlet + c)
            Y[k] = row
    # residual of every unit's equation, the mills' through their n triangular solves
    from millflow.mill.cells import _trtrs

    pred = np.zeros((S_, N)) + src
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        feed = x[ins].sum(axis=0) if ins else np.zeros(N)
        if uname in chains:
            M, n, tau = chains[uname]
            y, ones = feed, np.ones(N)  # ones: the column sums of P = M^-n (mass balance)
            Mf = np.asfortranarray(M)
            for _ in range(n):
                y = _trtrs(Mf, y, lower=1)[0]
                ones = _trtrs(Mf, ones, lower=1, trans=1)[0]
            pred[sidx[fs.outlet(uname, unit.ports[0])]] += y
            how = f"millflow.mill.transfer_matrix({_transport(unit, tau)!r})"
            if unit.transport_note:
                how += f" [{unit.transport_note}]"
            infos[uname] = {"method": how, "error_estimate": float(np.max(np.abs(ones - 1.0))),
                            "runtime_s": infos[uname]["runtime_s"], "tau_s": tau, **unit._basis_info()}
            blocks[uname] = _LazyBlocks(unit, grid, state.get(uname, {}))
            continue
        for port in unit.ports:
            B = blocks[uname].get(port)
            if B is not None:
                pred[sidx[fs.outlet(uname, port)]] += np.asarray(B, dtype=float) * feed
    if not np.all(np.isfinite(x)):
        return None
    resid = float(np.max(np.abs(x - pred)) / max(float(np.max(np.abs(src))), 1e-300))
    info = {"method": "class-by-class forward substitution (mills as chains of triangular cell solves, "
                      "no transfer matrix formed)",
            "n_unknowns": int(N * S_), "nnz": None, "relative_residual": resid,
            "loop_amplification": amplification, "runtime_s": time.perf_counter() - t0}
    return x, info, blocks, infos


def _transport(unit, tau):
    from millflow.flowsheet.units import build_transport

    return build_transport(unit.transport, tau, unit.transport_params)
