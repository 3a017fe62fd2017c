"""Newton's method for the steady states of mills with non-linear kinetics: one solver for
every transport (a perfect mixer, a network of cells, the nodes of an axial grid).

Solves F(y) = 0 with a factorised Jacobian that is kept while it works (the chord, or
simplified Newton, method) and rebuilt when it does not:

- a step dy = -J0^-1 F(y) with the kept factors J0 of an earlier state (or of the previous
  cell of a chain: a warm start), a backtracking line search on max|F|;
- the factors are rebuilt at the current state when the contraction of the steps
  rho = |dy_k| / |dy_(k-1)| exceeds :data:`REFRESH_RATIO`, or when a step with kept factors
  is refused by the line search (then the step is retried with fresh ones);
- if Newton with fresh factors stalls (no step reduces max|F|) it hands over to
  pseudo-transient continuation, (Mass/dt - J) dy = F with dt grown by the residual ratio,
  to residual 1e-6 s, with its own iteration budget (``ptc_iter``: far from the root it
  takes hundreds of steps where Newton takes a few), then Newton again;
- if that fails too (continuation stalls where material accumulates slowly in a retained
  class), the dynamics themselves, Mass dy/dt = F(y), are integrated by an
  error-controlled implicit solver towards the steady state the mill's start-up reaches
  (``dynamics``), then Newton again.

Stated criterion: converged when max|F| <= tol * s, s the size of the terms F is made of
(the caller's ``scale``: feed, transport flows x state, breakage flux); or when a chord
step follows one with the same factors and twice its measured contraction q = 2 |dy_k| /
|dy_(k-1)| (at most 0.2) predicts it, q max|F| <= tol * s: that step is taken without
evaluating F after it, and its error bounded by q |dy_k| / (1 - q) (this saves a residual
evaluation and a solve per Newton call); or, at the rounding floor where no step reduces
max|F|, when the full step is itself below tol * s.

Error estimate (of the state, max norm): the next step at the answer with the kept
factors, |dy| / (1 - rho), rho the observed contraction (at most 1/2: the factors are
rebuilt above :data:`REFRESH_RATIO`), i.e. the distance to the root of the linearised
problem bounded by the geometric series of the chord iteration. It costs one solve with
factors already built (no Jacobian, no factorisation, no extra residual); the step is
then applied, so the returned state is the corrected one (its error is below the
estimate, which bounds the error before the step) and ``residual`` is max|F| at the last
evaluated state, before it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.linalg import lapack

from millflow.errors import SolverError
from millflow.ode import integrate

__all__ = ["NewtonResult", "newton", "DenseFactor", "SparseFactor", "BlockTridiagonalFactor", "ChainFactor",
           "REFRESH_RATIO"]

#: Chord contraction above which the factors are rebuilt at the current state.
REFRESH_RATIO = 0.2
#: Default budgets: Newton iterations per Newton phase, and pseudo-transient steps.
MAX_ITER, PTC_ITER = 60, 500

_getrf, _getrs = lapack.get_lapack_funcs(("getrf", "getrs"), dtype=np.float64)


class DenseFactor:
    """LU factors of a dense matrix (LAPACK getrf/getrs directly: small systems, where
    the wrappers' checks cost as much as the work)."""

    def __init__(self, A):
        # the factors of A^T in place: a C-ordered A is LAPACK's (column-ordered) A^T, so no
        # copy is made; A x = r is then solved as (A^T)^T x = r (getrs, trans = 1)
        self.lu, self.piv, info = _getrf(A.T, overwrite_a=True)
        if info > 0 or not np.isfinite(self.lu).all():
            raise SolverError("the Newton matrix is singular")

    def solve(self, r):
        x, info = _getrs(self.lu, self.piv, r, trans=1)
        return x


class SparseFactor:
    """SuperLU factors of a sparse matrix."""

    def __init__(self, A):
        import scipy.sparse.linalg

        try:
            self.lu = scipy.sparse.linalg.splu(A.tocsc())
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SolverError(f"the Newton matrix is singular ({exc})") from exc

    def solve(self, r):
        return self.lu.solve(r)


class BlockTridiagonalFactor:
    """Block elimination of lower_k x_(k-1) + D_k x_k + upper_k x_(k+1) = r_k with diagonal
    off-diagonal blocks (``lower`` (m - 1, n) the coefficients of x_(k-1) in equation k,
    ``upper`` (m - 1, n) those of x_(k+1) in equation k), dense D (m, n, n): the
    transport couples each component only to itself at the neighbouring nodes. The
    Schur complements D'_k = D_k - diag(lower_k) D'_(k-1)^-1 diag(upper_(k-1)) are
    inverted once (O(m n^3)); a solve is then two sweeps of matrix-vector products."""

    def __init__(self, blocks, lower, upper):
        """``blocks``: the dense diagonal blocks D_k in order (an array (m, n, n) or an iterable
        of (n, n) arrays); each node's inverse is kept as its own array (small arrays come
        back from the allocator warm; one large one is fresh memory at every factorisation)."""
        inv = []
        for k, Dk in enumerate(blocks):
            if k:
                Dk = Dk - lower[k - 1][:, None] * inv[-1] * upper[k - 1][None, :]
            try:
                Ik = scipy.linalg.inv(Dk, check_finite=False, overwrite_a=k > 0)
            except (np.linalg.LinAlgError, ValueError) as exc:
                raise SolverError(f"the Newton matrix is singular at node {k + 1} ({exc})") from exc
            if not np.isfinite(Ik).all():
                raise SolverError(f"the Newton matrix is singular at node {k + 1} (non-finite block inverse)")
            inv.append(Ik)
        self.inv, self.lower, self.upper = inv, lower, upper

    def solve(self, r):
        m, n = len(self.inv), self.inv[0].shape[0]
        r = np.array(r, dtype=float).reshape(m, n)
        inv, lo, up = self.inv, self.lower, self.upper
        g = np.empty_like(r)
        g[0] = inv[0] @ r[0]
        for k in range(1, m):
            g[k] = inv[k] @ (r[k] - lo[k - 1] * g[k - 1])
        x = g  # back substitution in place: x_k = g_k - D'_k^-1 (upper_k x_(k+1))
        for k in range(m - 2, -1, -1):
            x[k] = g[k] - inv[k] @ (up[k] * x[k + 1])
        return x.ravel()


class ChainFactor:
    """Factors of a chain of cells: block lower bidiagonal, A_k x_k + c_(k-1) * x_(k-1) = r_k
    (dense diagonal blocks A (n, m, m), ``coupling`` (n - 1, m) the diagonal blocks below:
    what cell k - 1 passes to cell k). Solved by forward substitution, one LU per cell."""

    def __init__(self, A, coupling):
        """``A``: the diagonal blocks (an array (n, m, m) or an iterable of (m, m) arrays)."""
        self.blocks = [DenseFactor(Ak) for Ak in A]
        self.coupling = coupling

    def solve(self, r):
        n = len(self.blocks)
        r = np.asarray(r, dtype=float).reshape(n, -1)
        x = np.empty_like(r)
        x[0] = self.blocks[0].solve(r[0])
        for k in range(1, n):
            x[k] = self.blocks[k].solve(r[k] - self.coupling[k - 1] * x[k - 1])
        return x.ravel()


@dataclass
class NewtonResult:
    """The root ``y`` (the last evaluated state plus ``correction``), ``residual`` max|F| at the
    last evaluated state (or, when the last chord step was taken on its predicted residual,
    that prediction q max|F|), ``scale`` s of the criterion, ``step`` the error estimate of y (max
    norm), ``iterations`` (Newton and pseudo-transient steps, right-hand sides of the dynamics),
    ``factorizations``, ``how`` (the phases that ran), ``factor`` (the factors kept at
    the end, for a warm start of the next solve), ``correction`` the next step at the
    answer and ``rho`` the contraction it is divided by (``step`` = max|correction| /
    (1 - rho): a caller maps the correction to its product)."""

    y: np.ndarray
    residual: float
    scale: float
    step: float
    iterations: int
    factorizations: int
    how: str
    factor: object
    correction: np.ndarray
    rho: float


def newton(F, factor, y0, scale, *, tol: float, max_iter: int = MAX_ITER, ptc_iter: int = PTC_ITER,
           unit: str = "steady state", what: str = "", dt0: float = 1.0, warm=None,
           phases=("newton", "pseudo-transient", "newton", "transient", "newton"), dynamics=None) -> NewtonResult:
    """Solve F(y) = 0 (module docstring).

    Parameters
    ----------
    F : y -> residual; may raise SolverError where it is undefined (a failed trial point).
    factor : (y, shift) -> factors of dF/dy - shift Mass (shift 0: the Jacobian; shift 1/dt:
        the pseudo-transient matrix), an object with ``solve(r)``.
    y0 : start; scale : y -> s, the size of the terms of F (criterion max|F| <= tol s).
    max_iter : Newton iterations per Newton phase; ptc_iter : pseudo-transient steps.
    dt0 : first pseudo-time step (the time scale of the system, e.g. its residence time).
    warm : factors of a nearby problem to start the chord iteration with (or None).
    unit, what : named in the error message (the unit; the kinetics and grid).
    dynamics : (mass (n,), jacobian y -> dF/dy) for the "transient" phase: the dynamics
        Mass dy/dt = F(y) integrated by an error-controlled implicit solver (scipy BDF) over
        horizons growing tenfold from ``dt0``, until max|F| < 1e-6 s (the steady state the
        mill's own start-up reaches, where pseudo-transient steps stalled); None skips it.
    """
    y = np.array(y0, dtype=float)
    f = F(y)
    res = float(np.abs(f).max())
    scale_of = scale
    scale_at = [None, 0.0]

    def scale(v):  # the scale of the last state asked for, kept (it costs a rate evaluation)
        if scale_at[0] is not v:
            scale_at[0], scale_at[1] = v, scale_of(v)
        return scale_at[1]

    s = scale(y)
    its, nfac, ran = 0, 0, []
    fac, fresh = warm, False
    rho, last_step = 0.0, None
    floor, refresh = False, False

    start = y

    def safe_F(v):
        try:
            out = F(v)
        except SolverError:  # e.g. Phi undefined at a trial point: a failed trial, not a failed solve
            return None
        return out if np.isfinite(out).all() else None

    def fresh_factor(v):
        nonlocal nfac
        nfac += 1
        return factor(v, 0.0)

    for phase in phases:
        if res <= tol * s or floor:
            break
        ran.append(phase)
        if phase == "newton":
            budget = its + max_iter
            while its < budget:
                if res <= tol * s:
                    s = scale(y)  # the state moved: the criterion's scale with it
                    if res <= tol * s:
                        break
                its += 1
                if fac is None or refresh:
                    fac, fresh, last_step, refresh = fresh_factor(y), True, None, False
                dy = fac.solve(-f)
                if not np.isfinite(dy).all():
                    if fresh:
                        break
                    fac = None
                    continue
                if last_step:  # a chord step after one with the same factors: its contraction is measured
                    q = 2.0 * float(np.abs(dy).max()) / last_step  # twice the measured contraction
                    if q <= 0.2 and q * res <= tol * scale(y):
                        # the step's predicted residual (q max|F|) meets the criterion: take it without
                        # evaluating F there; its error is bounded by the series q |dy| / (1 - q)
                        return NewtonResult(y + dy, q * res, scale(y), q * float(np.abs(dy).max()) / (1.0 - q),
                                            its, nfac, " + ".join(ran), fac, q * dy, q)
                lam, ft = 1.0, None
                while lam >= 1.0 / 256:
                    trial = safe_F(y + lam * dy)
                    if trial is not None and np.abs(trial).max() <= (1.0 - 1e-4 * lam) * res:
                        ft = trial
                        break
                    lam *= 0.5
                if ft is None:
                    if not fresh:  # kept factors that no longer give a descent step: rebuild them
                        fac = None
                        continue
                    floor = bool(np.abs(dy).max() <= tol * s)
                    break
                size = float(np.abs(dy).max())
                new = float(np.abs(ft).max())
                # contraction: of the steps with these factors, or of the residual on their first step
                rho = size / last_step if (last_step and lam == 1.0) else new / res
                y, f, res = y + lam * dy, ft, new
                last_step = size if lam == 1.0 else None
                # damped, or a slow chord: fresh factors at the new state (if another step is needed)
                refresh = lam < 1.0 or (not fresh and rho > REFRESH_RATIO)
                rho = 1.0 if lam < 1.0 else rho
                fresh = False
        elif phase == "pseudo-transient":
            dt = dt0
            budget = its + ptc_iter
            while its < budget:
                its += 1
                nfac += 1
                dy = factor(y, 1.0 / dt).solve(f)
                trial = safe_F(y - dy)
                if trial is None:
                    dt *= 0.25
                    continue
                new = float(np.abs(trial).max())
                # switched evolution relaxation: dt grows with the residual's fall (at most 10x); a
                # residual that rises on the way (material accumulating in a slow class) keeps dt,
                # only a blow-up (10x) halves it: implicit Euler is stable at any dt for the
                # linearised system, and a shrinking dt stalls the continuation on slow transients
                ratio = res / max(new, 1e-300)
                dt *= min(10.0, max(1.0, ratio)) if ratio > 0.1 else 0.5
                y, f, res = y - dy, trial, new
                if res < 1e-6 * scale(y):
                    break
            fac, last_step, refresh = None, None, False
        elif phase == "transient":
            if dynamics is None:
                continue
            # from the start (a physical state: continuation may have wandered into one that is not)
            y, f, res, n_ode = _integrate_to_steady(F, dynamics, start, scale, dt0, res)
            its += n_ode
            fac, last_step, refresh = None, None, False
        s = scale(y)
        if phase == "newton" and its >= budget and res > tol * s and not floor:
            break
    how = " + ".join(p for p in ran if p != "transient" or dynamics is not None) or "start already converged"
    s = scale(y)
    if not np.isfinite(res) or (res > tol * s and not floor):
        raise SolverError(f"{unit}: the steady state did not converge: residual max|F| = {res:.3g} > tol {tol:g} "
                          f"x scale {s:.3g} after {its} iterations ({how}{'; ' + what if what else ''})")
    if fac is None or rho >= 0.5 or its == 0:  # no factors, too slow a chord for its series bound, or no step
        fac, rho = fresh_factor(y), 0.0
    corr = fac.solve(-f)
    rho = min(rho, 0.5)
    # the correction is applied (it costs nothing more): the state moves closer to the root
    # (the chord contracts), and the mass balance closes to second order in the step (the
    # columns of dR/dy sum to zero, so sum F(y + dy) = sum (F + J0 dy) + O(dy^2) = O(dy^2))
    return NewtonResult(y + corr, res, s, float(np.abs(corr).max()) / (1.0 - rho), its, nfac, how, fac, corr, rho)


def _integrate_to_steady(F, dynamics, y, scale, dt0, res, horizons: int = 14):
    """Mass dy/dt = F(y) from y by BDF (rtol 1e-6) over horizons dt0 10^k until max|F| < 1e-6 s;
    returns (y, F(y), max|F|, right-hand-side evaluations)."""
    mass, jacobian = dynamics
    inv = 1.0 / np.asarray(mass, float)
    import scipy.sparse as sp

    def rhs(_t, v):
        return inv * F(v)

    def jac(_t, v):
        J = jacobian(v)
        return (sp.diags(inv) @ J).tocsc() if sp.issparse(J) else inv[:, None] * J

    f, nfev, T = F(y), 0, dt0
    for _ in range(horizons):
        try:
            sol = integrate(rhs, (0.0, T), y, method="BDF", jac=jac, rtol=1e-6, atol=1e-12 * max(np.abs(y).max(), 1.0),
                            what="Newton's transient continuation")
        except SolverError:  # a failed solve (or a right-hand side that refused the state): stop here
            break
        nfev += int(sol.nfev)
        if not np.isfinite(sol.y[:, -1]).all():
            break
        y = sol.y[:, -1]
        f = F(y)
        res = float(np.abs(f).max())
        if res < 1e-6 * scale(y):
            break
        T *= 10.0
    return y, f, res, nfev
