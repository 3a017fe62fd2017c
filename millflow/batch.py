"""Batch grinding and plug flow: the linear population balance of eq. 4.

    dM_i/dt = -S_i M_i + sum_{j<i} b_ij S_j M_j,    M(0) = feed,

i.e. dM/dt = K M with K = (b - I) diag(S) (see :mod:`millflow.linalg`). Its exact
solution M(t) = exp(K t) feed is evaluated by the block eigen-decomposition of
:class:`~millflow.linalg.SpectralBlocks`, which stays accurate when rates are equal
or nearly equal (where Reid's closed form divides by zero), when they span many
decades and when S t is huge or tiny. The ODE path (scipy's ``solve_ivp`` with the
analytic Jacobian K, through :func:`millflow.ode.integrate_linear`) is kept for
comparison and for nonlinear terms added later.

Plug flow (no back-mixing) is the same solution at the contact time t* = y/u,
u = L/tau: the product is M(t* = tau), the axial profile M(y) at any positions.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from millflow import checks
from millflow.errors import InputError
from millflow.linalg import (DEFAULT_CLUSTER_GAP, SpectralBlocks, breakage_matrix,
                             eigenvectors_distinct_population)
from millflow.ode import integrate_linear

__all__ = ["BatchResult", "batch_grind", "batch_grind_population", "batch_solve", "grind", "plug_flow_profile",
           "ODE_METHODS"]

#: Cancellation target of the exact path: the first decomposition (distinct rates, gap
#: 1e-3) is accepted when eps * max |X| |X^-1 f| is below it (as in SpectralBlocks.decompose).
CANCELLATION_TARGET = 1e-13

#: solve_ivp methods offered on the ODE path (implicit, for stiff rates).
ODE_METHODS = ("BDF", "Radau", "LSODA")


@dataclass(frozen=True)
class BatchResult:
    """Mass fractions of a batch grind with the diagnostics of the solve.

    Attributes
    ----------
    M : (T, N) mass in each class at each time (same total as the feed).
    t : (T,) times [s].
    method : name of the method that ran.
    error_estimate : estimated max absolute error of M (rounding bound of the
        exact path; the tolerance-scaled estimate of an ODE path).
    mass_balance_error : max over times of |sum(M) - sum(feed)|.
    runtime_s : wall time of the solve [s].
    info : method details (cluster gap, cluster sizes, evaluation counts).
    """

    M: np.ndarray
    t: np.ndarray
    method: str
    error_estimate: float
    mass_balance_error: float
    runtime_s: float
    info: dict = field(default_factory=dict)


def _check_inputs(S, b, feed, t):
    S, b = checks.kernel(S, b)
    feed = checks.class_vector(feed, S.size, "feed", "mass fraction")
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1:
        raise InputError(f"t has shape {t.shape}; expected a scalar or a 1-D array of times")
    if not np.all(np.isfinite(t)) or np.any(t < 0):
        k = int(np.flatnonzero(~(np.isfinite(t) & (t >= 0)))[0])
        raise InputError(f"t[{k}] is {t[k]!r}; expected a finite time >= 0")
    return S, b, feed, t


def batch_solve(S, b, feed, t, method: str = "exact", *, rtol: float = 1e-10, atol: float = 1e-14,
                kernel: str | None = None) -> BatchResult:
    """Solve eq. 4 and return a :class:`BatchResult` with diagnostics.

    Parameters
    ----------
    S : (N,) specific breakage rates [1/s]; S_N = 0 (the sink does not break).
    b : (N, N) fractional breakage distribution, strictly lower triangular,
        b[i, j] = fraction of class-j breakage going to class i; columns sum to 1.
    feed : (N,) initial mass fractions (any non-negative total; it is conserved).
    t : scalar or (T,) times [s].
    method : "exact" (block eigen-decomposition, default) or one of
        :data:`ODE_METHODS` for scipy's solve_ivp with the analytic Jacobian.
    rtol, atol : tolerances of the ODE path (ignored by the exact path).
    kernel : who runs the exact path's row recurrences: None (the environment's
        choice, :func:`millflow.compiled.kernel`), "compiled" or "numpy".
    """
    S, b, feed, t = _check_inputs(S, b, feed, t)
    start = time.perf_counter()
    if method == "exact":
        blocks, w, cancellation = SpectralBlocks.decompose(S, b, feed=feed, target=CANCELLATION_TARGET,
                                                           kernel=kernel)
        M = blocks.expm_apply(feed, t, w=w)
        M, error, rounding = _finish(M, feed, t, cancellation)
        info = {**blocks.summary(), "sink_rounding_removed": float(rounding.max())}
    elif method in ODE_METHODS:
        M, info = _ode_solve(breakage_matrix(S, b), feed, t, method, rtol, atol)
        error = float(rtol * np.abs(M).max() + atol)
    else:
        raise InputError(f"method {method!r} is unknown; expected 'exact' or one of {', '.join(ODE_METHODS)}")
    runtime = time.perf_counter() - start
    mass_error = float(np.abs(M.sum(axis=1) - feed.sum()).max())
    return BatchResult(M, t, method, float(error), mass_error, runtime, info)


def _finish(M, feed, t, cancellation):
    """Finish the exact path in place: sink balance, error, sink rounding.

    Last steps of the exact path, in place, for one member (M (T, N), feed (N,),
    cancellation a float) or a population (M (P, T, N), feed (P, N), cancellation (P,));
    returns (M, error, sink rounding removed).

    The sink row of X is a difference of O(1) terms, which carries eps-level
    cancellation when the sink is nearly empty; the balance (the same quantity in
    exact arithmetic, since columns of K sum to zero) is accurate to the error of the
    other classes. exp(0) = I exactly, not through X X^-1. A nearly empty sink can
    come out as -1e-16: rounding of the other classes' sum, inside the error
    estimate; it is set to zero and the amount recorded.
    """
    total = feed.sum(axis=-1)
    M[..., -1] = np.expand_dims(total, -1) - M[..., :-1].sum(axis=-1)
    zero = t == 0
    if zero.any():
        M[..., zero, :] = np.expand_dims(feed, -2)
    error = 4.0 * cancellation + np.finfo(float).eps * total * feed.shape[-1]
    rounding = np.clip(-M[..., -1], 0.0, np.expand_dims(error, -1))
    M[..., -1] += rounding
    return M, error, rounding


def batch_grind_population(S, b, feed, t, *, kernel: str | None = None) -> np.ndarray:
    """Eq. 4 for a population of rate and breakage sets at once: (P, T, N).

    Each member's result is :func:`batch_grind`'s (the same method, to rounding): the
    eigenvectors of the breakage matrix by the row recurrence of :mod:`millflow.linalg`
    (``kernel``: the compiled kernel member by member when available, else numpy
    vectorised over the population), accepted when no two rates lie within the
    cluster gap (1e-3 relative) and the cancellation estimate eps |X| |X^-1 f| is below
    :data:`CANCELLATION_TARGET`; every other member (nearly equal rates, e.g. alpha
    near 0 in eq. 5) is solved by :func:`batch_solve`, which groups close rates into
    blocks and stays exact.

    Parameters
    ----------
    S : (P, N) rates [1/s] (S_N = 0); b : (P, N, N) or (N, N) fractional breakage;
    feed : (N,) or (P, N); t : (T,) times [s] (>= 0).

    Members with non-finite S or b (parameters outside the model's domain, see
    :func:`millflow.breakage.rates.power_law_rates_population`) get NaN, not an error:
    an optimiser's population may visit them. Other bad input raises InputError.
    """
    S = np.atleast_2d(np.asarray(S, dtype=float))
    n_pop, n = S.shape
    b = np.broadcast_to(np.asarray(b, dtype=float), (n_pop, n, n))
    feed = np.asarray(feed, dtype=float)
    if feed.shape not in ((n,), (n_pop, n)):
        raise InputError(f"feed has shape {feed.shape}; expected ({n},) or ({n_pop}, {n})")
    feeds = np.broadcast_to(feed, (n_pop, n))
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise InputError(f"t = {t!r}: expected a 1-D array of finite times >= 0 [s]")
    out = np.full((n_pop, t.size, n), np.nan)
    valid = np.isfinite(S).all(axis=1) & np.isfinite(b).all(axis=(1, 2))
    s_sorted = np.sort(S, axis=1)
    close = (np.diff(s_sorted, axis=1) <= DEFAULT_CLUSTER_GAP * s_sorted[:, 1:]).any(axis=1)
    fast = np.flatnonzero(valid & ~close)
    slow = [int(k) for k in np.flatnonzero(valid & close)]
    if fast.size:
        Sf = S[fast]
        A = b[fast] * -Sf[:, np.newaxis, :]
        A[:, np.arange(n), np.arange(n)] = Sf
        X = eigenvectors_distinct_population(A, Sf, kernel)
        ok = np.isfinite(X).all(axis=(1, 2))
        w = np.zeros((fast.size, n))
        if ok.any():
            w[ok] = np.linalg.solve(X[ok], feeds[fast[ok]][:, :, np.newaxis])[:, :, 0]
        with np.errstate(invalid="ignore", over="ignore"):
            cancellation = np.finfo(float).eps * np.matmul(np.abs(X), np.abs(w)[:, :, np.newaxis])[:, :, 0].max(axis=1)
        ok &= cancellation <= CANCELLATION_TARGET
        keep = fast[ok]
        if keep.size:
            E = np.exp(-S[keep][:, np.newaxis, :] * t[np.newaxis, :, np.newaxis]) * w[ok][:, np.newaxis, :]
            M = np.matmul(E, X[ok].transpose(0, 2, 1))
            out[keep] = _finish(M, feeds[keep], t, cancellation[ok])[0]
        slow += [int(k) for k in fast[~ok]]
    for k in sorted(slow):
        out[k] = batch_solve(S[k], b[k], feeds[k], t, kernel=kernel).M
    return out


def batch_grind(S, b, feed, t, method: str = "exact", *, rtol: float = 1e-10, atol: float = 1e-14) -> np.ndarray:
    """Mass fractions of a batch grind (eq. 4) at times t; shape (T, N).

    The plain-array entry point; see :func:`batch_solve` for the diagnostics (method,
    error estimate, run time) and the methods.

    Parameters
    ----------
    S : array_like, (N,)
        Specific breakage rates [1/s]; S_N = 0 (the sink).
    b : array_like, (N, N)
        Fractional breakage distribution [-], strictly lower triangular, columns j < N
        summing to 1.
    feed : array_like, (N,)
        Mass fractions at t = 0 [-].
    t : float or array_like, (T,)
        Times [s], >= 0; a scalar gives T = 1.
    method : str
        "exact" (the eigenvector recurrence, exact for equal rates too), or an ODE method
        of :func:`batch_solve`.
    rtol, atol : float
        Tolerances of the ODE methods.

    Returns
    -------
    numpy.ndarray, (T, N)
        Mass fractions [-] at each time.

    Raises
    ------
    InputError
        Shapes that do not agree, negative or non-finite times.

    References
    ----------
    K. J. Reid, A solution to the batch grinding equation, Chem. Eng. Sci. 20 (1965)
    953-963 (the analytic solution, whose divisions by S_i - S_j the exact method avoids).

    Examples
    --------
    One class breaking into the sink decays as exp(-S t):

    >>> import numpy as np
    >>> M = batch_grind([2.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], [0.0, 0.5])
    >>> bool(np.allclose(M[:, 0], np.exp(-2.0 * np.array([0.0, 0.5]))))
    True
    """
    return batch_solve(S, b, feed, t, method, rtol=rtol, atol=atol).M


def _ode_solve(K: np.ndarray, feed: np.ndarray, t: np.ndarray, method: str, rtol: float, atol: float):
    """Solve exp(K t) feed by scipy's solve_ivp.

    exp(K t) feed by :func:`millflow.ode.integrate_linear`: dM/dt = K M with the constant
    Jacobian K.
    """
    order = np.argsort(t)
    t_sorted = t[order]
    out = np.empty((t.size, feed.size))
    at_zero = t_sorted == 0.0
    out[order[at_zero]] = feed
    if (~at_zero).any():
        sol = integrate_linear(K, (0.0, float(t_sorted[-1])), feed, method=method, t_eval=t_sorted[~at_zero],
                               rtol=rtol, atol=atol, what="batch grind (ODE path)")
        out[order[~at_zero]] = sol.y.T
        info = {"nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu)}
    else:
        info = {"nfev": 0, "njev": 0, "nlu": 0}
    return out, info


def plug_flow_profile(S, b, feed, tau: float, positions) -> np.ndarray:
    """Axial profile of a plug-flow mill: M(y) at fractional positions y/L; (P, N).

    Contact time t* = y/u with u = L/tau, so t* = tau * (y/L) [s]; position 1 is the
    discharge (the product). Parameters as :func:`batch_grind`, tau > 0 [s].
    """
    if not np.isfinite(tau) or tau <= 0:
        raise InputError(f"tau is {tau!r}; expected a mean residence time > 0 [s]")
    positions = np.atleast_1d(np.asarray(positions, dtype=float))
    if np.any((positions < 0) | (positions > 1)) or not np.all(np.isfinite(positions)):
        raise InputError("positions must be fractions of the mill length in [0, 1]")
    return batch_grind(S, b, feed, tau * positions)


def _kernel_status() -> str:
    from millflow.compiled import status

    return status()


def _on_grid(rates, breakage, grid):
    """(S, b, how) of rate and breakage models (or arrays: the discrete model as given)."""
    from millflow.breakage import evaluate_b, evaluate_rates
    from millflow.breakage.averaged import breakage_on_grid

    model_S = callable(rates) or hasattr(rates, "rates")
    model_b = callable(breakage) or hasattr(breakage, "b")
    if model_S and model_b:
        S, b, how = breakage_on_grid(rates, breakage, grid)
        return S, b, how
    S = evaluate_rates(rates, grid) if model_S else np.asarray(rates, float)
    b = evaluate_b(breakage, grid) if model_b else np.asarray(breakage, float)
    return S, b, "discrete (as given)"


def _grind_grid_error(rates, breakage, grid, feed, times_s, method, M, how):
    """Grid error [max abs of M] of a batch grind of continuous forms.

    The grind again on the grid refined 2x, the feed moved there by the module's monotone
    interpolation of its cumulative passing (:func:`millflow.psd.regrid`: the same class
    masses on the coarse edges), reduced exactly to the coarse edges, Richardson at the
    scheme's order with Roache's safety factor 3. Discrete S_i, b_ij carry no grid error.
    """
    from millflow.grid import SAFETY_FACTOR
    from millflow.psd import regrid

    if how == "discrete (as given)" or getattr(grid, "n", 1) < 2:
        return 0.0, "none: the discrete S_i, b_ij as given are the model (no size grid error)"
    fine = grid.refine(2)
    f = np.asarray(feed, float)
    total = f.sum()
    f2 = regrid(f / total, grid, fine) * total if total > 0 else np.zeros(fine.n)
    S2, b2, _ = _on_grid(rates, breakage, fine)
    M2 = batch_solve(S2, b2, f2, times_s, method).M
    red = np.array([regrid(m / m.sum(), fine, grid) * m.sum() if m.sum() > 0 else m[::2] for m in M2])
    order = 2 if how == "class average" else 1
    ext = red + (red - M) / (2.0 ** order - 1.0)
    err = SAFETY_FACTOR * float(np.max(np.abs(M - ext)))
    return err, (f"Richardson (order {order}, {how}) against the grind on the grid refined 2x in ln x (feed "
                 f"interpolated by psd.regrid); {SAFETY_FACTOR:g} x |M - M_extrapolated| (Roache's two-grid GCI)")


def grind(grid, rates, breakage, feed, times_s, method: str = "exact"):
    """Batch grind on a size grid with breakage models; an xarray Dataset.

    Parameters
    ----------
    grid : :class:`~millflow.grid.SizeGrid` (class sizes [m], Austin's upper edges).
    rates : rate model (callable x -> S [1/s], e.g. ``PowerLawRate``) or an (N,) array.
    breakage : distribution model (callable x -> b, e.g. ``NormalizedBreakage``) or an
        (N, N) b array.
    feed : (N,) mass fractions at t = 0.
    times_s : times [s].

    Returns
    -------
    xarray.Dataset with ``mass_fraction`` and ``cum_passing`` over (time, size) and the
    solve's ``method``, ``error_estimate``, ``mass_balance_error``, ``runtime_s`` in attrs.
    ``error_estimate`` [max abs of M] is the sum of ``solver_error_estimate`` and
    ``grid_error_estimate``, each with its ``..._method``: continuous forms (rate and
    breakage models) are class-averaged on ``grid`` (``discretisation``; Austin's
    upper edges on a grid with ``scheme="upper_edge"``) and their grid error is
    estimated by a second grind on the grid refined 2x (Richardson); arrays S_i, b_ij
    are the discrete model itself and carry no grid error.

    Examples
    --------
    >>> from millflow.grid import SizeGrid
    >>> from millflow.breakage import PowerLawRate, NormalizedBreakage
    >>> grid = SizeGrid.geometric(1e-3, 2 ** 0.25, 40)
    >>> feed = np.r_[1.0, np.zeros(39)]
    >>> rate, breakage = PowerLawRate(A=0.01, alpha=1.0, x0=1e-3), NormalizedBreakage(0.4, 0.8, 3.0)
    >>> ds = grind(grid, rate, breakage, feed, [0, 60, 600])
    >>> ds.mass_fraction.dims
    ('time', 'size')
    >>> bool(ds.attrs["mass_balance_error"] < 1e-13)
    True
    """
    import xarray as xr

    from millflow.psd import cum_passing

    S, b, how = _on_grid(rates, breakage, grid)
    res = batch_solve(S, b, feed, times_s, method)
    grid_err, grid_how = _grind_grid_error(rates, breakage, grid, feed, times_s, method, res.M, how)
    coords = {"time": ("time", res.t, {"units": "s", "long_name": "grinding time"}), "size": grid.size_coord()}
    cum = np.array([cum_passing(m) for m in res.M])
    return xr.Dataset(
        {
            "mass_fraction": (("time", "size"), res.M, {"units": "1", "long_name": "mass fraction in class"}),
            "cum_passing": (("time", "size"), cum, {"units": "1", "long_name": "cumulative fraction passing x"}),
            "rate": ("size", S, {"units": "1/s", "long_name": "specific breakage rate S_i"}),
        },
        coords=coords,
        attrs={
            "method": res.method,
            "error_estimate": res.error_estimate + grid_err,
            "solver_error_estimate": res.error_estimate,
            "solver_error_method": f"{res.method}: rounding bound of the solve (max abs error of M)",
            "grid_error_estimate": grid_err,
            "grid_error_method": grid_how,
            "discretisation": how,
            "mass_balance_error": res.mass_balance_error,
            "runtime_s": res.runtime_s,
            "kernel": _kernel_status(),  # which kernel ran: compiled C or numpy
            "equation": "dM_i/dt = -S_i M_i + sum_{j<i} b_ij S_j M_j (eq. 4)",
        },
    )
