"""Steady-state solution of a flowsheet: one linear system, torn only where nonlinear.

Unknowns are the solids mass flows per size class [kg/s] of every stream. A unit with
inlets I_u sends to its outlet stream o the flow x_o = B_o sum_{i in I_u} x_i + s_o
(:mod:`millflow.flowsheet.units`), so the whole flowsheet is (I - T) x = s: one
sparse linear system of (streams x classes) unknowns, assembled block by block and
solved once by sparse LU (recycles need no tear iterations), followed by one step of
iterative refinement. Unknowns are ordered size-major (class 1 of every stream,
then class 2, ...): breakage only moves mass to finer classes, so every block is lower
triangular and the system is block lower triangular with one (streams x streams)
diagonal block G_k per size class k: the gains of that size around the flowsheet.

Material of size k can never leave when I - G_k is singular (a recycle loop whose gain
for that size is 1: e.g. a classifier returning all of a size the mill does not break).
With natural ordering and no off-diagonal pivoting, the pivots of the sparse LU are
those of the blocks I - G_k; a pivot below 1e-10 (or an exactly zero one) flags such a
size, and the smallest singular value of each I - G_k then names the streams and units
of the loop (the support of the null vector) in a :class:`~millflow.errors.SolverError`
instead of returning huge numbers.

Mills with non-linear kinetics (aggregation, population-dependent rates) are
not linear maps of their feed: each is torn on its inlet flow vector. For given inlet
vectors their products are computed (:meth:`~millflow.flowsheet.units.Mill.product_flows`,
Newton on the mill's steady state) and enter the linear system as sources; the inlet
vectors that system returns are iterated to a fixed point by vector Wegstein (default),
substitution or Newton (scipy root, hybr), the change measured as
max |x_new - x| / sum(x_new). A hold-up mill with non-linear kinetics needs no second
tear (its throughput is the sum of its torn inlet vector).

Nonlinear units (a mill given by its hold-up, tau = holdup / throughput) are torn on
their throughput: the linear system is solved for given throughputs, and the
throughputs are updated by Wegstein's method (default), direct substitution or
Newton (scipy.optimize.root, 'hybr') until their relative change is below ``tol``.
The tear report records the method, iterations and residual history.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from millflow.errors import InputError, SolverError
from millflow.flowsheet.water import solve_water
from millflow.threads import limit_blas_threads

__all__ = ["solve", "solve_at", "FlowsheetSolution", "TEAR_METHODS", "assemble"]

#: Smallest singular value of I - G_k below which size k counts as trapped in a loop.
SINGULAR_TOL = 1e-10


@dataclass(frozen=True, eq=False)
class FlowsheetSolution:
    """Stream flows of a solved flowsheet with the diagnostics of every step.

    Attributes
    ----------
    flowsheet : the solved Flowsheet.
    flows : (n_streams, N) solids mass flow per class [kg/s], rows in ``flowsheet.streams`` order.
    units : dict unit -> report (type, method, error_estimate, runtime_s, mass_balance_error, ...).
    solver : dict (method, residual, n_unknowns, runtime_s, tear report).
    runtime_s : total wall time [s].
    """

    flowsheet: object
    flows: np.ndarray
    units: dict
    solver: dict
    runtime_s: float
    unit_blocks: dict = field(default_factory=dict, repr=False)
    water: object = field(default=None, repr=False)

    def water_flow(self, stream: str) -> float:
        """Water [kg/s] of a stream (0 in a dry circuit)."""
        return float(self.water.flows[self.flowsheet.stream_names.index(stream)]) if self.water is not None else 0.0

    def flow(self, stream: str) -> np.ndarray:
        """Solids flows [kg/s] per size class of ``stream``."""
        return self.flows[self.flowsheet.stream_names.index(stream)]


#: Default largest relative mass-balance error of a unit (each closes to ~1e-13 in practice).
MASS_TOL = 1e-9


def _unit_blocks(fs, state):
    """Blocks of every unit, at the torn inlet values of the torn units.

    Blocks of every unit; ``state`` maps a torn unit to its torn inlet values (``throughput``
    [kg/s] of solids, ``water`` [kg/s], ``recovery`` C [-]) passed as keywords.
    """
    blocks, infos = {}, {}
    for name, unit in fs.units.items():
        blocks[name], infos[name] = unit.blocks(fs.grid, **state.get(name, {}))
    return blocks, infos


def assemble(fs, blocks, extra_sources=None):
    """Sparse matrix A = I - T and source vector s of the flowsheet.

    Sparse matrix A = I - T and source vector s (size-major ordering) of the flowsheet;
    ``extra_sources`` (stream -> flows) adds constant sources (torn non-linear mills).
    """
    import scipy.sparse as sp  # imported here: a flowsheet of cell-chain mills never needs it (start-up)

    names = fs.stream_names
    S, N = len(names), fs.grid.n
    sidx = {n: k for k, n in enumerate(names)}
    rows, cols, vals = [], [], []
    rhs = np.zeros(N * S)
    kk = np.arange(N)
    for uname, unit in fs.units.items():
        ins = [sidx[i] for i in fs.inlets(uname)]
        src = unit.source() if hasattr(unit, "source") else {}
        for port in unit.ports:
            o = sidx[fs.outlet(uname, port)]
            if port in src:
                rhs[kk * S + o] += src[port]
            B = blocks[uname].get(port)
            if B is None:
                continue
            B = np.asarray(B, dtype=float)
            if B.ndim == 1:
                for i in ins:
                    rows.append(kk * S + o)
                    cols.append(kk * S + i)
                    vals.append(-B)
            else:
                r, c = np.nonzero(B)
                for i in ins:
                    rows.append(r * S + o)
                    cols.append(c * S + i)
                    vals.append(-B[r, c])
    for stream, flows in (extra_sources or {}).items():
        rhs[kk * S + sidx[stream]] += flows
    rows.append(np.arange(N * S))
    cols.append(np.arange(N * S))
    vals.append(np.ones(N * S))
    A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(N * S, N * S))
    return A, rhs


def _size_gains(fs, blocks) -> np.ndarray:
    """G[k, o, i]: gain of size k from stream i to stream o (diagonal of every block)."""
    names = fs.stream_names
    S, N = len(names), fs.grid.n
    sidx = {n: k for k, n in enumerate(names)}
    G = np.zeros((N, S, S))
    for uname in fs.units:
        ins = [sidx[i] for i in fs.inlets(uname)]
        for port, B in blocks[uname].items():
            B = np.asarray(B, dtype=float)
            d = B if B.ndim == 1 else np.diagonal(B)
            o = sidx[fs.outlet(uname, port)]
            for i in ins:
                G[:, o, i] += d
    return G


def check_exits(fs, blocks) -> None:
    """Raise SolverError naming the loop if some size can never reach a product."""
    G = _size_gains(fs, blocks)
    S = G.shape[1]
    M = np.eye(S)[None] - G
    sv = np.linalg.svd(M, compute_uv=False)
    smin = sv[:, -1] / np.maximum(sv[:, 0], 1.0)
    bad = np.flatnonzero(smin < SINGULAR_TOL)
    if not bad.size:
        return
    k = int(bad[0])
    v = np.linalg.svd(M[k])[2][-1]
    names = fs.stream_names
    loop = [names[j] for j in np.flatnonzero(np.abs(v) > 1e-6 * np.abs(v).max())]
    units = []
    for s in loop:
        for u in (fs.streams[s].source, fs.streams[s].target):
            if u not in units:
                units.append(u)
    raise SolverError(
        f"material of {fs.grid.label(k)} can never leave the loop {' -> '.join(units)} "
        f"(streams {', '.join(loop)}): no route to a product for this size "
        f"({bad.size} size class(es) affected, coarsest shown). Typical causes: a classifier returns all of a "
        "size that the mill does not break (S = 0), or a splitter sends everything back."
    )


def _linear_solve(fs, blocks, extra_sources=None):
    import scipy.sparse.linalg as spla

    t0 = time.perf_counter()
    A, rhs = assemble(fs, blocks, extra_sources)
    S, N = len(fs.streams), fs.grid.n
    try:
        # size-major order makes A block lower triangular with M-matrix diagonal blocks
        # I - G_k: natural ordering without off-diagonal pivoting keeps the factors inside
        # that pattern (no fill), is stable for M-matrices, and its pivots are those of
        # the blocks, so a (nearly) zero pivot flags a size that cannot leave its loop
        lu = spla.splu(A, permc_spec="NATURAL", diag_pivot_thresh=0.0)
    except RuntimeError as exc:  # an exactly zero pivot
        check_exits(fs, blocks)
        raise SolverError(f"flowsheet system is singular ({exc}); a recycle loop has no exit") from exc
    pivots = np.abs(lu.U.diagonal())
    if pivots.min() < SINGULAR_TOL:
        check_exits(fs, blocks)  # names the loop; falls through only if the block check disagrees
        k = int(np.argmin(pivots)) // S
        raise SolverError(f"flowsheet system is singular at {fs.grid.label(k)} (pivot {pivots.min():.3g}); "
                          "a recycle loop has no exit for this size")
    x = lu.solve(rhs)
    r = rhs - A @ x
    x = x + lu.solve(r)  # one step of iterative refinement
    resid = float(np.max(np.abs(rhs - A @ x)) / max(np.max(np.abs(rhs)), 1e-300))
    if not np.all(np.isfinite(x)):
        raise SolverError("flowsheet solution is not finite; check the recycle loops for an exit")
    flows = x.reshape(N, S).T.copy()
    info = {"method": "sparse LU (scipy splu, natural size-major order: block forward substitution), "
                      "1 refinement step",
            "n_unknowns": int(N * S), "nnz": int(A.nnz), "relative_residual": resid,
            "min_pivot": float(pivots.min()), "runtime_s": time.perf_counter() - t0}
    return flows, info


# --------------------------------------------------------------- tear methods
def _relative_change(gx, x) -> float:
    """The largest relative change max |g(x) - x| / |g(x)| (a variable that is and stays 0 counts 0)."""
    d = np.abs(gx - x)
    return float(np.max(np.where(d == 0, 0.0, d / np.where(gx != 0, np.abs(gx), 1e-300))))


def _substitute_negative(x, gx):
    """Plain substitution where the extrapolation would make a torn value negative.

    Torn values (flows, water, recovery) are >= 0: where the extrapolation would make one
    negative, that component takes the plain substitution step.
    """
    return np.where(x < 0, gx, x)


def _substitution(g, x0, tol, maxiter, err=_relative_change):
    x, hist = x0, []
    for it in range(1, maxiter + 1):
        gx = g(x)
        hist.append(err(gx, x))
        x = gx
        if hist[-1] < tol:
            return x, it, hist, True
    return x, maxiter, hist, False


def _wegstein(g, x0, tol, maxiter, qmin=-5.0, qmax=0.0, err=_relative_change, bound=_substitute_negative,
              stall: int | None = None):
    """Wegstein's accelerated substitution, componentwise.

    The factor q is bounded to [qmin, qmax]; ``err`` measures the change, ``bound(x, g(x))`` keeps the
    extrapolated iterate physical. With ``stall`` it gives up (not converged) when the
    smallest change of the last ``stall`` iterations is not 10 x below the smallest before
    them (a caller then switches method).
    """
    x_prev, g_prev = x0, g(x0)
    hist = [err(g_prev, x_prev)]
    if hist[-1] < tol:
        return g_prev, 1, hist, True
    x = g_prev
    for it in range(2, maxiter + 1):
        gx = g(x)
        hist.append(err(gx, x))
        if hist[-1] < tol or _at_rounding_floor(hist):
            return gx, it, hist, True
        if stall and len(hist) > 2 * stall and min(hist[-stall:]) > 0.1 * min(hist[:-stall]):
            return gx, it, hist, False
        dx = x - x_prev
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(dx != 0, (gx - g_prev) / dx, 0.0)
            q = np.where(s != 1, s / (s - 1.0), 0.0)
        q = np.clip(np.nan_to_num(q), qmin, qmax)
        x_prev, g_prev = x, gx
        x = bound(q * x + (1.0 - q) * gx, gx)
    return x, maxiter, hist, False


#: Relative change below which a tear has reached the rounding of its unit solves: three
#: successive changes below it count as converged (the units' own results are accurate to
#: ~1e-15 relative; a tolerance of 1e-13 then cannot always be beaten by 1.6e-13 noise).
ROUNDING_FLOOR = 1e3 * np.finfo(float).eps


def _at_rounding_floor(hist) -> bool:
    return len(hist) >= 3 and max(hist[-3:]) < ROUNDING_FLOOR


def _newton(g, x0, tol, maxiter):
    """Scipy's hybrid Powell on g(x) - x for a torn scalar.

    scipy's hybrid Powell (Newton with a finite-difference Jacobian and trust region) on
    g(x) - x; the answer is the evaluated point with the smallest relative change (hybr may
    wander off a root it has found, e.g. when g does not depend on x).
    """
    from scipy.optimize import root

    hist, best = [], [np.inf, x0]

    def f(x):
        gx = g(x)
        hist.append(_relative_change(gx, x))
        if hist[-1] < best[0]:
            best[:] = [hist[-1], np.array(gx, dtype=float)]
        return (gx - x) / np.where(x0 != 0, np.abs(x0), 1.0)

    root(f, x0, method="hybr", options={"xtol": tol, "maxfev": maxiter})
    ok = bool(hist) and (best[0] < tol or _at_rounding_floor(hist))
    return best[1], len(hist), hist, ok


#: Tear methods for nonlinear units, by name (``method=`` of :func:`solve`).
TEAR_METHODS = {"wegstein": _wegstein, "substitution": _substitution, "newton": _newton}


@limit_blas_threads  # unit matrices and tear Jacobians are small and dense (millflow.threads)
def solve(fs, *, method="wegstein", tol: float = 1e-13, maxiter: int = 200,
          mass_tol: float = MASS_TOL) -> FlowsheetSolution:
    """Solve a flowsheet at steady state.

    Parameters
    ----------
    fs : Flowsheet
    method : str or callable
        Tear method for nonlinear units (key of :data:`TEAR_METHODS` or a callable
        ``(g, x0, tol, maxiter) -> (x, iterations, history, converged)``); unused when
        every unit is linear (then the flowsheet is one linear solve).
    tol : float
        Relative tolerance on torn throughputs [-].
    maxiter : int
        Iteration limit of the tear method.
    mass_tol : float
        Largest relative mass-balance error of any unit; above it SolverError names the
        unit (a solve that creates or loses mass never returns).

    Returns
    -------
    FlowsheetSolution
    """
    t0 = time.perf_counter()
    if isinstance(method, str):
        try:
            tear = TEAR_METHODS[method]
        except KeyError:
            raise InputError(f"method = {method!r}: unknown tear method; valid names: "
                             f"{', '.join(sorted(TEAR_METHODS))}") from None
    elif callable(method):
        tear = method
    else:
        raise InputError(f"method = {method!r}: expected a name ({', '.join(TEAR_METHODS)}) or a callable")

    kin = [n for n, u in fs.units.items() if getattr(u, "kinetic_nonlinear", False)]
    if kin:
        return _solve_kinetic(fs, kin, method, tol, maxiter, t0, mass_tol)
    torn = [n for n, u in fs.units.items() if getattr(u, "nonlinear", False)]
    wet = [n for n in torn if getattr(fs.units[n], "needs_water", False)]
    recov = [n for n in torn if getattr(fs.units[n], "needs_recovery", False)]

    def state_of(flows, infos):
        return np.array(_torn_state(fs, torn, wet, recov, flows, infos))

    def unit_state(X):
        return _torn_unit_state(torn, wet, recov, X)

    tear_report = None
    if torn:
        fresh = sum(u.solids for u in fs.units.values() if u.type == "feed")
        water0 = sum(getattr(u, "water", 0.0) for u in fs.units.values() if u.type == "feed")
        water0 += sum((getattr(fs, "water_added", {}) or {}).values())
        state = {}

        from millflow.flowsheet.structured import structured_solve

        def g(X):
            fast = structured_solve(fs, unit_state(X))  # mills of equal cells: no transfer matrix
            if fast is not None:
                flows, info, blocks, infos = fast
            else:
                blocks, infos = _unit_blocks(fs, unit_state(X))
                flows, info = _linear_solve(fs, blocks)
            state.update(blocks=blocks, infos=infos, flows=flows, info=info)
            return state_of(flows, infos)

        X0 = np.array([float(fresh)] * len(torn) + [float(water0)] * len(wet) + [0.5] * len(recov))
        X, its, hist, ok = tear(g, X0, tol, maxiter)
        fallback = None
        if not ok and tear is _wegstein:
            # Wegstein's secant slopes stall where the torn variables are coupled; Newton
            # (hybrid Powell) on the tear from where Wegstein stopped
            X2, its2, hist2, ok = _newton(g, np.asarray(X, dtype=float), tol, maxiter)
            fallback = (f"wegstein stalled after {its} iterations at a relative change of "
                        f"{hist[-1] if hist else float('nan'):.3g}; newton on the tear from there "
                        f"{'converged' if ok else 'did not converge either'} in {its2} evaluations")
            X, its, hist = X2, its + its2, hist + hist2
        if not ok:
            raise SolverError(f"tear iterations on the throughput of {', '.join(torn)} did not converge "
                              f"({method if isinstance(method, str) else 'custom'}, {its} iterations, "
                              f"last relative change {hist[-1] if hist else float('nan'):.3g})")
        g(np.asarray(X))  # final consistent pass at the converged throughputs
        blocks, infos, flows, lin = state["blocks"], state["infos"], state["flows"], state["info"]
        tear_report = {"method": method if isinstance(method, str) else getattr(method, "__name__", "custom"),
                       "torn_units": torn, "iterations": int(its), "converged": bool(ok),
                       "torn": "solids throughput" + (f" (and water of {', '.join(wet)})" if wet else "")
                               + (f" (and corrected recovery C of {', '.join(recov)})" if recov else ""),
                       "residual_history": [float(h) for h in hist], "tolerance": tol}
        if fallback:
            tear_report["fallback"] = fallback
    else:
        from millflow.flowsheet.structured import structured_solve

        fast = structured_solve(fs)  # mills of equal cells: class by class, no transfer matrix
        if fast is not None:
            flows, lin, blocks, infos = fast
        else:
            blocks, infos = _unit_blocks(fs, {})
            flows, lin = _linear_solve(fs, blocks)

    water = solve_water(fs, flows, infos)
    reports = _unit_reports(fs, flows, infos, mass_tol, water)
    from millflow.flowsheet.cyclone import report_operation
    report_operation(fs, flows, water, reports)  # cyclone numbers, and a warning per quantity out of range
    solver = dict(lin)
    solver["structure"] = ("nonlinear: tear iterations on the inlet flows of " + ", ".join(torn) if torn
                           else "all linear: one linear solve")
    solver["tear"] = tear_report
    return FlowsheetSolution(flowsheet=fs, flows=flows, units=reports, solver=solver,
                             runtime_s=time.perf_counter() - t0, unit_blocks=blocks, water=water)


def solve_at(fs, state: dict) -> tuple[np.ndarray, dict]:
    """Flows (n_streams, N) [kg/s] and solver info with every torn unit held at ``state``.

    ``state`` maps a torn unit to its torn values (``{"throughput": kg/s}``, and ``water``,
    ``recovery`` where they apply), as the tear iterations of :func:`solve` pass them: the
    flowsheet is then linear, one solve (class by class for mills of equal cells, else the
    sparse LU), no iteration. A study that moves a torn value itself (a root in a mill's
    throughput) calls this, reusing the flowsheet and its units (their forms on the grid are
    kept on the units) across its steps.
    """
    from millflow.flowsheet.structured import structured_solve

    fast = structured_solve(fs, state)
    if fast is not None:
        return fast[0], fast[1]
    blocks, _ = _unit_blocks(fs, state)
    return _linear_solve(fs, blocks)


def _vector_err(gx, x):
    return float(np.max(np.abs(gx - x)) / max(float(np.sum(np.abs(gx))), 1e-300))


#: The tears of inlet flow vectors: change relative to the total flow, a flow cut at 0.
_vector_substitution = functools.partial(_substitution, err=_vector_err)
_vector_wegstein = functools.partial(_wegstein, err=_vector_err, bound=lambda x, gx: np.maximum(x, 0.0))


def _vector_newton(g, x0, tol, maxiter, err=_vector_err, scale=None, project=None):
    """Scipy's hybrid Powell on a torn vector.

    scipy's hybrid Powell on (g(x) - x) / scale for a torn vector (flows >= 0); the answer is
    g at the evaluated point with the smallest change ``err``, accepted when that change is
    below ``tol`` (or at the rounding floor of the unit solves), the same test as Wegstein's.
    """
    from scipy.optimize import root

    hist = []
    if scale is None:
        scale = max(float(np.sum(x0)), 1e-300)
    if project is None:
        project = functools.partial(np.maximum, 0.0)  # flows >= 0

    def f(x):
        gx = g(project(x))
        hist.append(err(gx, x))
        return (gx - x) / scale

    best = [np.inf, x0]

    def f_best(x):
        out = f(x)
        if hist[-1] < best[0]:
            best[:] = [hist[-1], x + out * scale]  # g(project(x)) at the best point
        return out

    root(f_best, x0, method="hybr", options={"xtol": tol, "maxfev": maxiter * (x0.size + 1)})
    ok = bool(hist) and (best[0] < tol or _at_rounding_floor(hist))
    return project(best[1]), len(hist), hist, ok


_VECTOR_TEARS = {"wegstein": _vector_wegstein, "substitution": _vector_substitution, "newton": _vector_newton}


def _torn_state(fs, torn, wet, recov, flows, infos, water=None) -> list:
    """Torn variables of the units torn on their throughput.

    Each one's solids throughput, the water of those that need it, the corrected recovery C
    of the predicted cyclones.
    """
    names = fs.stream_names
    out = [math.fsum(math.fsum(flows[names.index(s)]) for s in fs.inlets(u)) for u in torn]
    if wet:
        w = water if water is not None else solve_water(fs, flows, infos)
        out += [w.units[u]["water_in_kg_s"] for u in wet]
    for u in recov:
        inflow = sum(flows[names.index(s)] for s in fs.inlets(u))
        out.append(fs.units[u].corrected_recovery(fs.grid, inflow, infos[u]))
    return out


def _torn_unit_state(torn, wet, recov, X) -> dict:
    """The keywords of each torn unit's ``blocks`` from its torn variables (:func:`_torn_state`'s order)."""
    state = {u: {"throughput": X[k]} for k, u in enumerate(torn)}
    for k, u in enumerate(wet):
        state[u]["water"] = X[len(torn) + k]
    for k, u in enumerate(recov):
        state[u]["recovery"] = X[len(torn) + len(wet) + k]
    return state


#: Iterations without a tenfold gain after which the inlet-vector Wegstein tear counts as
#: stalled and Newton takes over.
TEAR_STALL = 25

#: A tear cannot resolve changes below the error of the unit solves it iterates on: the
#: tolerance in effect is at least this many times the largest error estimate of a
#: non-linear mill's product (relative to its throughput), and the report says so.
TEAR_NOISE_FACTOR = 4.0


_NOTED: set = set()


def _note_once(message: str) -> None:
    """A UserWarning once per process (the grid check's second solve would repeat it)."""
    import warnings

    if message not in _NOTED:
        _NOTED.add(message)
        warnings.warn(message, UserWarning, stacklevel=3)


def _solve_kinetic(fs, kin, method, tol, maxiter, t0, mass_tol=MASS_TOL):
    """Tear the inlet flow vectors of the mills with non-linear kinetics (see the module).

    Units torn on their throughput (a hold-up, slurry-volume or per-energy linear mill, a
    predicted hydrocyclone) join the same tear with their throughput, water and corrected
    recovery, as in the linear path. The torn vector is [inlet flows of each non-linear
    mill, water of those given by slurry volume, the other units' torn variables]; its change
    is the largest of max |dx| / sum(x) over the flows and the relative change of each
    scalar. Wegstein (default) falls back to Newton on the tear from where it stalled.
    """
    if not isinstance(method, str) or method not in _VECTOR_TEARS:
        raise InputError(f"method = {method!r}: the inlet-vector tear of non-linear mills takes one of "
                         f"{', '.join(_VECTOR_TEARS)}")
    names = fs.stream_names
    N = fs.grid.n
    torn = [n for n, u in fs.units.items() if getattr(u, "nonlinear", False) and n not in kin]
    wet_o = [n for n in torn if getattr(fs.units[n], "needs_water", False)]
    recov = [n for n in torn if getattr(fs.units[n], "needs_recovery", False)]
    blocks, infos = {}, {}
    for name, unit in fs.units.items():
        if name in kin:
            blocks[name], infos[name] = {}, {}
        elif name not in torn:
            blocks[name], infos[name] = unit.blocks(fs.grid, None)
    outlets = {u: fs.outlet(u, "out") for u in kin}
    # mills given by their slurry hold-up: tau = V / Q needs the water through them, torn too
    wet = [u for u in kin if getattr(fs.units[u], "needs_water", False)]
    nv = len(kin) * N  # the flow vectors; the scalars (water, throughputs, recoveries) follow
    state = {}

    def g(X):
        extra = {}
        ustate = _torn_unit_state(torn, wet_o, recov, X[nv + len(wet):])
        for u in torn:
            blocks[u], infos[u] = fs.units[u].blocks(fs.grid, **ustate[u])
        for k, u in enumerate(kin):
            water = X[nv + wet.index(u)] if u in wet else None
            extra[outlets[u]], infos[u] = fs.units[u].product_flows(fs.grid, X[k * N:(k + 1) * N], water)
            note = getattr(fs.units[u], "transport_note", None)
            if note:
                infos[u]["method"] += f" [{note}]"
        flows, info = _linear_solve(fs, blocks, extra)
        state.update(flows=flows, info=info)
        out = [sum(flows[names.index(s)] for s in fs.inlets(u)) for u in kin]
        w = solve_water(fs, flows, infos) if (wet or wet_o) else None
        if wet:
            out.append(np.array([w.units[u]["water_in_kg_s"] for u in wet]))
        out.append(np.array(_torn_state(fs, torn, wet_o, recov, flows, infos, w), dtype=float))
        return np.concatenate(out)

    def err(gx, x):
        scalars = _relative_change(gx[nv:], x[nv:]) if gx.size > nv else 0.0
        return max(_vector_err(gx[:nv], x[:nv]), scalars)

    fresh = sum(u.solids * np.asarray(u.psd, float) for u in fs.units.values() if u.type == "feed")
    water0 = sum(getattr(u, "water", 0.0) for u in fs.units.values() if u.type == "feed")
    water0 += sum((getattr(fs, "water_added", {}) or {}).values())
    X0 = np.concatenate([fresh for _ in kin] + [np.full(len(wet), float(water0))]
                        + [np.array([float(np.sum(fresh))] * len(torn) + [float(water0)] * len(wet_o)
                                    + [0.5] * len(recov))])
    # the tolerance in effect: the tear cannot resolve what the mill solves do not
    g(X0)
    noise = max((float(infos[u].get("error_estimate") or 0.0) for u in kin), default=0.0)
    tol_used = max(tol, TEAR_NOISE_FACTOR * noise)
    scale = np.concatenate([np.full(nv, max(float(np.sum(X0[:nv])), 1e-300)),
                            np.maximum(np.abs(X0[nv:]), 1.0)])
    first_recovery = nv + len(wet) + len(torn) + len(wet_o)

    def project(x):  # flows, water and throughputs >= 0, corrected recoveries in [0, 1]
        x = np.maximum(np.asarray(x, dtype=float), 0.0)
        x[first_recovery:] = np.minimum(x[first_recovery:], 1.0)
        return x

    def bound(x, gx):  # an extrapolated Wegstein component outside its range takes the substitution step
        x = np.where(x < 0, gx, x)
        x[first_recovery:] = np.where(x[first_recovery:] > 1, gx[first_recovery:], x[first_recovery:])
        return x

    tears = {"wegstein": functools.partial(_wegstein, err=err, bound=bound, stall=TEAR_STALL),
             "substitution": functools.partial(_substitution, err=err),
             "newton": functools.partial(_vector_newton, err=err, scale=scale, project=project)}
    def at_floor(h):  # stopped (stalled or out of iterations) below the tolerance in effect
        return tol_used > tol and bool(h) and h[-1] <= tol_used

    # iterate to the requested tolerance while the changes keep falling; a tear that stops
    # above it but below the mills' own error (the tolerance in effect) is converged as far
    # as the solves it iterates allow, and says so
    X, its, hist, ok = tears[method](g, X0, tol, maxiter)
    floor = not ok and at_floor(hist)
    ok = ok or floor
    fallback = None
    if not ok and method == "wegstein":
        # Wegstein's componentwise secant slopes stall where the torn flows are coupled
        # (a non-linear mill in a recycle): Newton on the tear from where it stopped
        X2, its2, hist2, ok = tears["newton"](g, np.asarray(X, dtype=float), tol, maxiter)
        floor = not ok and at_floor(hist2)
        ok = ok or floor
        fallback = (f"wegstein stalled after {its} iterations at a relative change of "
                    f"{hist[-1] if hist else float('nan'):.3g}; newton on the tear from there "
                    f"{'converged' if ok else 'did not converge either'} in {its2} evaluations")
        if ok:
            _note_once(f"units {', '.join(kin)}: the Wegstein tear on the inlet flows stalled; Newton on the tear "
                       "took over and converged (the summary's solver.tear.fallback)")
        X, its, hist = X2, its + its2, hist + hist2
    also = f" (and the throughput of {', '.join(torn)})" if torn else ""
    if not ok:
        raise SolverError(f"tear iterations on the inlet flows of {', '.join(kin)} (non-linear kinetics){also} did "
                          f"not converge ({method}{', then newton from where it stalled' if fallback else ''}, "
                          f"{its} iterations, last relative change {hist[-1] if hist else float('nan'):.3g}, "
                          f"tolerance {tol_used:.2g}); the tear method is chosen with --tear-method "
                          "newton|wegstein|substitution (method= of millflow.flowsheet.solve)")
    g(np.asarray(X))  # final consistent pass
    flows, lin = state["flows"], state["info"]
    water = solve_water(fs, flows, infos)
    reports = _unit_reports(fs, flows, infos, mass_tol, water)
    from millflow.flowsheet.cyclone import report_operation
    report_operation(fs, flows, water, reports)
    solver = dict(lin)
    solver["structure"] = ("non-linear kinetics: tear iterations on the inlet flow vectors of " + ", ".join(kin)
                           + (f" and the throughput of {', '.join(torn)}" if torn else ""))
    solver["tear"] = {"method": method, "torn_units": kin + torn, "iterations": int(its), "converged": True,
                      "torn": "inlet flow vector"
                              + (f" (and the solids throughput of {', '.join(torn)})" if torn else "")
                              + (f" (and water of {', '.join(wet + wet_o)})" if wet or wet_o else "")
                              + (f" (and corrected recovery C of {', '.join(recov)})" if recov else ""),
                      "residual_history": [float(h) for h in hist], "tolerance": tol}
    if floor:
        solver["tear"]["tolerance_in_effect"] = tol_used
        solver["tear"]["tolerance_note"] = (f"{TEAR_NOISE_FACTOR:g} x the largest error estimate of the non-linear "
                                            f"mills' products ({noise:.2g}): the tear cannot resolve changes below "
                                            "the error of the solves it iterates")
    if fallback:
        solver["tear"]["fallback"] = fallback
    return FlowsheetSolution(flowsheet=fs, flows=flows, units=reports, solver=solver,
                             runtime_s=time.perf_counter() - t0, unit_blocks=blocks, water=water)


def _unit_reports(fs, flows, infos, mass_tol: float = MASS_TOL, water=None) -> dict:
    names = fs.stream_names
    tot = {n: math.fsum(flows[k]) for k, n in enumerate(names)}
    out = {}
    for uname, unit in fs.units.items():
        fin = math.fsum(tot[s] for s in fs.inlets(uname))
        if unit.type == "feed":
            fin = unit.solids
        fout = math.fsum(tot[s] for s in fs.outlets(uname))
        if unit.type == "product":
            fout = fin
        scale = max(abs(fin), abs(fout), 1e-300)
        rep = {"type": getattr(unit, "kind", unit.type), **infos[uname],
               "solids_in_kg_s": fin, "solids_out_kg_s": fout,
               "mass_balance_error": abs(fout - fin) / scale}
        if not rep["mass_balance_error"] <= mass_tol:
            raise SolverError(f"units.{uname}: mass balance error {rep['mass_balance_error']:.2g} "
                              f"(in {fin:.6g} kg/s, out {fout:.6g} kg/s) above mass_tol {mass_tol:.2g}")
        if water is not None:
            rep.update(water.units[uname])
            if not rep["water_balance_error"] <= mass_tol:
                raise SolverError(f"units.{uname}: water balance error {rep['water_balance_error']:.2g} above "
                                  f"mass_tol {mass_tol:.2g}")
        if unit.type == "mill":
            tau = infos[uname].get("tau_s")
            if tau is not None:
                rep["holdup_kg"] = tau * fin  # solids hold-up at steady state, H = tau F
        if unit.type == "mill" and unit.power is not None and fin > 0:
            rep["power_kW"] = unit.power / 1e3
            rep["specific_energy_kWh_per_t"] = (unit.power / 1e3) / (fin * 3.6)
        out[uname] = rep
    if water is not None and not water.overall_error <= mass_tol:
        # every unit may close while the flowsheet does not (water in a loop the tear left
        # unconverged): the overall balance is checked like the solids'
        raise SolverError(f"water balance of the flowsheet: error {water.overall_error:.2g} (water fed and added vs "
                          f"water in the products) above mass_tol {mass_tol:.2g}")
    return out
