"""Transient mills with slowing-down in the particle's age, S_i = S_i0 kappa(a): start-up,
a step change of feed and a tracer pulse from the age-structured balances.

The rates depend on a particle's age only, so the mill is linear in its feed and invariant
under shifts of the entry time. The material that entered at time t - a has age a at time
t and its state is Y_f(a), the solution of the age ODE of the steady solvers
(:mod:`millflow.mill.age_cells`, :mod:`millflow.mill.age_axis`) for feed f::

    dY/da = (kappa(a) K + T) Y,  Y(0) = the feed placed at the inlet,  Q_f(a) = int_0^a Y_f.

With the feed f0 before t = 0 (the steady state; zero for a start-up from empty), f1 after,
and a pulse of mass P placed at the inlet at t = 0, the content at time t [mass] is::

    M(t) = Q_f1(t) + (Q_f0(inf) - Q_f0(t)) + Y_P(t),

the hold-up is M(t) summed over cells or nodes and the product [mass/s] is the exit rate
applied to it, p(t) = beta f1 + E M(t) (beta the bypass), the same exit weights E the steady
solvers apply to Q(inf): t = 0 gives the old steady state, t -> inf the new one. Exact (no
linearisation): one ODE in the age per feed, evaluated at the output times.

Built for cells (perfect mixing, tanks in series, recirculating cells, compartment
networks) with and without classification (:func:`millflow.mill.age_cells._operators`, LSODA)
the closed axial-dispersion vessel with and without d* on the axis (the finite volumes
of :func:`millflow.mill.age_axis.age_structured_axial` on one grid, the one its steady
refinement chooses for the largest feed, a pulse P counted as the rate P / tau; BDF with the
sparse Jacobian), the open vessel the same way on the operators of
:func:`millflow.mill.age_axis.age_structured_open` (:func:`millflow.mill.age_axis.open_grid`:
its whole line, d* and per-class dispersion w on the axis; the flux discharge's product the
net flux through z = 1, -U T M(t) with U the part upstream of z = 1, so that dH/dt = f - p
summed over classes; the sampled discharge's v c(1), its hold-up with the back-dispersion
layer of each entry time at its age, as the steady solver counts it: the ends are its steady
states, but between them the layer lags c(1), unlike the linear transient, which takes the
steady layer of the current c(1), and dH/dt = f - p does not hold for it; unequal Peclet
numbers with the sampled discharge refused, as the linear open vessel), and plug flow without
classification (exact: every parcel is the batch grind at theta(age); the product is the
feed ground for tau, delayed by tau; the hold-up int_0^min(t, tau) Y_f1 + the old contents
older than t) and plug flow with d* (classes at different speeds: an impulse's deltas and
fragments on the strip of :mod:`millflow.mill.plug_fronts_age`). The new feed and the pulse are
integrated up to the last output time only; the old feed to its tail, for Q_f0(inf).
Refused: a pulse through plug flow (a delta at tau / d*).

Error estimate (measured): every age ODE at (rtol, atol) and 10x tighter, the tighter
returned; the largest difference of product and of hold-up, plus the tail: the ODE stops
at the age A where the mass left falls below ``tail`` of the feed; ages beyond A take
Q(inf) (closed at kappa(A) as the steady solvers close it) and Y = 0, which moves the
product by at most the mass left at A (the exit rate times the mass left for the pulse)
and the hold-up by at most that mass times max(tau, 1 / slowest decay rate) (the open vessel:
the flux product by 3x the mass left, a class's net flux through z = 1 lying within [-left,
2 left]; the sampled hold-up times 1 + 2 / min Pe_i for its back layer). On the axial
grid (M volumes, chosen by the steady refinement) the grid part is the difference from the
same transient on M / 2 volumes: the steady answer is Richardson-extrapolated, the
transient one is not, so the steady refinement's estimate does not apply to it.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from millflow.errors import InputError, SolverError
from millflow.mill.age_cells import AGE_ATOL, AGE_RTOL, AGE_TAIL, _kappa_of
from millflow.ode import integrate

__all__ = ["age_transient"]


def _paths(kap, Kb, T, y0, ages, *, fsum, tscale, horizon, rtol, atol, tail, method, line=None, need_inf=True):
    """Y(a) and Q(a) = int_0^a Y at the sorted ``ages`` [s], Q(inf), and the mass left at the stop.

    The mass left is that of the first ``line`` states (None: all; the open vessel's line
    without the sampled discharge's back layer). Without ``need_inf`` (the new feed and the
    pulse, which need no Q(inf)) the ODE stops at the last output age if the mass has not
    fallen below the tail by then: Q(inf) is then None and the mass left 0 (no tail taken).
    """
    m = y0.size
    line = m if line is None else int(line)
    if sp.issparse(T):
        eye, zero = sp.identity(m, format="csc"), sp.csc_matrix((m, m))
        J_T = sp.bmat([[T, zero], [eye, zero]], format="csc")
        J_K = sp.bmat([[Kb, zero], [zero, zero]], format="csc")
    else:
        J_T = np.block([[T, np.zeros((m, m))], [np.eye(m), np.zeros((m, m))]])
        J_K = np.zeros((2 * m, 2 * m))
        J_K[:m, :m] = Kb

    def rhs(a, z):
        y = z[:m]
        return np.concatenate([T @ y + kap(a) * (Kb @ y), y])

    def jac(a, _z):
        return J_T + kap(a) * J_K

    def left(_a, z):
        return float(z[:line].sum()) - tail * fsum
    left.terminal, left.direction = True, -1
    at = np.concatenate([np.full(m, atol * fsum), np.full(m, atol * fsum * tscale)])
    end = horizon if need_inf else min(horizon, float(ages.max(initial=0.0)))
    if end <= 0:  # every output at age 0
        return np.tile(y0, (ages.size, 1)), np.zeros((ages.size, m)), None, 0.0, 0
    pos = ages[(ages > 0) & (ages <= end)]
    sol = integrate(rhs, (0.0, end), np.concatenate([y0, np.zeros(m)]), method=method, jac=jac, rtol=rtol,
                    atol=at, t_eval=pos if pos.size else None, events=left,
                    what="transient age-structured mill (the ODE in the age)")
    if sol.status == 0 and not need_inf:  # reached the last output age first: every output solved
        Y, Q = np.zeros((ages.size, m)), np.zeros((ages.size, m))
        Y[ages == 0] = y0
        idx = np.searchsorted(ages, sol.t)
        Y[idx], Q[idx] = sol.y[:m].T, sol.y[m:].T
        return Y, Q, None, 0.0, int(sol.nfev)
    if sol.status != 1:
        raise SolverError(f"transient age-structured mill: mass is still in the mill at age {horizon:.4g} s (the "
                          f"horizon); expected it below {tail:g} of the feed")
    A, zA = float(sol.t_events[0][0]), sol.y_events[0][0]
    L = T + kap(A) * Kb
    closure = sp.linalg.spsolve(-L.tocsc(), zA[:m]) if sp.issparse(L) else np.linalg.solve(-L, zA[:m])
    q_inf = zA[m:] + closure
    Y = np.zeros((ages.size, m))
    Q = np.tile(q_inf, (ages.size, 1))  # beyond A: Q(inf), Y = 0 (within the tail bound)
    Y[ages == 0] = y0
    Q[ages == 0] = 0.0
    if pos.size:  # the output ages the ODE reached before the stop at A
        idx = np.searchsorted(ages, sol.t)
        Y[idx], Q[idx] = sol.y[:m].T, sol.y[m:].T
    return Y, Q, q_inf, float(max(zA[:line].sum(), 0.0)), int(sol.nfev)


def _scenario(model, t, feed, start_feed, pulse, rtol, atol, tail):
    """Product and content over t for one model; (outputs, ode difference, tail bound, nfev)."""
    order = np.argsort(t)
    ages = t[order]
    kap, Kb, T, place, E = model["kap"], model["Kb"], model["T"], model["place"], model["E"]
    common = {"tscale": model["tau"], "horizon": model["horizon"], "tail": tail, "method": model["method"],
              "line": model.get("line")}
    runs = []
    lefts = {"f1": 0.0, "f0": 0.0, "P": 0.0}
    nfev = 0
    for rt, at in ((rtol, atol), (max(0.1 * rtol, 3e-14), 0.1 * atol)):
        C = np.zeros((t.size, T.shape[0]))
        for name, f in (("f1", feed), ("f0", start_feed), ("P", pulse)):
            if f is None or not np.any(f > 0):
                continue
            Y, Q, q_inf, left, nf = _paths(kap, Kb, T, place(f), ages, fsum=float(f.sum()), rtol=rt, atol=at,
                                           need_inf=name == "f0", **common)
            nfev += nf
            lefts[name] = max(lefts[name], left)
            part = Q if name == "f1" else (q_inf[None, :] - Q if name == "f0" else Y)
            C[order] += part
        p = (E @ C.T).T + model["bypass"] * feed[None, :]
        runs.append((p, C))
    (p1, C1), (p2, C2) = runs
    hold = model["hold"]
    h1, h2 = (hold @ C1.T).T, (hold @ C2.T).T
    diff = {"product": float(np.abs(p2 - p1).max(initial=0.0)), "holdup": float(np.abs(h2 - h1).max(initial=0.0))}
    emax = float(np.abs(E).sum(axis=0).max()) if not sp.issparse(E) else float(abs(E).sum(axis=0).max())
    scale = max(model["tau"], 1.0 / model["slow"])
    step, counted = model.get("tail_factor", 2.0), model.get("tail_hold", 1.0)
    tail_b = {"product": step * (lefts["f1"] + lefts["f0"]) + emax * lefts["P"],
              "holdup": (2.0 * (lefts["f1"] + lefts["f0"]) * scale + lefts["P"]) * counted}
    return {"product": p2, "holdup": h2, "C": C2}, diff, tail_b, nfev


def _cells_model(kin, sc):
    from millflow.mill.age_cells import _operators
    from millflow.mill.cells import network_of

    net = sc.network if sc.network is not None else network_of(sc.transport)
    Kb, T, w, inlet, bypass = _operators(kin, net, sc.d, sc.where or "discharge")
    n, N = int(net.n), kin.n
    E = np.zeros((N, n * N))
    E[np.tile(np.arange(N), n), np.arange(n * N)] = w
    hold = np.tile(np.eye(N), (1, n))
    tau = float(getattr(sc.transport, "mean", np.sum(net.volumes)))
    slow = float(np.min(-np.linalg.eigvals(T).real))
    if not slow > 0:
        raise InputError(f"transport {sc.transport!r}: some class never leaves the cells (the transport has a decay "
                         "rate <= 0)")
    return {"Kb": Kb, "T": T, "E": E, "hold": hold, "place": lambda f: np.kron(inlet, f), "bypass": bypass,
            "tau": tau, "slow": slow, "horizon": 80.0 / slow + 10.0 * tau, "method": "LSODA", "cells": n}


def _axial_grid(kin, sc, feeds):
    """The grid (volumes) the steady refinement chooses for the largest of ``feeds``."""
    import rtd

    from millflow.mill.age_axis import age_structured_axial, age_structured_open

    tr = sc.transport
    big = max(feeds, key=lambda f: float(f.sum()))
    if sc.kind == "axial_open":
        steady = age_structured_open(kin, big, tr, sc.d, dispersion=sc.dispersion,
                                     discharge=sc.discharge or "sampled", error_estimate=False, holdup=False)
    else:
        steady = age_structured_axial(kin, big, rtd.AxialDispersion(float(tr.tau), float(tr.pe), bc="closed"), sc.d,
                                      dispersion=sc.dispersion, error_estimate=False, holdup=False)
    return int(steady.info["m_cells"])


def _axial_model(kin, sc, M):
    from millflow.linalg import breakage_matrix
    from millflow.mill.age_axis import _fv_transport, _slowest_decay

    tr = sc.transport
    tau, pe = float(tr.tau), float(tr.pe)
    N = kin.n
    v = np.ones(N) if sc.d is None else np.asarray(sc.d, float)
    w = np.ones(N) if sc.dispersion is None else np.asarray(sc.dispersion, float)
    T, exit_, _ = _fv_transport(v, w, pe, tau, M)
    Kb = sp.kron(sp.identity(M + 1, format="csc"), sp.csc_matrix(breakage_matrix(kin.S, kin.b)), format="csc")
    m = T.shape[0]
    hold = sp.csr_matrix((np.ones(m), (np.tile(np.arange(N), M + 1), np.arange(m))), shape=(N, m))

    def place(f):
        y0 = np.zeros(m)
        y0[:N] = f
        return y0
    slow = _slowest_decay(v, w, pe, tau)
    return {"Kb": Kb, "T": T, "E": exit_, "hold": hold, "place": place, "bypass": 0.0, "tau": tau, "slow": slow,
            "horizon": 80.0 / slow + 10.0 * tau, "method": "BDF", "m_cells": M}


def _open_model(kin, sc, M):
    """The open vessel on its whole line (:func:`millflow.mill.age_axis.open_grid`), the sampled
    discharge with its back-dispersion layer in the state."""
    from millflow.linalg import breakage_matrix
    from millflow.mill.age_axis import open_grid, open_slowest_decay, open_vessel

    tr = sc.transport
    tau, pe = float(tr.tau), float(tr.pe)
    N = kin.n
    v, w, discharge, length = open_vessel(N, tau, pe, sc.d, sc.dispersion, sc.discharge)
    flux = discharge == "flux"
    g = open_grid(v, w, pe, tau, M, length, flux, not flux)
    m = g.TX.shape[0]
    Kb = sp.kron(sp.identity(m // N, format="csc"), sp.csc_matrix(breakage_matrix(kin.S, kin.b)), format="csc")

    def place(f):
        y0 = np.zeros(m)
        y0[g.inlet] = f
        return y0
    slow = open_slowest_decay(v, w, pe, tau, length)
    # the tail's bounds: a class's net flux through z = 1 is its upstream mass plus what breakage
    # moves in minus what it moves out, each at most the mass left, so within [-left, 2 left], and
    # the true tail and its closure differ by at most 3 left (the sampled product and the exits
    # of the closed vessel are >= 0: 2 left); the sampled hold-up counts the back layer too,
    # at most 2 / Pe_i of the line's (the open density's mean tau (1 + 2/Pe))
    pe_min = float(np.min(pe * v / w))
    return {"Kb": Kb, "T": g.TX, "E": g.exit, "hold": g.hold, "place": place, "bypass": 0.0, "tau": tau,
            "slow": slow, "horizon": 80.0 / slow + 10.0 * tau, "method": "BDF", "m_cells": M, "line": g.n,
            "tail_factor": 3.0 if flux else 2.0, "tail_hold": 1.0 if flux else 1.0 + 2.0 / pe_min,
            "discharge": discharge}


def _plug(kin, sc, t, feed, start_feed, pulse, rtol, atol):
    """Plug flow without classification: the batch grind in the age, exact (module docstring)."""
    from millflow.linalg import breakage_matrix

    if np.any(pulse > 0):
        raise InputError("pulse: plug flow passes a pulse as a delta at t = tau; expected feed or initial_feed steps "
                         "(or a transport with dispersion)")
    tau = float(sc.transport.mean)
    K = breakage_matrix(kin.S, kin.b)
    N = kin.n
    kap = _kappa_of(kin.age, tau)[0]
    if sc.d is not None and np.ptp(sc.d) > 0:  # classes at different speeds: the impulse's strip
        from millflow.mill.plug_fronts_age import plug_fronts_age

        old = np.zeros(N) if start_feed is None else start_feed
        product, holdup, diff, info = plug_fronts_age(kap, K, np.asarray(sc.d, dtype=float), tau, feed, old, t,
                                                      rtol=min(rtol, 1e-9))
        zero = np.zeros((t.size, 1))
        extra = {"spatial_error_estimate": diff["product"], "spatial_holdup_error_estimate": diff["holdup"]}
        return ({"product": np.hstack([product, zero]), "holdup": np.hstack([holdup, zero])}, info,
                {"product": 0.0, "holdup": 0.0}, extra, "plug_flow_age_fronts")
    if sc.d is not None:  # one speed v: plug flow with the residence time tau / v
        tau = tau / float(sc.d[0])
    a = np.minimum(t, tau)  # the age of the oldest new feed inside
    ages = np.unique(np.concatenate([a, [tau]]))
    J_T = np.zeros((2 * N, 2 * N))
    J_T[N:, :N] = np.eye(N)
    J_K = np.zeros((2 * N, 2 * N))
    J_K[:N, :N] = K

    def rhs(s, z):
        return np.concatenate([kap(s) * (K @ z[:N]), z[:N]])

    def jac(s, _z):
        return J_T + kap(s) * J_K
    res, nfev = [], 0
    for rt, at in ((rtol, atol), (max(0.1 * rtol, 3e-14), 0.1 * atol)):
        parts = {}
        for name, f in (("new", feed), ("old", np.zeros(N) if start_feed is None else start_feed)):
            fs = max(float(f.sum()), 1e-300)
            Z = np.zeros((ages.size, 2 * N))
            Z[0, :N] = f
            if ages.size > 1:
                sol = integrate(rhs, (0.0, tau), np.concatenate([f, np.zeros(N)]), method="LSODA", jac=jac, rtol=rt,
                                atol=np.concatenate([np.full(N, at * fs), np.full(N, at * fs * tau)]),
                                t_eval=ages[1:], what="transient plug flow with kappa(t) (the batch grind in the age)")
                Z[1:] = sol.y.T
                nfev += int(sol.nfev)
            parts[name] = Z
        idx = np.searchsorted(ages, a)
        Zn, Zo = parts["new"], parts["old"]
        product = np.where((t >= tau)[:, None], Zn[-1, :N][None, :], Zo[-1, :N][None, :])
        holdup = Zn[idx, N:] + (Zo[-1, N:][None, :] - Zo[idx, N:])
        res.append((product, holdup))
    (p1, h1), (p2, h2) = res
    diff = {"product": float(np.abs(p2 - p1).max()), "holdup": float(np.abs(h2 - h1).max())}
    zero = np.zeros((t.size, 1))
    out = {"product": np.hstack([p2, zero]), "holdup": np.hstack([h2, zero])}
    return out, {"nfev": nfev, "njev": 0, "nlu": 0}, diff, {}, "plug_flow_age_batch_transient"


def age_transient(kin, sc, t, feed, start_feed, pulse, *, rtol: float = AGE_RTOL, atol: float = AGE_ATOL,
                  tail: float = AGE_TAIL):
    """Product and hold-up over time of a mill with kappa(t) kinetics (module docstring).

    Parameters
    ----------
    kin : millflow.nonlinear.Kinetics
        First-order rates S_i0 [1/s] and b with kappa(t) (``kin.age``), t the age in s.
    sc : millflow.mill.scene._Scene
        The checked transport scene (cells, plug flow, the closed or open axial vessel), with d*,
        where, dispersion and the open vessel's discharge.
    t : (T,) array
        Output times >= 0 [s].
    feed : (N,) array
        Feed flow after t = 0 [mass/s].
    start_feed : (N,) array or None
        Feed flow before t = 0, whose steady state the mill holds at t = 0 [mass/s]; None: empty.
    pulse : (N,) array
        Tracer mass placed at the inlet at t = 0 [mass].
    rtol, atol : float
        Tolerances of the age ODE (relative; absolute of the feed); the answer is a solve 10x tighter.
    tail : float
        Share of the feed left in the mill at which the age ODE stops.

    Returns
    -------
    tuple
        (outputs {"product" (T, N+1) [mass/s], "holdup" (T, N+1) [mass], "cells" (T, cells, N+1)
        for cells}, info, {"product", "holdup"} ODE differences, extra attributes, method name).
    """
    if kin.age is None:
        raise InputError("age_transient: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    if sc.kind == "plug":
        return _plug(kin, sc, t, feed, start_feed, pulse, rtol, atol)
    if sc.kind in ("perfect_mixing", "network"):
        model = _cells_model(kin, sc)
        name = "age_structured_cells_transient"
    elif sc.kind in ("axial", "axial_open"):
        # the grid for the largest feed; a pulse [mass] as the rate pulse / tau, the scale of its
        # product (as a rate it would ask the steady refinement for tau times the accuracy)
        feeds = [f for f in (feed, start_feed, pulse / float(sc.transport.tau)) if f is not None and np.any(f > 0)]
        build = _axial_model if sc.kind == "axial" else _open_model
        model = build(kin, sc, _axial_grid(kin, sc, feeds or [feed]))
        name = "age_structured_axial_transient" if sc.kind == "axial" else "age_structured_open_transient"
    else:
        raise InputError(f"transient_mill with kappa(t) (slowing-down in the particle's age): solved for cells "
                         f"(perfect mixing, tanks in series, recirculating cells, networks), axial dispersion "
                         f"(closed and open vessel) and plug flow; transport {sc.transport!r} is solved in the "
                         "steady state only")
    model["kap"] = _kappa_of(kin.age, model["tau"])[0]
    out, diff, tail_b, nfev = _scenario(model, t, feed, start_feed, pulse, rtol, atol, tail)
    N = kin.n
    zero = np.zeros((t.size, 1))
    res = {"product": np.hstack([out["product"], zero]), "holdup": np.hstack([out["holdup"], zero])}
    extra = {"tail_error_estimate": tail_b["product"], "tail_holdup_error_estimate": tail_b["holdup"]}
    if "cells" in model:
        cells = out["C"].reshape(t.size, model["cells"], N)
        res["cells"] = np.concatenate([cells, np.zeros((t.size, model["cells"], 1))], axis=2)
    else:  # the grid part: the same transient on half the volumes, the difference (conservative for a
        # second-order scheme, whose error on M is about a third of it)
        half = build(kin, sc, max(model["m_cells"] // 2, 2))
        half["kap"] = model["kap"]
        out2, _, _, nf2 = _scenario(half, t, feed, start_feed, pulse, rtol, atol, tail)
        nfev += nf2
        if "discharge" in model:
            extra["discharge"] = model["discharge"]
        extra.update(control_volumes=model["m_cells"],
                     spatial_error_estimate=float(np.abs(out2["product"] - out["product"]).max(initial=0.0)),
                     spatial_holdup_error_estimate=float(np.abs(out2["holdup"] - out["holdup"]).max(initial=0.0)))
    both = {"product": diff["product"] + tail_b["product"], "holdup": diff["holdup"] + tail_b["holdup"]}
    return res, {"nfev": nfev, "njev": 0, "nlu": 0}, both, extra, name
