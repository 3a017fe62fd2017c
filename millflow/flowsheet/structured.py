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
from millflow.mill.transport import equal_cells

__all__ = ["CellCircuit", "cell_chain", "cell_circuit", "structured_solve"]


def cell_chain(unit, grid, throughput=None, water=None):
    """(M (N, N) cell matrix, n cells, tau [s]) of a mill of n equal well-mixed cells without
    classification at the given (torn) solids throughput and water [kg/s], or None when the
    mill is anything else."""
    if getattr(unit, "type", None) != "mill" or getattr(unit, "kinetic_nonlinear", True) \
            or unit.classification is not None:
        return None
    n = equal_cells(unit.transport, unit.transport_params)
    if n is None:
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


class CellCircuit:
    """The class-by-class system of a linear flowsheet whose mills are cell chains, built.

    Attributes: ``G`` (N, S, S) the diagonal gains of every class (a mill's M_kk^-n, a
    classifier's efficiency), ``Gd`` the same without the mills (for the residual),
    ``src`` (S, N) the constant sources, ``chains`` one (name, M, n, w = 1/diag(M),
    outlet, inlets) per mill, and ``errors`` each mill's error estimate, max |column sums
    of M^-n - 1| (a property of the unit like the column sums of a dense transfer matrix
    P, so computed with the unit data: n transposed triangular solves).
    :meth:`solve` is the linear solve and its residual, nothing else.
    """

    __slots__ = ("N", "G", "Gd", "src", "chains", "errors", "_srcT", "_A", "_Gd", "_kernel_mills", "_module")

    def __init__(self, N, G, Gd, src, chains):
        self.N, self.G, self.Gd, self.src, self.chains = N, G, Gd, src, chains
        # the compiled kernel's inputs, laid out once: M^T, inlet indices, sources class-major
        self._module = _compiled_kernel(None)  # the environment's choice, read when the system is built
        self._kernel_mills = [(M, np.ascontiguousarray(M.T), w, o, np.asarray(ins, dtype=np.int64), n)
                              for (_, M, n, w, o, ins) in chains]
        self._srcT = np.ascontiguousarray(src.T)
        self._A = np.eye(src.shape[0]) - G
        self._Gd = np.ascontiguousarray(Gd)
        self.errors = [_column_sum_error(M, n, self._module) for (_, M, n, *_) in chains]

    def solve(self, kernel=None):
        """(flows (S, N), relative residual, loop amplification), or None when some class's
        loop gain is within ~1e-10 of 1 or the flows are not finite (then the sparse path
        names the loop).

        x_k = (I - G_k)^-1 (s_k + the breakage of coarser classes into the mills' cells),
        class after class, coarsest first (the module's recurrence; compiled in
        millflow/_cells.c, else a numpy loop), by the LU of I - G_k with partial
        pivoting; the loop amplification is 1 / its smallest pivot over the classes
        (1 / (1 - loop gain) for one recycle loop). The residual of every unit's equation
        is then evaluated independently, the mills' outputs re-solved from the solved
        inlets by their n triangular solves.
        """
        N, S_ = self.N, self.src.shape[0]
        module = self._module if kernel is None else _compiled_kernel(kernel)
        if module is not None:
            xT = np.empty((N, S_))
            amplification, resid = module.circuit_solve(self._A, self._Gd, self._srcT, xT, self._kernel_mills, N, S_)
            if not amplification < 1e10:  # a loop gain within ~1e-10 of 1, or flows not finite
                return None
            return xT.T, resid, amplification
        if not np.isfinite(self._A).all():
            return None
        import warnings

        from scipy.linalg import lu_factor

        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")  # a singular class is answered below, by its zero pivot
            pivots = np.array([np.min(np.abs(np.diagonal(lu_factor(a, check_finite=False)[0]))) for a in self._A])
        amplification = float(1.0 / pivots.min()) if pivots.min() > 0 else math.inf
        if not amplification < 1e10:  # the sparse path names the loop that traps a size
            return None
        Ainv = np.linalg.inv(self._A)
        x = _classes_numpy(Ainv, self.src, self.chains, [np.zeros((N, n)) for (_, _, n, *_) in self.chains])
        if not np.isfinite(x).all():
            return None
        # residual of every unit's equation, the mills' through their n triangular solves
        from millflow.mill.cells import _trtrs

        pred = self.src + np.einsum("kos,sk->ok", self.Gd, x)
        for _, M, n, _, o, ins in self.chains:
            y = x[list(ins)].sum(axis=0) if ins else np.zeros(N)
            Mf = np.asfortranarray(M)
            for _ in range(n):
                y = _trtrs(Mf, y, lower=1)[0]
            pred[o] += y
        resid = float(np.max(np.abs(x - pred)) / max(float(np.max(np.abs(self.src))), 1e-300))
        return x, resid, amplification


def _column_sum_error(M, n, module) -> float:
    """max |column sums of M^-n - 1|: the mass defect of a chain of n cells' transfer matrix."""
    if module is not None:
        sums = np.array(module.chain_column_sums(M, n))
    else:
        from millflow.mill.cells import _trtrs

        sums, Mf = np.ones(M.shape[0]), np.asfortranarray(M)
        for _ in range(n):
            sums = _trtrs(Mf, sums, lower=1, trans=1)[0]
    return float(np.max(np.abs(sums - 1.0)))


def _compiled_kernel(choice):
    from millflow import compiled

    return compiled.kernel("cells", choice)


def _classes_numpy(Ainv, src, chains, Ys):
    """The class-by-class recurrence of :meth:`CellCircuit.solve` in numpy (the reference
    and the fallback of ``circuit_classes`` in millflow/_cells.c)."""
    S_, N = src.shape
    x = np.zeros((S_, N))
    srcT = np.ascontiguousarray(src.T)
    for k in range(N):
        rhs = srcT[k].copy()
        consts = []
        for (_, M, n, w, o, _ins), Y in zip(chains, Ys):
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
        for (_, _M, _n, w, _o, ins), Y, cs in zip(chains, Ys, consts):
            inlet = math.fsum([xl[i] for i in ins])
            wk = float(w[k])
            coef, row = 1.0, []
            for c in cs:
                coef *= wk
                row.append(coef * inlet + c)
            Y[k] = row
    return x


def cell_circuit(fs, state=None):
    """(:class:`CellCircuit`, blocks, infos, {mill: tau [s]}) of a linear flowsheet whose every
    block is diagonal except cell-chain mills (their blocks not formed), or None when some
    unit does not fit. ``state`` maps a torn unit to its torn inlet values (as
    :func:`millflow.flowsheet.solve._unit_blocks`)."""
    state = state or {}
    grid = fs.grid
    N = grid.n
    names = fs.stream_names
    S_ = len(names)
    sidx = {n: k for k, n in enumerate(names)}
    G = np.zeros((N, S_, S_))
    Gd = np.zeros((N, S_, S_))
    src = np.zeros((S_, N))
    chains, blocks, infos, taus = [], {}, {}, {}
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        if getattr(unit, "type", None) == "mill":
            t1 = time.perf_counter()
            chain = cell_chain(unit, grid, **state.get(uname, {}))
            if chain is None:
                return None
            M, n, tau = chain
            o = sidx[fs.outlet(uname, unit.ports[0])]
            w = 1.0 / np.diagonal(M)
            for i in ins:
                G[:, o, i] += w ** n
            chains.append((uname, M, n, w, o, tuple(ins)))
            taus[uname] = tau
            infos[uname] = {"runtime_s": time.perf_counter() - t1}
            continue
        blk, inf = unit.blocks(grid, **state.get(uname, {}))
        if any(np.ndim(B) != 1 for B in blk.values()):
            return None
        blocks[uname], infos[uname] = blk, inf
        s = unit.source() if hasattr(unit, "source") else {}
        for port in unit.ports:
            o = sidx[fs.outlet(uname, port)]
            if port in s:
                src[o] += s[port]
            B = blk.get(port)
            if B is None:
                continue
            for i in ins:
                G[:, o, i] += B
                Gd[:, o, i] += B
    return CellCircuit(N, G, Gd, src, tuple(chains)), blocks, infos, taus


def structured_solve(fs, state=None, *, kernel=None):
    """(flows (S, N), solver info, blocks, infos) of a linear flowsheet whose every block is
    diagonal except cell-chain mills; None when some unit does not fit. ``state`` maps a torn
    unit to its torn inlet values (as :func:`millflow.flowsheet.solve._unit_blocks`);
    ``kernel`` as :func:`millflow.compiled.kernel`."""
    t0 = time.perf_counter()
    built = cell_circuit(fs, state)
    if built is None:
        return None
    circuit, blocks, infos, taus = built
    solved = circuit.solve(kernel)
    if solved is None:
        return None
    x, resid, amplification = solved
    state = state or {}
    for (uname, *_), err in zip(circuit.chains, circuit.errors):
        unit, tau = fs.units[uname], taus[uname]
        how = f"millflow.mill.transfer_matrix({_transport(unit, tau)!r})"
        if unit.transport_note:
            how += f" [{unit.transport_note}]"
        infos[uname] = {"method": how, "error_estimate": err, "runtime_s": infos[uname]["runtime_s"],
                        "tau_s": tau, **unit._basis_info()}
        blocks[uname] = _LazyBlocks(unit, fs.grid, state.get(uname, {}))
    info = {"method": "class-by-class forward substitution (mills as chains of triangular cell solves, "
                      "no transfer matrix formed)",
            "n_unknowns": int(x.size), "nnz": None, "relative_residual": resid,
            "loop_amplification": amplification, "runtime_s": time.perf_counter() - t0}
    return x, info, blocks, infos


def _transport(unit, tau):
    from millflow.flowsheet.units import build_transport

    return build_transport(unit.transport, tau, unit.transport_params)
