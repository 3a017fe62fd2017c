"""Transient mills with non-linear kinetics: start-up, a step change of feed, a tracer
pulse, for the transports the linear transient mill solves (cells, axial dispersion,
plug flow), with classification where the steady non-linear mill takes it.

- Cells (perfect mixing, tanks in series, recirculating cells, any compartment network):
  the content c_k of cell k (per unit volume) obeys V_k dc_k/dt = src_k(t) + (T c)_k +
  V_k R(c_k), the steady residual of :func:`millflow.mill.nonlinear.cells` as a
  right-hand side (the same transport operator T with its classification);
  product p = beta f + sum_l H_l o_l c_l, hold-up V_k c_k.
- Axial dispersion (closed and open vessel): the method of lines of the node balances
  the steady Newton solves (:mod:`millflow.mill.nonlinear_axial`), tau w_k dc_k/dt =
  F_k(c); product v c at the discharge node (closed, open sampled) or, for the open
  vessel's flux discharge, the balance of (-inf, 1]: f + tau sum_k u_k (R(c_k) - dc_k/dt)
  (u the weights upstream of z = 1); hold-up tau sum_k w_k c_k (closed), the upstream part
  (flux) or that plus the back-dispersion layer of c(1) (sampled, solved by Newton at each
  output time, as the steady state defines it).
- Plug flow (d* = 1): no mixing, so the answer is exact from the batch grind in contact
  time: the product is the feed ground for tau, delayed by tau; the hold-up is the
  integral over ages of the parcels inside (new feed younger than t, the old steady
  contents older). With d* in the velocity classes travel at different speeds and a step
  spreads into one front per speed: the sector between the fronts by
  :mod:`millflow.mill.plug_fronts` (the aggregation overflow at d* = 1).
- Slowing-down in the particle's age, kappa(t) (``kin.age``): the mill is linear in its feed
  and invariant under shifts of entry time, so the content at time t is int_0^t Y_f1 +
  int_t^inf Y_f0 (+ the pulse's Y_P(t)), Y_f(a) the age-structured balance of the steady
  solvers for feed f (:mod:`millflow.mill.age_transient`): cells with and without
  classification, the closed and the open axial vessel (flux and sampled discharges) with and
  without d* on the axis, plug flow without d* (the batch grind in the age) and plug flow with
  d* (:mod:`millflow.mill.plug_fronts_age`). A pulse through plug flow is refused.

Integration by scipy's ``solve_ivp`` (through :func:`millflow.ode.integrate`) with the analytic
Jacobian (sparse: the transport plus the dense blocks dR/dc of the cells or nodes). Default
method (measured on a mill of four recirculating cells with strong aggregation, 84
unknowns, rtol 1e-8: BDF 250,000 right-hand sides / 140 s, Radau 18,000 / 3.4 s, LSODA
3,500 / 0.5 s): LSODA with the Jacobian made dense for cells up to :data:`DENSE_STATE`
unknowns, Radau (sparse) above and for the axial grids.
Error estimate (measured, not the tolerance): the same solve at 100x tighter tolerances,
the tighter one returned, the largest difference of product and hold-up; on the axial
grids plus the spatial error, the same solve on half the volumes. A mill started from
``initial_feed`` starts at the steady state of :func:`millflow.mill.nonlinear.solve_transport`
on the same grid, so a start-up ends at the steady answer.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from millflow.errors import InputError
from millflow.mill.scene import _check_feed, _scene
from millflow.ode import integrate

__all__ = ["transient_nonlinear", "DENSE_STATE"]

#: Largest state (cells x (classes + 1)) integrated by LSODA with the dense Jacobian when no
#: method is given; larger ones by Radau with the sparse Jacobian.
DENSE_STATE = 500


def _integrate(rhs, jac, y0, t, method, rtol, atol):
    order = np.argsort(t)
    ts = t[order]
    out = np.empty((t.size, y0.size))
    at0 = ts == 0.0
    out[order[at0]] = y0
    info = {"nfev": 0, "njev": 0, "nlu": 0}
    if (~at0).any():  # (LSODA gets the sparse Jacobian made dense by integrate)
        sol = integrate(rhs, (0.0, float(ts[-1])), y0, method=method, t_eval=ts[~at0], jac=jac, rtol=rtol, atol=atol,
                        what="transient mill with non-linear kinetics")
        out[order[~at0]] = sol.y.T
        info = {"nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu)}
    return out, info


def _measured(system, y0, t, method, rtol, atol):
    """Two solves (rtol, atol) and 100x tighter: the tighter outputs and their differences."""
    loose, i1 = _integrate(system["rhs"], system["jac"], y0, t, method, rtol, atol)
    tight, i2 = _integrate(system["rhs"], system["jac"], y0, t, method, rtol / 100, atol / 100)
    out_t, out_l = system["outputs"](tight, t), system["outputs"](loose, t)
    diff = {k: float(np.abs(out_t[k] - out_l[k]).max(initial=0.0)) for k in ("product", "holdup")}
    return out_t, {k: i1[k] + i2[k] for k in i1}, diff


# ------------------------------------------------------------------------- cells
def _cells_system(kin, sc, feed):
    from millflow.mill.cells import network_of
    from millflow.mill.nonlinear import _discharge, network_operator

    net = sc.network if sc.network is not None else network_of(sc.transport)
    n, n1 = int(net.n), kin.n + 1
    dx = _discharge(kin, sc.d)
    T, inlet, out = network_operator(net, dx, sc.where or "discharge", n1)
    V = np.asarray(net.volumes, float)
    iv = np.repeat(1.0 / V, n1)
    src = np.outer(inlet, np.append(feed, 0.0)).ravel()
    beta = float(net.bypass)

    def rhs(_t, c):
        return iv * (src + T @ c + (V[:, None] * kin.rate_many(c.reshape(n, n1))).ravel())

    def jac(_t, c):
        blocks = V[:, None, None] * kin.jacobian_many(c.reshape(n, n1))
        B = sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(n * n1, n * n1))
        return (sp.diags(iv) @ (T + B)).tocsc()

    def outputs(Y, t):
        C = Y.reshape(t.size, n, n1)
        p = beta * np.append(feed, 0.0)[None, :] + np.einsum("in,tni->ti", out, C)
        cells = V[None, :, None] * C
        return {"product": p, "holdup": cells.sum(axis=1), "cells": cells}

    return {"rhs": rhs, "jac": jac, "outputs": outputs, "n": n, "n1": n1, "V": V, "inlet": inlet}


def _cells(kin, sc, t, feed, start_feed, pulse, method, rtol, atol):
    from millflow.mill.nonlinear import solve_transport

    system = _cells_system(kin, sc, feed)
    V = system["V"]
    c0 = (system["inlet"][:, None] * np.append(pulse, 0.0)[None, :] / V[:, None]).ravel()
    steady0 = None
    if start_feed is not None:
        steady0 = solve_transport(kin, start_feed, sc.transport, sc.d, where=sc.where)
        held = steady0.info.get("cell_holdup", steady0.info.get("cells"))
        over = steady0.info.get("cell_overflow", steady0.info.get("cells_overflow"))
        c0 = c0 + (np.concatenate([held, np.asarray(over)[:, None]], axis=1) / V[:, None]).ravel()
    out, info, diff = _measured(system, c0, t, method, rtol, atol)
    extra = {"initial_steady_error_estimate": steady0.error_estimate} if steady0 is not None else {}
    return out, info, diff, extra, f"cells_nonlinear_{method}"


# ------------------------------------------------------------------------- axial
def _line_system(kin, line, tau, feed, open_flux: bool):
    m1, n1 = line.z.size, kin.n + 1
    lo, dg, up, wts = line.lower, line.diag, line.upper, line.weights
    src = np.zeros((m1, n1))
    src[line.feed_node] = np.append(feed, 0.0)
    iw = 1.0 / (tau * wts)
    k1 = line.out_node
    hw = line.holdup_weights
    diag_idx = np.arange(n1)
    # the constant transport part as a sparse matrix (node-major state)
    rows, cols, vals = [], [], []
    base = np.arange(m1 - 1)[:, None] * n1 + diag_idx[None, :]
    rows += [base + n1, base]
    cols += [base, base + n1]
    vals += [lo, up]
    T = sp.csr_matrix((np.concatenate([v.ravel() for v in vals]),
                       (np.concatenate([r.ravel() for r in rows]), np.concatenate([c.ravel() for c in cols]))),
                      shape=(m1 * n1, m1 * n1)) + sp.diags(dg.ravel())

    def balance(C):
        out = dg * C + src + tau * wts[:, None] * kin.rate_many(C)
        out[1:] += lo * C[:-1]
        out[:-1] += up * C[1:]
        return out

    def rhs(_t, c):
        return (balance(c.reshape(m1, n1)) * iw[:, None]).ravel()

    def jac(_t, c):
        blocks = (tau * wts)[:, None, None] * kin.jacobian_many(c.reshape(m1, n1))
        B = sp.bsr_matrix((blocks, np.arange(m1), np.arange(m1 + 1)), shape=(m1 * n1, m1 * n1))
        return (sp.diags(np.repeat(iw, n1)) @ (T + B)).tocsc()

    def outputs(Y, t):
        C = Y.reshape(t.size, m1, n1)
        hold = tau * np.einsum("k,tki->ti", hw, C)
        if open_flux:
            f = np.append(feed, 0.0)
            p = np.empty((t.size, n1))
            for i, Ck in enumerate(C):
                dcdt = balance(Ck) * iw[:, None]
                p[i] = f + tau * (hw[:, None] * (kin.rate_many(Ck) - dcdt)).sum(axis=0)
        else:
            p = line.v[None, :] * C[:, k1]
        return {"product": p, "holdup": hold, "C": C}

    return {"rhs": rhs, "jac": jac, "outputs": outputs}


def _axial(kin, sc, t, feed, start_feed, pulse, method, rtol, atol, m_cells):
    from millflow.mill.nonlinear import _discharge
    from millflow.mill.nonlinear_axial import _closed_line, _open_line, _solve_line_steady, back_layer

    T = sc.transport
    tau, pe = float(T.tau), float(T.pe)
    open_vessel = sc.kind == "axial_open"
    dx = _discharge(kin, sc.d)
    v = np.ones(kin.n + 1) if dx is None else dx
    w = (v.copy() if open_vessel else np.ones(kin.n + 1)) if sc.dispersion is None else np.append(sc.dispersion, 1.0)
    discharge = (sc.discharge or "sampled") if open_vessel else None
    if open_vessel and discharge == "sampled":
        w[-1] = v[-1] * w[0] / v[0]
    runs = []
    for M in (int(m_cells), max(int(m_cells) // 2, 2)):
        line = _open_line(kin, tau, pe, M, v, w) if open_vessel else _closed_line(pe, M, v, w)
        system = _line_system(kin, line, tau, feed, discharge == "flux")
        c0 = np.zeros((line.z.size, kin.n + 1))
        c0[line.feed_node] = np.append(pulse, 0.0) / (tau * line.weights[line.feed_node])
        if start_feed is not None:
            c0 = c0 + _solve_line_steady(kin, line, tau, start_feed)
        out, info, diff = _measured(system, c0.ravel(), t, method, rtol, atol)
        if discharge == "sampled":  # the back-dispersion layer of c(1), as the steady state counts it
            out["holdup"] = out["holdup"] + np.array([back_layer(kin, line, tau, Ck) for Ck in out["C"]])
        runs.append((out, info, diff, M))
    (out, info, diff, M), (out2, _, _, _) = runs
    extra = {"control_volumes": M,
             "spatial_error_estimate": float(np.abs(out2["product"] - out["product"]).max(initial=0.0)),
             "spatial_holdup_error_estimate": float(np.abs(out2["holdup"] - out["holdup"]).max(initial=0.0))}
    if open_vessel:
        extra["discharge"] = discharge
    name = f"axial{'_open' if open_vessel else ''}_fv_nonlinear_{method}"
    return out, info, diff, extra, name


# ------------------------------------------------------------------------- plug flow
def _plug(kin, sc, t, feed, start_feed, pulse, rtol, atol):
    from millflow.mill.nonlinear import _plug_ode

    if np.any(pulse > 0):
        raise InputError("pulse: plug flow passes a pulse as a delta at t = tau; expected feed or initial_feed steps "
                         "(or a transport with dispersion)")
    tau = float(sc.transport.mean)
    n1 = kin.n + 1
    if sc.d is not None and np.ptp(np.append(sc.d, 1.0)) > 0:
        # classes at different speeds (the overflow at d* = 1): the fronts' sector
        from millflow.mill.plug_fronts import plug_fronts

        old = np.zeros(n1) if start_feed is None else np.append(start_feed, 0.0)
        product, holdup, diff, info = plug_fronts(kin.rate_many, kin.jacobian_many, np.append(sc.d, 1.0), tau,
                                                  np.append(feed, 0.0), old, t, rtol=min(rtol, 1e-9))
        extra = {"spatial_error_estimate": diff["product"], "spatial_holdup_error_estimate": diff["holdup"]}
        return {"product": product, "holdup": holdup}, info, {"product": 0.0, "holdup": 0.0}, extra, \
            "plug_flow_fronts_nonlinear"
    ones = np.ones(n1)
    a = np.minimum(t, tau) / tau  # the youngest part of the contents, new feed, as a fraction of the length
    z = np.unique(np.concatenate([a, [1.0]]))
    old = np.zeros(kin.n) if start_feed is None else start_feed
    res = {}
    diffs = {"product": 0.0, "holdup": 0.0}
    for name, f in (("new", feed), ("old", old)):
        runs = [_plug_ode(kin, np.append(f, 0.0), tau, ones, z, r, at, True) for r, at in
                ((rtol, atol), (rtol / 100, atol / 100))]
        (F1, Q1), (F2, Q2) = runs
        res[name] = (F2, Q2)
        diffs["product"] = max(diffs["product"], float(np.abs(F2[-1] - F1[-1]).max()))
        diffs["holdup"] = max(diffs["holdup"], float(np.abs(Q2 - Q1).max()))
    idx = np.searchsorted(z, a)
    Fn, Qn = res["new"]
    Fo, Qo = res["old"]
    product = np.where((t >= tau)[:, None], Fn[-1][None, :], Fo[-1][None, :])
    holdup = Qn[idx] + (Qo[-1][None, :] - Qo[idx])
    return {"product": product, "holdup": holdup}, {}, diffs, {}, "plug_flow_delay_nonlinear"


# ------------------------------------------------------------------------- entry
def transient_nonlinear(kin, b, transport, t, *, feed=None, initial_feed=None, pulse=None, d=None, where=None,
                        dispersion=None, discharge=None, x=None, method: str | None = None, rtol: float = 1e-8,
                        atol: float = 1e-12, m_cells: int = 200):
    """:func:`millflow.mill.transient.transient_mill` for non-linear kinetics (module docstring)."""
    import xarray as xr

    from millflow.mill.nonlinear import _NEEDS_STRUCTURE
    from millflow.mill.nonlinear_mill import check_no_b
    from millflow.mill.dataset import _GRID_NOTE, _size_coords

    start = time.perf_counter()
    check_no_b(kin, b, "transient_mill")
    sc = _scene(kin.S, kin.b, transport, d, where, dispersion, discharge=discharge)
    n = kin.n
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or np.any(~np.isfinite(t)) or np.any(t < 0):
        raise InputError(f"t = {t!r}; expected a 1-D array of times >= 0 [s]")
    zeros = np.zeros(n)
    feed = zeros if feed is None else _check_feed(feed, n)
    pulse_m = zeros if pulse is None else _check_feed(pulse, n)
    start_feed = None if initial_feed is None else _check_feed(initial_feed, n)
    if kin.age is not None:  # kappa(t): the age-structured balances (millflow.mill.age_transient)
        from millflow.mill.age_transient import age_transient

        out, info, diff, extra, name = age_transient(kin, sc, t, feed, start_feed, pulse_m)
    elif sc.kind in ("perfect_mixing", "network"):
        if method is None:  # a small state: ODEPACK with the dense Jacobian; a large one: Radau, sparse
            cells = sc.network.n if sc.network is not None else 1
            method = "LSODA" if cells * (n + 1) <= DENSE_STATE else "Radau"
        out, info, diff, extra, name = _cells(kin, sc, t, feed, start_feed, pulse_m, method, rtol, atol)
    elif sc.kind in ("axial", "axial_open"):
        method = "Radau" if method is None else method
        out, info, diff, extra, name = _axial(kin, sc, t, feed, start_feed, pulse_m, method, rtol, atol, m_cells)
    elif sc.kind == "plug":
        out, info, diff, extra, name = _plug(kin, sc, t, feed, start_feed, pulse_m, rtol, atol)
    else:
        raise InputError(f"transport {transport!r}: {_NEEDS_STRUCTURE} (transient: cells, plug flow or axial "
                         "dispersion)")
    product, holdup = out["product"], out["holdup"]
    coords = _size_coords(n, x)
    coords["time"] = ("time", t, {"units": "s"})
    data = {
        "product": (("time", "size"), product[:, :n], {"units": "mass/s", "long_name": "product (discharge) flow"}),
        "holdup": (("time", "size"), holdup[:, :n], {"units": "mass", "long_name": "hold-up in the mill"}),
        "overflow": ("time", product[:, n], {"units": "mass/s",
                                             "long_name": "aggregation overflow above the top class, discharged"}),
    }
    if holdup.shape[1] > n:
        data["overflow_holdup"] = ("time", holdup[:, n], {"units": "mass",
                                                          "long_name": "aggregation overflow held in the mill"})
    if "cells" in out:
        coords["cell"] = ("cell", np.arange(1, out["cells"].shape[1] + 1))
        data["cell_holdup"] = (("time", "cell", "size"), out["cells"][:, :, :n],
                               {"units": "mass", "long_name": "hold-up per cell"})
    ds = xr.Dataset(data, coords=coords)
    err = diff["product"] + extra.get("spatial_error_estimate", 0.0)
    hold_err = diff["holdup"] + extra.get("spatial_holdup_error_estimate", 0.0)
    ds.attrs.update(solver_error_estimate=err, grid_error_estimate=0.0, grid_error_method=_GRID_NOTE,
                    method=name, error_estimate=err, holdup_error_estimate=hold_err,
                    time_error_estimate=diff["product"],
                    runtime_s=time.perf_counter() - start, transport=repr(transport), kinetics=kin.describe(),
                    classification="none" if sc.d is None else f"d* at {sc.where}", **info, **extra)
    return ds
