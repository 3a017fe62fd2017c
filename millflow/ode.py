"""The one home of millflow's ODE solves: scipy's ``solve_ivp`` behind one checked call.

Every initial-value problem of the library (the batch ODE path, the transient mills, plug
flow and the age-structured cells with non-linear kinetics, the non-linear batch, the
micromixing limits, Newton's transient continuation, the kinetics fit's stacked forward
solve) goes through :func:`integrate` or, for a linear system with a constant Jacobian,
:func:`integrate_linear`. One place checks the tolerances, hands the Jacobian to the
method in the form it takes, and turns a failed solve into one
:class:`~millflow.errors.SolverError` line of one form.

Why implicit methods with an analytic Jacobian: grinding ODEs are stiff. Breakage rates
span decades (tau S from 1e-3 to 1e8 on one grid), so the fastest classes decay in a tiny
fraction of the time the slow ones need. An explicit method's stable step is bounded by
the fastest rate whatever the accuracy asked, which makes it take about max(S) t steps; an
implicit method (BDF, Radau, or LSODA switching to BDF once the problem turns stiff) is
stable at any step and takes the steps the accuracy needs. Each implicit step solves a
linear system with the iteration matrix I - h c J; the analytic Jacobian J (the breakage
operator K = (b - I) diag(S), plus the transport and the non-linear terms' derivatives)
costs one evaluation instead of the n right-hand sides of a finite-difference one, and it
is exact, so Newton's iterations converge at the rate the method assumes.

scipy is imported inside the functions: ``import millflow`` does not load
``scipy.integrate``.
"""
from __future__ import annotations

import math

import numpy as np

from millflow.errors import InputError, SolverError

__all__ = ["integrate", "integrate_linear", "METHODS"]

#: The implicit methods of ``solve_ivp`` offered (stiff problems: module docstring).
METHODS = ("BDF", "Radau", "LSODA")


def _shown(value) -> str:
    return f"{float(value):g}" if isinstance(value, (int, float, np.number)) else repr(value)


def _positive(value, name: str, what: str, shape=None):
    """``value`` as a float or an array of ``shape``: finite and > 0, else InputError."""
    arr = np.asarray(value, dtype=float) if np.ndim(value) else None
    if arr is None:
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{what}: {name} is {_shown(value)}; expected a finite number > 0") from None
        if not (math.isfinite(x) and x > 0.0):
            raise InputError(f"{what}: {name} is {_shown(value)}; expected a finite number > 0")
        return x
    if shape is None or arr.shape != shape:
        expected = "a number" if shape is None else f"a number or an array of shape {shape} (that of y0)"
        raise InputError(f"{what}: {name} has shape {arr.shape}; expected {expected}")
    if not (np.isfinite(arr).all() and (arr > 0.0).all()):
        bad = int(np.flatnonzero(~(np.isfinite(arr) & (arr > 0.0)))[0])
        raise InputError(f"{what}: {name}[{bad}] is {_shown(arr[bad])}; expected finite numbers > 0")
    return arr


def _dense_jacobian(jac):
    """A Jacobian in the form LSODA takes: a callable giving a dense array.

    scipy's LSODA (compiled ODEPACK) takes neither a constant matrix nor a sparse one.
    """
    if jac is None:
        return None
    if not callable(jac):
        J = jac.toarray() if hasattr(jac, "toarray") else np.asarray(jac, dtype=float)
        return lambda _t, _y: J
    given = jac

    def dense(t, y):
        J = given(t, y)
        return J.toarray() if hasattr(J, "toarray") else J
    return dense


def integrate(rhs, t_span, y0, *, jac, method: str = "BDF", rtol: float, atol, t_eval=None, events=None,
              dense_output: bool = False, finite: bool = False, what: str, **options):
    """Solve dy/dt = rhs(t, y), y(t0) = y0, by an implicit method of scipy's ``solve_ivp``.

    The one ODE call of the library. An implicit method with the analytic Jacobian is the
    default because grinding ODEs are stiff (rates spanning decades: an explicit method's
    step would be bounded by the fastest rate, an implicit one's by the accuracy; module
    docstring).

    Parameters
    ----------
    rhs : callable
        ``rhs(t, y) -> (n,)`` array, dy/dt in the units of y per unit of t (per second
        for a time, per unit fractional position for plug flow's axis).
    t_span : (float, float)
        Start and end of the integration, in the unit of t (s, or a dimensionless
        position).
    y0 : (n,) array
        Initial state (masses, fluxes or hold-ups, in the caller's units).
    jac : callable, array, sparse matrix or None
        The Jacobian d rhs / dy, (n, n) [1/unit of t]: a constant matrix (dense or sparse)
        or ``jac(t, y)`` returning one. Handed to BDF and Radau as given; for LSODA a
        constant becomes a callable and a sparse result a dense one (ODEPACK takes
        neither). None: finite differences (n right-hand sides per Jacobian; avoid).
    method : str, default "BDF"
        One of :data:`METHODS`: "BDF", "Radau" or "LSODA".
    rtol : float
        Relative tolerance, finite and > 0 [1].
    atol : float or (n,) array
        Absolute tolerance, finite and > 0, in the units of y (one for all components or
        one per component).
    t_eval : (T,) array, optional
        Increasing output times within ``t_span`` (None: the solver's own steps).
    events : callable or list of callables, optional
        As ``solve_ivp``: ``event(t, y)`` whose zeros are located; a ``terminal`` one
        stops the integration (``result.status == 1``).
    dense_output : bool, default False
        Keep the continuous solution (``result.sol``).
    finite : bool, default False
        Count non-finite states as a failed solve (LSODA can end "successfully" on NaN
        right-hand sides).
    what : str
        What is solved, for the error message (e.g. "transient mill").
    **options
        Further options of the method (``lband``, ``uband`` of LSODA, ``first_step``,
        ``max_step``).

    Returns
    -------
    scipy.integrate.OdeResult
        ``solve_ivp``'s result (``t``, ``y`` (n, T), ``sol``, ``t_events``, ``nfev``,
        ``njev``, ``nlu``, ``status``, ``message``), with ``success`` True.

    Raises
    ------
    InputError
        ``method`` not implicit, ``rtol`` or ``atol`` not finite and > 0, or ``atol`` of
        another shape than ``y0``.
    SolverError
        The solve failed, as one line: "{what}: the ODE ({method}, rtol {rtol:g}) failed
        at t = {t}: {message}", t the last time the right-hand side was evaluated at
        (where the solver gave up); with ``finite``, the message says "non-finite states"
        and t is the first output time holding one.
    """
    from scipy.integrate import solve_ivp

    if method not in METHODS:
        raise InputError(f"{what}: method {method!r}; expected one of {', '.join(METHODS)} (implicit: the problem is "
                         "stiff)")
    y0 = np.asarray(y0, dtype=float)
    rtol = _positive(rtol, "rtol", what)
    atol = _positive(atol, "atol", what, y0.shape)
    if method == "LSODA":
        jac = _dense_jacobian(jac)
    reached = [float(t_span[0])]

    def fun(t, y):
        reached[0] = t
        return rhs(t, y)

    sol = solve_ivp(fun, t_span, y0, method=method, t_eval=t_eval, events=events, dense_output=dense_output,
                    jac=jac, rtol=rtol, atol=atol, **options)
    head = f"{what}: the ODE ({method}, rtol {rtol:g}) failed at t = "
    if not sol.success:
        raise SolverError(f"{head}{float(reached[0]):.6g}: {sol.message}")
    if finite and not np.isfinite(sol.y).all():
        first = int(np.flatnonzero(~np.isfinite(sol.y).all(axis=0))[0])
        raise SolverError(f"{head}{float(sol.t[first]):.6g}: non-finite states (non-finite right-hand side: rates "
                          "or kinetics)")
    return sol


def integrate_linear(J, t_span, y0, *, c=None, method: str = "BDF", rtol: float, atol, t_eval=None,
                     what: str, **options):
    """Solve the linear system dy/dt = J y + c, y(t0) = y0, with its constant Jacobian J.

    :func:`integrate` with the right-hand side J y (+ c) and the Jacobian J itself: BDF
    and Radau factor it without evaluating a Jacobian again (implicit methods for the
    stiff breakage operator: module docstring).

    Parameters
    ----------
    J : (n, n) array or sparse matrix
        The constant system matrix [1/s], e.g. the breakage operator K = (b - I) diag(S)
        or a transient mill's transport plus breakage.
    t_span : (float, float)
        Start and end time [s].
    y0 : (n,) array
        Initial state (masses, in the caller's units).
    c : (n,) array, optional
        Constant source (units of y per s; a feed), None for none.
    method, rtol, atol, t_eval, what, **options
        As :func:`integrate`.

    Returns
    -------
    scipy.integrate.OdeResult
        As :func:`integrate`.

    Raises
    ------
    InputError, SolverError
        As :func:`integrate`.
    """
    if c is None:
        def rhs(_t, y):
            return J @ y
    else:
        def rhs(_t, y):
            return J @ y + c
    return integrate(rhs, t_span, y0, jac=J, method=method, rtol=rtol, atol=atol, t_eval=t_eval, what=what,
                     **options)
